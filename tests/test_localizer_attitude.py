"""Rotations, and the camera attitude from every source through camera_pose with real telemetry.

Expected optical axes are written by hand: a camera heading ψ and pitched θ
(negative down) looks along (cos θ cos ψ, cos θ sin ψ, −sin θ) in NED.
"""

import math

import cv2
import numpy as np
import pytest
from conftest import T0_UNIX
from hypothesis import given, settings
from hypothesis import strategies as st
from pyproj import Geod

from localizer.attitude import euler_rates, euler_to_quat, euler_to_R, quat_to_R, rotvec
from localizer.fix import locate
from localizer.pose import camera_pose

angles = {
    "roll": st.floats(-math.pi, math.pi),
    "pitch": st.floats(-1.55, 1.55),
    "yaw": st.floats(-math.pi, math.pi),
}


def rodrigues(axis, angle):
    return cv2.Rodrigues(np.asarray(axis, float) * angle)[0]


def look(heading_deg, pitch_deg):
    y, p = math.radians(heading_deg), math.radians(pitch_deg)
    return np.array([math.cos(p) * math.cos(y), math.cos(p) * math.sin(y), -math.sin(p)])


@settings(max_examples=200, deadline=None)
@given(**angles)
def test_euler_is_yaw_then_pitch_then_roll(roll, pitch, yaw):
    expected = rodrigues([0, 0, 1], yaw) @ rodrigues([0, 1, 0], pitch) @ rodrigues([1, 0, 0], roll)
    assert np.allclose(euler_to_R(roll, pitch, yaw), expected, atol=1e-12)


@settings(max_examples=200, deadline=None)
@given(**angles)
def test_quaternion_and_euler_agree(roll, pitch, yaw):
    R = euler_to_R(roll, pitch, yaw)
    assert np.allclose(quat_to_R(euler_to_quat(roll, pitch, yaw)), R, atol=1e-12)
    assert np.allclose(np.linalg.norm(euler_to_quat(roll, pitch, yaw)), 1.0)


def test_hand_built_quaternion_matches_euler(quat_ypr):
    for y, p, r in [(10, -30, 0), (100, -90, 0), (-170, 20, 15), (45, 0, -60)]:
        R = euler_to_R(math.radians(r), math.radians(p), math.radians(y))
        assert np.allclose(quat_to_R(quat_ypr(y, p, r)), R, atol=1e-12)
        # quat_to_R normalizes, and q and −q are the same rotation
        assert np.allclose(quat_to_R(-3.0 * np.array(quat_ypr(y, p, r))), R, atol=1e-12)


def test_batched_shapes():
    r = np.linspace(-1, 1, 7)
    R = euler_to_R(r, 0.2 * r, 3 * r)
    assert R.shape == (7, 3, 3)
    assert np.allclose(quat_to_R(euler_to_quat(r, 0.2 * r, 3 * r)), R)


# ---- attitude sources through camera_pose ----


def pose_of(cal, tel):
    pose = camera_pose(cal, tel, T0_UNIX + 1.03)
    assert pose.status[0] == "ok", pose.status[0]
    return pose


def optical_axis(pose):
    return pose.R_ned_from_cv[0][:, 2]


def image_right(pose):
    return pose.R_ned_from_cv[0][:, 0]


UAV = (5.0, 3.0, 90.0)  # roll, pitch, yaw (deg): roll/pitch must not leak into a gimbal's attitude


@pytest.mark.parametrize(
    "flags, heading_deg",
    [
        (64, 10.0),  # YAW_IN_EARTH_FRAME: yaw from North
        (32, 100.0),  # YAW_IN_VEHICLE_FRAME: UAV yaw 90° + gimbal 10°
        (16, 10.0),  # older rule: YAW_LOCK set → earth frame
        (0, 100.0),  # older rule: no YAW_LOCK → vehicle frame
        (16 | 32, 100.0),  # the explicit frame flag wins over YAW_LOCK
        (64 | 16, 10.0),
        (64 | 4, 10.0),  # other bits (ROLL_LOCK=4) change nothing
    ],
)
def test_gimbal_device_yaw_frames(make_cal, make_telemetry, flags, heading_deg):
    cal = make_cal()
    tel = make_telemetry(uav_rpy_deg=UAV, gimbal_ypr_deg=(10.0, -30.0, 0.0), gimbal_flags=flags)
    pose = pose_of(cal, tel)
    assert np.allclose(optical_axis(pose), look(heading_deg, -30.0), atol=1e-9)
    h = math.radians(heading_deg)
    assert np.allclose(image_right(pose), [-math.sin(h), math.cos(h), 0.0], atol=1e-9)


def test_gimbal_vehicle_frame_yaw_wraps(make_cal, make_telemetry):
    tel = make_telemetry(
        uav_rpy_deg=(0, 0, 170.0), gimbal_ypr_deg=(25.0, -45.0, 0.0), gimbal_flags=32
    )
    assert np.allclose(optical_axis(pose_of(make_cal(), tel)), look(-165.0, -45.0), atol=1e-9)


def test_gimbal_roll_tilts_the_image(make_cal, make_telemetry):
    """Gimbal rolled 20° right at heading 0, level: image right dips 20° below the horizon."""
    tel = make_telemetry(gimbal_ypr_deg=(0.0, 0.0, 20.0), gimbal_flags=64)
    pose = pose_of(make_cal(), tel)
    r = math.radians(20)
    assert np.allclose(image_right(pose), [0.0, math.cos(r), math.sin(r)], atol=1e-9)


def test_mount_orientation_yaw_is_relative_to_vehicle(make_cal, make_telemetry):
    cal = make_cal(mount={"attitude_source": "mount_orientation"})
    tel = make_telemetry(uav_rpy_deg=UAV, mount_rpy_deg=(0.0, -30.0, 10.0))
    assert np.allclose(optical_axis(pose_of(cal, tel)), look(100.0, -30.0), atol=1e-9)
    tel = make_telemetry(uav_rpy_deg=UAV)  # no MOUNT_ORIENTATION at all
    assert camera_pose(cal, tel, T0_UNIX + 1.0).status[0] == "no_gimbal"


@pytest.mark.parametrize(
    "uav_rpy_deg, axis",
    [
        ((0.0, 0.0, 37.0), [0.0, 0.0, 1.0]),
        # body rolled 10° right: a belly camera looks 10° to the left (West when heading North)
        ((10.0, 0.0, 0.0), [0.0, -math.sin(math.radians(10)), math.cos(math.radians(10))]),
        # nose up 10°: the belly, and the camera, face 10° forward
        ((0.0, 10.0, 0.0), [math.sin(math.radians(10)), 0.0, math.cos(math.radians(10))]),
    ],
)
def test_fixed_mount_down_looking(make_cal, make_telemetry, uav_rpy_deg, axis):
    cal = make_cal(mount={"attitude_source": "fixed", "fixed_rpy_deg": [0.0, -90.0, 0.0]})
    tel = make_telemetry(uav_rpy_deg=uav_rpy_deg, gimbal_ypr_deg=(50.0, 0.0, 0.0))  # gimbal ignored
    pose = pose_of(cal, tel)
    assert np.allclose(optical_axis(pose), axis, atol=1e-9)
    if uav_rpy_deg[:2] == (0.0, 0.0):  # image top towards the nose, right towards the right wing
        y = math.radians(uav_rpy_deg[2])
        assert np.allclose(image_right(pose), [-math.sin(y), math.cos(y), 0.0], atol=1e-9)


def test_fixed_mount_oblique(make_cal, make_telemetry):
    cal = make_cal(mount={"attitude_source": "fixed", "fixed_rpy_deg": [0.0, -30.0, 15.0]})
    tel = make_telemetry(uav_rpy_deg=(0.0, 0.0, 90.0))
    assert np.allclose(optical_axis(pose_of(cal, tel)), look(105.0, -30.0), atol=1e-9)


GEOD = Geod(ellps="WGS84")


def test_lever_arm_rotates_with_the_uav(make_cal, make_telemetry):
    """Camera 1 m ahead of, 0.25 m below the reported position; UAV heading East; nadir gimbal."""
    cal = make_cal(mount={"attitude_source": "gimbal_device", "camera_offset_m": [1.0, 0.0, 0.25]})
    tel = make_telemetry(
        height_m=30.0,
        uav_rpy_deg=(0.0, 0.0, 90.0),
        gimbal_ypr_deg=(0.0, -90.0, 0.0),
        depth_m=2.0,
        lat=47.5,
        lon=8.5,
    )
    pose = pose_of(cal, tel)
    assert np.allclose(pose.cam_offset_ned_m[0], [0.0, 1.0, 0.25], atol=1e-12)
    assert pose.height_m[0] == pytest.approx(30.0 - 0.25)
    assert pose.uav_height_m[0] == pytest.approx(30.0)
    fixes = locate(cal, pose, cal.camera.cx, cal.camera.cy)  # straight below the camera
    f = fixes[0]
    assert f.status == "ok"
    lon_e, lat_e, _ = GEOD.fwd(8.5, 47.5, 90.0, 1.0)
    assert GEOD.inv(f.lon, f.lat, lon_e, lat_e)[2] < 1e-3
    assert f.north_m == pytest.approx(0.0, abs=1e-9) and f.east_m == pytest.approx(1.0)


def test_lever_arm_follows_roll_and_pitch(make_cal, make_telemetry):
    cal = make_cal(mount={"attitude_source": "gimbal_device", "camera_offset_m": [1.0, 0.0, 0.25]})
    tel = make_telemetry(uav_rpy_deg=(0.0, 10.0, 0.0))
    pose = pose_of(cal, tel)
    c, s = math.cos(math.radians(10)), math.sin(math.radians(10))
    # nose up: forward tips up, down tips forward
    assert np.allclose(pose.cam_offset_ned_m[0], [c + 0.25 * s, 0.0, -s + 0.25 * c], atol=1e-12)


# ---- straight down, as rotations: no Euler round trip ----


def _f32(q):
    """A quaternion as MAVLink carries it (float32)."""
    return np.asarray(q, dtype=np.float32).astype(float)


def rot(axis, deg_):
    return rodrigues(np.eye(3)[axis], math.radians(deg_))


Z, Y, X = 2, 1, 0


@pytest.mark.parametrize(
    "rel_yaw_deg, vehicle_yaw_deg", [(52.3, 20.0), (-130.0, 175.0), (0.0, -90.0)]
)
def test_commanded_nadir_vehicle_frame_gimbal(
    make_cal, make_telemetry, rel_yaw_deg, vehicle_yaw_deg
):
    """Pitch exactly −90° with yaw relative to the vehicle (flags 44, as ArduCopter sends it), float32 on the
    wire: the image is turned by vehicle yaw + relative yaw; built here as Rz(ψ_v)·Rz(ψ_rel)·Ry(−90°)."""
    q = _f32(euler_to_quat(0.0, math.radians(-90.0), math.radians(rel_yaw_deg)))
    tel = make_telemetry(uav_rpy_deg=(4.0, -3.0, vehicle_yaw_deg), gimbal_flags=44)
    tel.gimbal.clear()
    for i in range(61):
        tel.add_gimbal(250_000 + 50 * i, q, 44, T0_UNIX + 0.05 * i)
    pose = pose_of(make_cal(), tel)
    R_expected = rot(Z, vehicle_yaw_deg) @ rot(Z, rel_yaw_deg) @ rot(Y, -90.0)
    assert np.allclose(pose.R_ned_from_cv[0][:, 2], [0.0, 0.0, 1.0], atol=1e-7)  # straight down
    h = math.radians(vehicle_yaw_deg + rel_yaw_deg)
    assert np.allclose(image_right(pose), [-math.sin(h), math.cos(h), 0.0], atol=1e-6)
    assert np.allclose(
        pose.R_ned_from_cv[0], R_expected @ np.array([[0, 0, 1], [1, 0, 0], [0, 1, 0.0]]), atol=1e-6
    )


def test_facts_quaternion_keeps_its_yaw(make_cal, make_telemetry):
    """The quaternion ArduCopter SITL sent pointing down (facts.md, "yaw 52.3°" from the vehicle's). A pure
    Rz(ψ)·Ry(−90°) is (c·a, s·a, −c·a, s·a) with c, s = cos, sin ψ/2 and a = √½: ψ = 2·atan2(x, w) = 52.67°."""
    q = _f32([0.63373, 0.31367, -0.63373, 0.31367])
    rel_yaw = math.degrees(2 * math.atan2(q[1], q[0]))
    assert rel_yaw == pytest.approx(52.3, abs=0.5)
    tel = make_telemetry(uav_rpy_deg=(0.0, 0.0, 30.0), gimbal_flags=44)
    tel.gimbal.clear()
    for i in range(61):
        tel.add_gimbal(250_000 + 50 * i, q, 44, T0_UNIX + 0.05 * i)
    pose = pose_of(make_cal(), tel)
    assert np.allclose(optical_axis(pose), [0.0, 0.0, 1.0], atol=1e-4)
    right = image_right(pose)
    assert math.degrees(math.atan2(-right[0], right[1])) == pytest.approx(30.0 + rel_yaw, abs=1e-3)


def test_earth_frame_nadir_ignores_vehicle_yaw(make_cal, make_telemetry):
    q = _f32(euler_to_quat(0.0, math.radians(-90.0), math.radians(-40.0)))
    for vehicle_yaw in (0.0, 77.0):
        tel = make_telemetry(uav_rpy_deg=(0.0, 0.0, vehicle_yaw), gimbal_flags=64)
        tel.gimbal.clear()
        for i in range(61):
            tel.add_gimbal(250_000 + 50 * i, q, 64, T0_UNIX + 0.05 * i)
        right = image_right(pose_of(make_cal(), tel))
        assert math.degrees(math.atan2(-right[0], right[1])) == pytest.approx(-40.0, abs=1e-4)


@pytest.mark.parametrize("roll_pitch, param", [("body", None), ("auto", 1.0)])
def test_servo_mount_roll_pitch_are_relative_to_the_leaning_body(
    make_cal, make_telemetry, roll_pitch, param
):
    """ArduPilot's servo mount (MNT1_TYPE 1) reports servo demands: target − lean, flagged as horizon-relative.
    The vehicle leans 15° right and 10° nose down; the camera is truly at pitch −60° from the horizon, yaw 0
    relative to the vehicle heading 30°. Built here as R_body · R(servo angles)."""
    lean_r, lean_p, yaw_v = 15.0, -10.0, 30.0
    servo = (0.0 - lean_r, -60.0 - lean_p, 0.0)  # roll, pitch, yaw demands
    q = _f32(euler_to_quat(*(math.radians(a) for a in servo)))
    tel = make_telemetry(uav_rpy_deg=(lean_r, lean_p, yaw_v), gimbal_flags=44)
    tel.gimbal.clear()
    for i in range(61):
        tel.add_gimbal(250_000 + 50 * i, q, 44, T0_UNIX + 0.05 * i)
    if param is not None:
        tel.add_param("MNT1_TYPE", param)
    cal = make_cal(mount={"attitude_source": "gimbal_device", "gimbal_roll_pitch": roll_pitch})
    pose = pose_of(cal, tel)
    R_body = rot(Z, yaw_v) @ rot(Y, lean_p) @ rot(X, lean_r)
    R_cam = R_body @ rot(Z, servo[2]) @ rot(Y, servo[1]) @ rot(X, servo[0])
    assert np.allclose(optical_axis(pose), R_cam[:, 0], atol=1e-6)
    # read as horizon-relative (the flags' word), the same message would point elsewhere
    horizon = pose_of(
        make_cal(mount={"attitude_source": "gimbal_device", "gimbal_roll_pitch": "horizon"}), tel
    )
    miss = math.degrees(math.acos(np.clip(optical_axis(horizon) @ optical_axis(pose), -1, 1)))
    assert miss > 10.0


def test_euler_rates_from_body_rates():
    """Body rates p, q, r of a leaning vehicle: the Euler angles of R·exp(ω dt) change at the returned rates."""
    roll, pitch, yaw = 0.3, -0.2, 1.0
    w = np.array([0.4, -0.7, 0.25])  # body FRD rad/s
    dt = 1e-6
    R1 = euler_to_R(roll, pitch, yaw) @ cv2.Rodrigues(w * dt)[0]
    r1 = math.atan2(R1[2, 1], R1[2, 2])
    p1 = -math.asin(R1[2, 0])
    y1 = math.atan2(R1[1, 0], R1[0, 0])
    expected = ((r1 - roll) / dt, (p1 - pitch) / dt, (y1 - yaw) / dt)
    assert np.allclose(euler_rates(roll, pitch, *w), expected, atol=1e-5)


def test_rotvec_matches_cv2():
    rng = np.random.default_rng(7)
    for r in rng.normal(0, 1.0, (20, 3)):
        assert np.allclose(rotvec(cv2.Rodrigues(r)[0]), r, atol=1e-9)

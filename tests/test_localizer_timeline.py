"""Time alignment: interpolation rules, staleness, the vehicle clock, and no-fix statuses."""

import math

import numpy as np
import pytest
from conftest import BOOT0_MS, T0_UNIX
from hypothesis import given, settings
from hypothesis import strategies as st

from localizer.attitude import quat_to_R
from localizer.fix import locate
from localizer.pose import camera_pose
from localizer.telemetry import Telemetry
from localizer.timeline import BEFORE_FIRST, GAP, OK, STALE, Series, VehicleClock


def deg(x):
    return math.radians(x)


def test_yaw_interpolates_across_180_not_through_0():
    s = Series("a", max_gap_s=1.0, max_hold_s=0.1)
    s.append(0.0, [deg(179.0)])
    s.append(0.2, [deg(-179.0)])
    mid, st_ = s.sample(0.1)
    assert st_ == OK
    assert abs(abs(math.degrees(mid[0])) - 180.0) < 1e-9  # ±180°, not 0°
    vals, status = s.sample([0.05, 0.15])
    assert list(status) == [OK, OK]
    assert np.degrees(vals[:, 0]) == pytest.approx([179.5, -179.5])


@settings(max_examples=200, deadline=None)
@given(a=st.floats(-180, 180), step=st.floats(-170, 170), w=st.floats(0, 1))
def test_angle_interpolation_takes_the_short_way(a, step, w):
    s = Series("a", max_gap_s=1.0, max_hold_s=0.1)
    b = (a + step + 180) % 360 - 180
    s.append(10.0, [deg(a)])
    s.append(11.0, [deg(b)])
    val, status = s.sample(10.0 + w)
    assert status == OK
    expected = a + w * step  # along the short arc, by hand
    diff = (math.degrees(val[0]) - expected + 180) % 360 - 180
    assert abs(diff) < 1e-7


def test_linear_columns_and_step_columns():
    s = Series("ls", max_gap_s=1.0, max_hold_s=0.1)
    s.append(1.0, [10.0, 16.0])
    s.append(1.5, [20.0, 32.0])
    v, _ = s.sample(1.2)
    assert v[0] == pytest.approx(14.0)
    assert v[1] == 16.0  # flags are held from the earlier sample


def test_quaternion_slerp_midpoint(quat_ypr):
    """Halfway between yaw 0° and yaw 90° (both pitched down 40°) the heading is 45°."""
    s = Series("qqqq", max_gap_s=1.0, max_hold_s=0.1)
    q0 = np.array(quat_ypr(0.0, 0.0, 0.0))
    q1 = np.array(quat_ypr(90.0, 0.0, 0.0))
    s.append(0.0, q0)
    s.append(0.5, -q1)  # the same rotation as q1: must still go the short way
    q, st_ = s.sample(0.25)
    assert st_ == OK
    assert np.isclose(np.linalg.norm(q), 1.0)
    R = quat_to_R(q)
    assert np.allclose(R[:, 0], [math.cos(deg(45)), math.sin(deg(45)), 0.0], atol=1e-12)
    # slerp keeps a constant angular rate: at a quarter of the way, 22.5°
    q, _ = s.sample(0.125)
    assert np.allclose(
        quat_to_R(q)[:, 0], [math.cos(deg(22.5)), math.sin(deg(22.5)), 0.0], atol=1e-12
    )


def test_quaternion_slerp_general_rotation(quat_ypr):
    a = np.array(quat_ypr(10.0, -80.0, 5.0))
    b = np.array(quat_ypr(70.0, -20.0, -15.0))
    s = Series("qqqq", max_gap_s=1.0, max_hold_s=0.1)
    s.append(0.0, a)
    s.append(1.0, b)
    Ra, Rb = quat_to_R(a), quat_to_R(b)
    q, _ = s.sample(0.5)
    Rm = quat_to_R(q)

    # the midpoint is equally far (in rotation angle) from both ends, half the total
    def angle(R1, R2):
        return math.acos(np.clip((np.trace(R1.T @ R2) - 1) / 2, -1, 1))

    total = angle(Ra, Rb)
    assert angle(Ra, Rm) == pytest.approx(total / 2, abs=1e-9)
    assert angle(Rm, Rb) == pytest.approx(total / 2, abs=1e-9)


def test_statuses_gap_stale_before_first():
    s = Series("l", max_gap_s=0.5, max_hold_s=0.2)
    for t in (0.0, 0.1, 0.2, 1.2, 1.3):  # a 1 s hole between 0.2 and 1.2
        s.append(t, [t * 10])
    ts = np.array([-0.01, 0.05, 0.7, 1.25, 1.3, 1.45, 1.55])
    vals, status = s.sample(ts)
    assert list(status) == [BEFORE_FIRST, OK, GAP, OK, OK, OK, STALE]
    assert vals[1, 0] == pytest.approx(0.5)
    assert vals[3, 0] == pytest.approx(12.5)
    assert vals[5, 0] == pytest.approx(13.0)  # held within max_hold_s, never extrapolated
    assert np.all(np.isnan(vals[[0, 2, 6], 0]))


def test_empty_series():
    vals, status = Series("a", 1.0, 1.0).sample([1.0, 2.0])
    assert list(status) == [BEFORE_FIRST, BEFORE_FIRST] and np.all(np.isnan(vals))


def test_out_of_order_and_non_finite_rejected():
    s = Series("la", max_gap_s=1.0, max_hold_s=0.1)
    assert s.append(1.0, [1.0, 0.1])
    assert not s.append(0.5, [2.0, 0.1])  # earlier
    assert not s.append(1.0, [2.0, 0.1])  # same time
    assert not s.append(2.0, [math.nan, 0.1])
    assert not s.append(2.0, [1.0, math.inf])
    assert not s.append(math.nan, [1.0, 0.1])
    assert not s.append(2.0, [1.0])  # wrong width
    assert s.rejected == 6 and len(s) == 1
    assert s.append(1.1, [3.0, 0.2])
    v, _ = s.sample(1.05)
    assert v[0] == pytest.approx(2.0)


def test_keep_s_bounds_memory_and_keeps_recent_samples():
    s = Series("l", max_gap_s=1.0, max_hold_s=0.5, keep_s=5.0)
    for i in range(10_000):
        s.append(i * 0.01, [i])
    assert len(s) < 2000
    v, st_ = s.sample(99.985)
    assert st_ == OK and v[0] == pytest.approx(9998.5)


# ---- VehicleClock ----


def test_system_time_median_resists_outliers():
    c = VehicleClock()
    off = 1_763_800_000.0
    for i in range(21):
        boot_ms = 1000 * i
        jitter = 50.0 if i in (3, 11) else 0.0  # two wild pairs
        c.add_system_time(boot_ms, round((off + i + jitter) * 1e6))
    assert c.source == "system_time"
    assert c.offset_s == pytest.approx(off, abs=1e-6)
    assert c.to_boot_s(off + 12.5) == pytest.approx(12.5)


def test_system_time_zero_is_ignored_and_receive_fallback_uses_least_delay():
    c = VehicleClock()
    assert c.source is None
    with pytest.raises(LookupError):
        c.to_boot_s(1.0)
    c.add_system_time(5000, 0)  # no GNSS time yet
    assert c.source is None
    off = 1_700_000_000.0
    for i, delay in enumerate([0.080, 0.030, 0.120, 0.021, 0.045]):
        c.add_receive(1000 * i, off + i + delay)
    assert c.source == "receive"
    assert c.offset_s == pytest.approx(off + 0.021, abs=1e-9)
    c.add_system_time(6000, round((off + 6) * 1e6))  # a real UNIX time takes over
    assert c.source == "system_time" and c.offset_s == pytest.approx(off, abs=1e-6)


def test_reboot_resets_the_clock():
    c = VehicleClock()
    c.add_system_time(600_000, round(1_000_600.0 * 1e6))
    assert c.offset_s == pytest.approx(1_000_000.0)
    c.add_system_time(2_000, round(1_000_700.0 * 1e6))  # boot clock went back 598 s: rebooted
    assert c.reboots == 1
    assert c.offset_s == pytest.approx(1_000_698.0)
    c.add_system_time(1_500, round(1_000_699.5 * 1e6))  # small step back: jitter, not a reboot
    assert c.reboots == 1


# ---- no fix rather than a guess ----


def test_camera_pose_statuses(make_cal, make_telemetry):
    cal = make_cal()
    t_mid = T0_UNIX + 1.0
    assert camera_pose(cal, make_telemetry(), t_mid).status[0] == "ok"

    tel = make_telemetry(system_time=False)
    assert camera_pose(cal, tel, t_mid).status[0] == "no_clock"

    tel = make_telemetry()
    tel.attitude.clear()
    assert camera_pose(cal, tel, t_mid).status[0] == "no_attitude"
    tel = make_telemetry()
    tel.gimbal.clear()
    assert camera_pose(cal, tel, t_mid).status[0] == "no_gimbal"
    tel = make_telemetry()
    tel.position.clear()
    assert camera_pose(cal, tel, t_mid).status[0] == "no_position"
    tel = make_telemetry()
    tel.depth.clear()
    assert camera_pose(cal, tel, t_mid).status[0] == "no_depth"

    # telemetry ends at T0 + 3 s: just after it the last values hold; later they are stale
    tel = make_telemetry(duration_s=3.0)
    pose = camera_pose(cal, tel, [T0_UNIX - 0.5, T0_UNIX + 3.1, T0_UNIX + 3.2, math.nan])
    assert list(pose.status) == ["no_attitude", "ok", "stale_attitude", "bad_time"]
    fixes = locate(cal, pose, [cal.camera.cx] * 4, [cal.camera.cy] * 4)
    assert list(fixes.status) == list(pose.status)
    assert np.isfinite(fixes.lat[1]) and np.all(np.isnan(fixes.lat[[0, 2, 3]]))


def test_stale_depth_and_attitude_gap(make_cal, make_telemetry):
    cal = make_cal()
    tel = make_telemetry(duration_s=3.0)
    tel.depth.clear()
    tel.add_depth(T0_UNIX, 2.0)
    tel.add_depth(T0_UNIX + 0.5, 2.1)
    pose = camera_pose(cal, tel, [T0_UNIX + 0.25, T0_UNIX + 1.4, T0_UNIX + 1.6])
    assert list(pose.status) == ["ok", "ok", "stale_depth"]  # depth_hold_s = 1.0
    assert pose.depth_m[0] == pytest.approx(2.05)

    tel = make_telemetry(duration_s=1.0)
    boot_ms = BOOT0_MS + 1000 + 400  # a 0.4 s hole in ATTITUDE (attitude_gap_s = 0.25)
    tel.add_attitude(boot_ms, 0.0, 0.0, 0.0)
    pose = camera_pose(cal, tel, T0_UNIX + 1.2)
    assert pose.status[0] == "stale_attitude"


def test_frame_time_maps_through_system_time(make_cal, make_telemetry):
    """Attitude that turns with time: the pose at a UNIX time shows the yaw of that instant."""
    cal = make_cal(mount={"attitude_source": "fixed", "fixed_rpy_deg": [0.0, 0.0, 0.0]})
    tel = make_telemetry(duration_s=0.0)
    tel.attitude.clear()
    for i in range(21):  # yaw 0.1 rad per second of boot time, from T0
        tel.add_attitude(BOOT0_MS + 100 * i, 0.0, 0.0, 0.01 * i)
        tel.add_position(BOOT0_MS + 100 * (i + 1), 47.5, 8.5, 412.0, 28.0)
        tel.add_depth(T0_UNIX + 0.1 * (i + 1), 1.0)
    pose = camera_pose(cal, tel, T0_UNIX + 1.234)
    assert pose.status[0] == "ok"
    axis = pose.R_ned_from_cv[0][:, 2]
    assert math.atan2(axis[1], axis[0]) == pytest.approx(
        0.1234, abs=1e-7
    )  # float64 UNIX times: ~0.2 µs


def test_reboot_does_not_reuse_old_telemetry(make_cal, make_telemetry):
    """After an autopilot reboot, samples on the old boot clock must not meet new frames."""
    cal = make_cal()
    tel = make_telemetry(duration_s=3.0)  # boot times 250 s … 253 s
    # the autopilot reboots; its new boot clock starts near 0 and maps to T0 + 300 s
    t_new = T0_UNIX + 300.0
    for i in range(10):
        boot_ms = 1000 + 100 * i
        t = t_new + 0.1 * i
        tel.clock.add_receive(boot_ms, t + 0.02)
        tel.clock.add_system_time(boot_ms, round(t * 1e6))
        tel.add_attitude(boot_ms, 0.0, 0.0, 0.0)
        tel.add_position(boot_ms, 47.5, 8.5, 412.0, 28.0)
        tel.add_gimbal(boot_ms, (0.7071067811865476, 0.0, -0.7071067811865476, 0.0), 64)
        tel.add_depth(t, 2.0)
    assert tel.clock.reboots == 1
    # a frame whose new-clock boot time (250.5 s) falls among the pre-reboot samples
    t_frame = t_new - 1.0 + 250.5
    tel.add_depth(t_frame, 2.0)
    pose = camera_pose(cal, tel, t_frame)
    assert (
        pose.status[0] == "stale_attitude"
    )  # the old samples are gone; the new ones are 249 s old
    # and the new samples are used for new frames
    pose = camera_pose(cal, tel, t_new + 0.45)
    assert pose.status[0] == "ok"


def test_telemetry_refuses_impossible_samples():
    tel = Telemetry()
    assert tel.add_attitude(1000, 0.1, -0.2, 3.0)
    assert not tel.add_attitude(1100, math.nan, 0.0, 0.0)
    assert not tel.add_attitude(1200, 0.0, 0.0, 100.0)  # degrees passed as radians
    assert not tel.add_attitude(900, 0.0, 0.0, 0.0)  # out of order
    assert tel.add_position(1000, 47.5, 8.5, 412.0, 28.0)
    assert not tel.add_position(1100, 0.0, 0.0, 0.0, 0.0)  # no GNSS fix yet
    assert not tel.add_position(1200, 475000000, 85000000, 412.0, 28.0)  # degE7 not converted
    assert tel.add_gimbal(1000, (1.0, 0.0, 0.0, 0.0), 64)
    assert not tel.add_gimbal(1100, (0.0, 0.0, 0.0, 0.0), 64)  # all-zero "no attitude" quaternion
    assert not tel.add_gimbal(1200, (1.0, math.nan, 0.0, 0.0), 64)
    assert tel.add_depth(T0_UNIX, 2.0)
    assert not tel.add_depth(T0_UNIX + 1, math.nan)
    assert not tel.add_depth(T0_UNIX + 2, -20.0)
    assert len(tel.attitude) == len(tel.position) == len(tel.gimbal) == len(tel.depth) == 1

"""Time alignment: interpolation rules (linear, angles, slerp, Hermite with rates), extrapolation,
staleness, and the no-fix statuses of camera poses."""

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
from localizer.timeline import BEFORE_FIRST, GAP, OK, STALE, Series


def deg(x):
    return math.radians(x)


def test_yaw_interpolates_across_180_not_through_0():
    s = Series("a", max_gap_s=1.0, max_hold_s=0.1)
    s.append(0.0, [deg(179.0)])
    s.append(0.2, [deg(-179.0)])
    mid, st_, _ = s.sample(0.1)
    assert st_ == OK
    assert abs(abs(math.degrees(mid[0])) - 180.0) < 1e-9  # ±180°, not 0°
    vals, status, _ = s.sample([0.05, 0.15])
    assert list(status) == [OK, OK]
    assert np.degrees(vals[:, 0]) == pytest.approx([179.5, -179.5])


@settings(max_examples=200, deadline=None)
@given(a=st.floats(-180, 180), step=st.floats(-170, 170), w=st.floats(0, 1))
def test_angle_interpolation_takes_the_short_way(a, step, w):
    s = Series("a", max_gap_s=1.0, max_hold_s=0.1)
    b = (a + step + 180) % 360 - 180
    s.append(10.0, [deg(a)])
    s.append(11.0, [deg(b)])
    val, status, _ = s.sample(10.0 + w)
    assert status == OK
    expected = a + w * step  # along the short arc, by hand
    diff = (math.degrees(val[0]) - expected + 180) % 360 - 180
    assert abs(diff) < 1e-7


def test_linear_columns_and_step_columns():
    s = Series("ls", max_gap_s=1.0, max_hold_s=0.1)
    s.append(1.0, [10.0, 16.0])
    s.append(1.5, [20.0, 32.0])
    v = s.sample(1.2).values
    assert v[0] == pytest.approx(14.0)
    assert v[1] == 16.0  # flags are held from the earlier sample


def test_quaternion_slerp_midpoint(quat_ypr):
    """Halfway between yaw 0° and yaw 90° (both pitched down 40°) the heading is 45°."""
    s = Series("qqqq", max_gap_s=1.0, max_hold_s=0.1)
    q0 = np.array(quat_ypr(0.0, 0.0, 0.0))
    q1 = np.array(quat_ypr(90.0, 0.0, 0.0))
    s.append(0.0, q0)
    s.append(0.5, -q1)  # the same rotation as q1: must still go the short way
    q, st_, _ = s.sample(0.25)
    assert st_ == OK
    assert np.isclose(np.linalg.norm(q), 1.0)
    R = quat_to_R(q)
    assert np.allclose(R[:, 0], [math.cos(deg(45)), math.sin(deg(45)), 0.0], atol=1e-12)
    # slerp keeps a constant angular rate: at a quarter of the way, 22.5°
    q = s.sample(0.125).values
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
    q = s.sample(0.5).values
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
    vals, status, err = s.sample(ts)
    assert list(status) == [BEFORE_FIRST, OK, GAP, OK, OK, OK, STALE]
    assert vals[1, 0] == pytest.approx(0.5)
    assert vals[3, 0] == pytest.approx(12.5)
    # held within max_hold_s (no rate column to extrapolate with)
    assert vals[5, 0] == pytest.approx(13.0)
    assert np.all(np.isnan(vals[[0, 2, 6], 0]))
    # the hold's error: the last rate of change (10 per second) times the 0.15 s since the last sample
    assert err[5, 0] == pytest.approx(1.5) and err[3, 0] == 0.0 and err[4, 0] == 0.0


def test_empty_series():
    vals, status, _ = Series("a", 1.0, 1.0).sample([1.0, 2.0])
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
    v = s.sample(1.05).values
    assert v[0] == pytest.approx(2.0)


def test_keep_s_bounds_memory_and_keeps_recent_samples():
    s = Series("l", max_gap_s=1.0, max_hold_s=0.5, keep_s=5.0)
    for i in range(10_000):
        s.append(i * 0.01, [i])
    assert len(s) < 2000
    v, st_, _ = s.sample(99.985)
    assert st_ == OK and v[0] == pytest.approx(9998.5)


# ---- Hermite interpolation with rates ----


WOBBLE_RAD = math.radians(2.0)


def _wobble(t, amp=WOBBLE_RAD, hz=1.2):
    w = 2 * math.pi * hz
    return amp * np.sin(w * t + 0.3), amp * w * np.cos(w * t + 0.3)


def test_hermite_follows_a_wobble_sampled_at_4_hz_where_linear_cannot():
    """2° at 1.2 Hz sampled at 4 Hz: the cubic with the rates stays within the textbook bound
    h^4/384 max|f^(4)|; linear interpolation (without rates) is off by most of a degree."""
    t_s = np.arange(0.0, 5.0, 0.25)
    herm, lin = Series("Hd", 0.6, 0.1), Series("a", 0.6, 0.1)
    for t in t_s:
        a, rate = _wobble(t)
        herm.append(t, [a, rate])
        lin.append(t, [a])
    tq = np.linspace(0.3, 4.7, 400)
    truth, _ = _wobble(tq)
    e_h = np.abs(herm.sample(tq).values[:, 0] - truth).max()
    e_l = np.abs(lin.sample(tq).values[:, 0] - truth).max()
    amp, w, h = math.radians(2.0), 2 * math.pi * 1.2, 0.25
    assert e_h <= h**4 / 384 * amp * w**4 * 1.01
    assert e_l > 10 * e_h and math.degrees(e_l) > 0.5


def test_hermite_angle_wraps_and_nan_rate_falls_back_to_linear():
    s = Series("Hd", 1.0, 0.1)
    s.append(0.0, [deg(179.0), deg(4.0)])  # turning at 4°/s through ±180°
    s.append(0.5, [deg(-179.0), deg(4.0)])
    v = s.sample(0.25).values[0]
    assert abs(abs(math.degrees(v)) - 180.0) < 1e-9
    s = Series("hd", 1.0, 0.1)
    s.append(0.0, [0.0, math.nan])  # no rate: linear
    s.append(1.0, [1.0, 5.0])
    assert s.sample(0.5).values[0] == pytest.approx(0.5)
    assert s.rejected == 0


def test_extrapolation_with_rates_and_its_error():
    s = Series("hd", 1.0, 0.2)
    s.append(0.0, [0.0, 1.0])
    s.append(0.1, [0.105, 1.1])  # the rate grew by 1 per second
    vals, status, err = s.sample([0.15, 0.3, 0.31])
    assert list(status) == [OK, OK, STALE]
    assert vals[0, 0] == pytest.approx(0.105 + 1.1 * 0.05)
    assert vals[1, 0] == pytest.approx(0.105 + 1.1 * 0.2)
    # half the rate's change per second × dt²
    assert err[0, 0] == pytest.approx(0.5 * 1.0 * 0.05**2)
    assert err[1, 0] == pytest.approx(0.5 * 1.0 * 0.2**2)


# ---- no fix rather than a guess ----


def test_camera_pose_statuses(make_cal, make_telemetry):
    cal = make_cal()
    t_mid = T0_UNIX + 1.0
    assert camera_pose(cal, make_telemetry(), t_mid).status[0] == "ok"

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

    # telemetry ends at T0 + 3 s: just after it the last values are extrapolated; later they are stale
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
    boot_ms = BOOT0_MS + 1000 + 800  # a 0.8 s hole in ATTITUDE (attitude_gap_s = 0.6)
    tel.add_attitude(boot_ms, 0.0, 0.0, 0.0, (0.0, 0.0, 0.0), T0_UNIX + 1.8)
    pose = camera_pose(cal, tel, T0_UNIX + 1.4)
    assert pose.status[0] == "stale_attitude"


def _turning(tel, delays_s, timesync=False):
    """ATTITUDE whose yaw turns 0.1 rad/s from T0, received after ``delays_s`` (cycled); optional TIMESYNC
    replies over a symmetric link whose one-way delay is the least of ``delays_s``."""
    link = min(delays_s)
    for i in range(41):
        boot_ms = BOOT0_MS + 100 * i
        t = T0_UNIX + 0.1 * i
        d = delays_s[i % len(delays_s)]
        tel.add_attitude(boot_ms, 0.0, 0.0, 0.01 * i, (0.0, 0.0, 0.1), t + d)
        tel.add_position(boot_ms, 47.5, 8.5, 412.0, 28.0, (0.0, 0.0, 0.0), t + d)
        tel.add_depth(t, 1.0)
        if (
            timesync
        ):  # our request left at t, arrived at t + link; the reply came back after link again
            tel.add_timesync(round((boot_ms / 1000 + link) * 1e9), round(t * 1e9), t + 2 * link)


def _yaw_at(cal, tel, t):
    pose = camera_pose(cal, tel, t)
    assert pose.status[0] == "ok"
    axis = pose.R_ned_from_cv[0][:, 2]
    return math.atan2(axis[1], axis[0])


def test_frame_time_maps_through_receive_times(make_cal):
    """Yaw turning 0.1 rad/s: the pose at a station time shows that instant's yaw once the link delay is
    known, from TIMESYNC, configured or estimated from the video's motion; without it, the pose is the least
    delay (20 ms) late, and the frame's time sigma carries [timing] unknown_latency_sigma_s on top of time_s."""
    fixed = {"attitude_source": "fixed", "fixed_rpy_deg": [0.0, 0.0, 0.0]}
    cal = make_cal(
        mount=fixed, uncertainty={"time_s": 0.03}, timing={"unknown_latency_sigma_s": 0.04}
    )
    delays = [0.045, 0.02, 0.07, 0.033]
    t = T0_UNIX + 1.234

    def time_of(cal, tel):
        pose = camera_pose(cal, tel, t)
        return pose.time_source[0], pose.sigma_time_s[0]

    tel = Telemetry(cal.timing)
    _turning(tel, delays)
    assert tel.latency_source == "unknown" and tel.latency_sigma_s == 0.04
    assert _yaw_at(cal, tel, t) == pytest.approx(0.1234 - 0.1 * 0.02, abs=1e-7)
    assert time_of(cal, tel) == ("unknown", pytest.approx(0.05, abs=1e-12))  # √(0.03² + 0.04²)
    tel.set_motion_latency(0.02, 0.004)  # the frames' offset to the telemetry as aligned so far
    assert tel.latency_source == "motion" and tel.uav_latency_s == pytest.approx(0.02, abs=1e-12)
    assert _yaw_at(cal, tel, t) == pytest.approx(0.1234, abs=1e-6)
    assert time_of(cal, tel) == ("motion", pytest.approx(np.hypot(0.03, 0.004), abs=1e-12))
    tel = Telemetry(cal.timing)
    _turning(tel, delays, timesync=True)
    assert tel.latency_source == "timesync" and tel.uav_latency_s == pytest.approx(0.02, abs=1e-6)
    assert _yaw_at(cal, tel, t) == pytest.approx(0.1234, abs=1e-6)
    tel.set_motion_latency(0.05, 0.004)  # a measured delay wins over an estimate
    assert tel.latency_source == "timesync" and tel.uav_latency_s == pytest.approx(0.02, abs=1e-6)
    assert time_of(cal, tel) == ("timesync", pytest.approx(0.03, abs=1e-12))
    cal_timed = make_cal(mount=fixed, timing={"mavlink_latency_s": 0.02})
    tel = Telemetry(cal_timed.timing)
    _turning(tel, delays)
    assert tel.latency_source == "configured"
    assert _yaw_at(cal_timed, tel, t) == pytest.approx(0.1234, abs=1e-6)
    assert time_of(cal_timed, tel) == ("configured", pytest.approx(0.02, abs=1e-12))


def test_station_clock_off_gnss_changes_nothing_but_gnss_time(make_cal, make_telemetry):
    """SYSTEM_TIME 2.5 s ahead of the station clock: the same poses, a GNSS time 2.5 s later, one notice."""
    cal = make_cal()
    in_sync = make_telemetry()
    tel = make_telemetry(system_time=False)
    for i in range(10):  # after the other samples (boot 250 s … 253 s), on the same clock
        boot_ms = BOOT0_MS + 3100 + 200 * i
        t = T0_UNIX + 3.1 + 0.2 * i
        tel.add_system_time(boot_ms, round((t + 2.5) * 1e6), t)
    a, b = camera_pose(cal, in_sync, T0_UNIX + 1.0), camera_pose(cal, tel, T0_UNIX + 1.0)
    assert np.array_equal(a.R_ned_from_cv, b.R_ned_from_cv) and a.lat_deg[0] == b.lat_deg[0]
    assert tel.station_minus_gnss_s == pytest.approx(-2.5, abs=1e-6)
    assert b.t_gnss[0] == pytest.approx(T0_UNIX + 3.5, abs=1e-6)
    assert a.t_gnss[0] == pytest.approx(T0_UNIX + 1.0, abs=1e-6)
    assert len(tel.notices) == 1 and "2.50 s behind GNSS" in tel.notices[0]


def test_reboot_keeps_earlier_telemetry_and_starts_a_new_segment(make_cal, make_telemetry):
    """A brown-out: the boot clock restarts near 0. Frames before it keep their telemetry, frames after
    it use the new segment, and the reboot is noticed once."""
    cal = make_cal()
    tel = make_telemetry(duration_s=3.0)  # boot times 250 s … 253 s at T0 … T0 + 3 s
    # rebooted at T0 + 3.2 s; telemetry again from T0 + 5 s, boot clock at 1.8 s
    t_new = T0_UNIX + 5.0
    for i in range(20):
        boot_ms = 1800 + 100 * i
        t = t_new + 0.1 * i
        tel.add_attitude(boot_ms, 0.0, 0.0, 0.0, (0.0, 0.0, 0.0), t + 0.02)
        tel.add_position(boot_ms, 47.5, 8.5, 412.0, 28.0, (0.0, 0.0, 0.0), t + 0.02)
        tel.add_gimbal(boot_ms, (0.7071067811865476, 0.0, -0.7071067811865476, 0.0), 64, t + 0.02)
        tel.add_depth(t, 2.0)
    assert tel.uav_clock.segments == 1
    assert len(tel.notices) == 1 and "rebooted" in tel.notices[0]
    pose = camera_pose(cal, tel, [T0_UNIX + 2.5, T0_UNIX + 4.0, t_new + 0.55])
    assert list(pose.status) == ["ok", "stale_attitude", "ok"]


def test_telemetry_refuses_impossible_samples():
    tel = Telemetry()
    t, z = T0_UNIX, (0.0, 0.0, 0.0)
    assert tel.add_attitude(1000, 0.1, -0.2, 3.0, z, t)
    assert not tel.add_attitude(1100, math.nan, 0.0, 0.0, z, t + 0.1)
    assert not tel.add_attitude(1200, 0.0, 0.0, 100.0, z, t + 0.2)  # degrees passed as radians
    assert "radians" in tel.refusal
    assert not tel.add_attitude(900, 0.0, 0.0, 0.0, z, t + 0.3)  # out of order
    assert tel.add_position(1000, 47.5, 8.5, 412.0, 28.0, z, t)
    assert not tel.add_position(1100, 0.0, 0.0, 0.0, 0.0, z, t + 0.1)
    assert tel.refusal == "lat/lon 0/0: the UAV has no GPS fix yet"
    # degE7 not converted
    assert not tel.add_position(1200, 475000000, 85000000, 412.0, 28.0, z, t + 0.2)
    assert "out of range" in tel.refusal
    assert tel.add_gimbal(1000, (1.0, 0.0, 0.0, 0.0), 64, t)
    # all-zero "no attitude" quaternion
    assert not tel.add_gimbal(1100, (0.0, 0.0, 0.0, 0.0), 64, t + 0.1)
    assert not tel.add_gimbal(1200, (1.0, math.nan, 0.0, 0.0), 64, t + 0.2)
    assert tel.add_depth(T0_UNIX, 2.0)
    assert not tel.add_depth(T0_UNIX + 1, math.nan)
    assert not tel.add_depth(T0_UNIX + 2, -20.0)
    assert len(tel.attitude) == len(tel.position) == len(tel.gimbal) == len(tel.depth) == 1
    assert tel.uav_clock.segments == 0  # the refused out-of-order boot time did not fake a reboot

"""The field-condition knobs of the simulator, each checked against the scenario's own truth.

Clock offsets (station, UUV), depth arrival times, TIMESYNC, GPS_RAW_INT, true body
rates, GLOBAL_POSITION_INT velocities, a wobbling airframe with slow ATTITUDE, the
straight-down vehicle-frame gimbal, the servo mount and an autopilot reboot. The
sessions are generated without video (fast); the twin test renders a short clip.
No accuracy of the localizer is asserted here for the new conditions.
"""

import csv
import json
import struct
from pathlib import Path

import numpy as np
import pymap3d
import pytest
from scipy.spatial.transform import Rotation

from groundstation.mavlink.ingest import mavutil
from groundstation.session.read import load_session
from localizer.attitude import euler_to_R, quat_to_R
from sim_fixtures.generate import generate
from sim_fixtures.motion import Motion
from sim_fixtures.scenario import load_scenario, scenario_from_dict, with_overrides
from sim_fixtures.tlog import Clock

SCENARIOS = Path(__file__).resolve().parents[1] / "sim_fixtures" / "scenarios"
NEW = (
    "clock_offset",
    "clock_sync",
    "nadir_vehicle_frame",
    "slow_attitude",
    "servo_mount",
    "reboot",
)
UAV_KINDS = {
    "HEARTBEAT",
    "SYSTEM_TIME",
    "ATTITUDE",
    "GLOBAL_POSITION_INT",
    "GPS_RAW_INT",
    "TIMESYNC",
    "GIMBAL_DEVICE_ATTITUDE_STATUS",
}


def read_tlog(path):
    """``[(record µs, raw frame bytes, decoded message)]`` split by hand from the tlog."""
    mav = mavutil().mavlink.MAVLink(None)
    data, out, i = path.read_bytes(), [], 0
    while i < len(data):
        (t_us,) = struct.unpack(">Q", data[i : i + 8])
        size = 10 + data[i + 9] + 2 + (13 if data[i + 10] & 1 else 0)
        frame = data[i + 8 : i + 8 + size]
        out.append((t_us, frame, mav.decode(bytearray(frame))))
        i += 8 + size
    return out


def of_kind(records, kind):
    return [(t, m) for t, _, m in records if m.get_type() == kind]


def read_csv(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def read_depth(path):
    return [json.loads(line) for line in path.read_text().splitlines()]


@pytest.fixture(scope="module")
def sessions(tmp_path_factory):
    root = tmp_path_factory.mktemp("knobs")
    out = {}
    for name in NEW:
        sc = load_scenario(SCENARIOS / f"{name}.toml")
        generate(sc, root / name, video=False)
        out[name] = (sc, root / name)
    return out


@pytest.mark.parametrize("name", NEW)
def test_new_scenarios_load_as_sessions(sessions, name):
    sc, path = sessions[name]
    session = load_session(path)
    # the only warnings are the ones the condition is about (clocks that disagree, a reboot)
    expected = {"clock_offset": ("behind GNSS", "UUV's clock"), "reboot": ("rebooted",)}.get(
        name, ()
    )
    assert all(any(e in w for e in expected) for w in session.warnings), session.warnings
    n = round(sc.duration_s * sc.fps)
    assert len(session.truth["t"]) == n and len(session.track["t"]) == n
    assert np.isfinite(session.track["u"]).mean() > 0.95  # the UUV stays in view
    assert all(set(r) == {"t", "depth_m", "t_recv"} for r in read_depth(path / "depth.jsonl"))


# --- clocks ----------------------------------------------------------------------------------------


def test_clock_offset_twin_differs_only_in_its_times(sessions):
    (sc, a), (sc0, b) = sessions["clock_offset"], sessions["clock_sync"]
    st, uuv = sc.clock.station_offset_s, sc.clock.uuv_offset_s
    assert (st, uuv) == (-2.5, 291.0) and (sc0.clock.station_offset_s, sc0.clock.uuv_offset_s) == (
        0.0,
        0.0,
    )
    for name, cols in (
        ("video_frames.csv", ("frame",)),
        ("track.csv", ("u", "v")),
        ("truth.csv", ("lat", "lon", "depth_m")),
    ):
        ra, rb = read_csv(a / name), read_csv(b / name)
        assert [[r[c] for c in cols] for r in ra] == [
            [r[c] for c in cols] for r in rb
        ]  # the same text
        assert np.allclose(
            [float(x["t"]) - float(y["t"]) for x, y in zip(ra, rb)], st, atol=1.5e-6, rtol=0
        )
    frames = read_csv(a / "video_frames.csv")
    assert [r["t"] for r in read_csv(a / "truth.csv")] == [r["t"] for r in frames]
    assert float(frames[0]["t"]) == pytest.approx(sc.start_unix + st, abs=1e-6)

    da, db = read_depth(a / "depth.jsonl"), read_depth(b / "depth.jsonl")
    assert [r["depth_m"] for r in da] == [r["depth_m"] for r in db]
    assert np.allclose([x["t"] - y["t"] for x, y in zip(da, db)], uuv, atol=1.5e-6, rtol=0)
    assert np.allclose([x["t_recv"] - y["t_recv"] for x, y in zip(da, db)], st, atol=1.5e-6, rtol=0)

    ta, tb = read_tlog(a / "uav.tlog"), read_tlog(b / "uav.tlog")
    assert len(ta) == len(tb)
    for (t1, f1, m1), (t2, f2, m2) in zip(ta, tb):
        assert t1 - t2 == round(st * 1e6)
        if m1.get_type() == "TIMESYNC":  # the request's station-clock send time, echoed
            assert m1.tc1 == m2.tc1 and m1.ts1 - m2.ts1 == round(st * 1e9)
        else:
            assert f1 == f2  # every other frame the same bytes, SYSTEM_TIME's GNSS time included


def test_depth_times_are_the_uuvs_clock_and_the_stations_arrival(sessions):
    sc, path = sessions["clock_offset"]
    recs = read_depth(path / "depth.jsonl")
    t_true = np.array([r["t"] for r in recs]) - sc.clock.uuv_offset_s
    arrived = np.array([r["t_recv"] for r in recs]) - sc.clock.station_offset_s
    delay = arrived - t_true
    assert np.all(np.diff(arrived) >= 0) and np.all(np.diff(t_true) > 0)
    assert delay.min() >= sc.link.depth_delay_s - 2e-6
    assert np.median(delay) < sc.link.depth_delay_s + 3 * sc.link.depth_jitter_s
    assert np.std(delay) > 0.2 * sc.link.depth_jitter_s
    tel = sc.telemetry  # measured over the telemetry's span at depth_hz
    assert t_true[0] - sc.start_unix == pytest.approx(-tel.lead_s, abs=0.2 / tel.depth_hz)
    assert len(recs) == pytest.approx((tel.lead_s + sc.duration_s + 1) * tel.depth_hz, abs=1)


def test_tlog_records_are_station_receive_times(sessions):
    sc, path = sessions["clock_offset"]
    clock = Clock.of(sc)
    st_us = round(sc.clock.station_offset_s * 1e6)
    for t_rec, m in of_kind(read_tlog(path / "uav.tlog"), "SYSTEM_TIME"):
        # GNSS time, not the station's
        assert m.time_unix_usec == clock.boot_epoch_us + 1000 * m.time_boot_ms
        delay = (t_rec - st_us - m.time_unix_usec) / 1e6
        assert sc.link.delay_s <= delay < sc.link.delay_s + 0.3


def test_timesync_replies_like_ardupilot(sessions):
    sc, path = sessions["clock_offset"]
    clock = Clock.of(sc)
    st_us = round(sc.clock.station_offset_s * 1e6)
    replies = of_kind(read_tlog(path / "uav.tlog"), "TIMESYNC")
    span = sc.telemetry.lead_s + sc.duration_s + 1.0
    assert abs(len(replies) - span * sc.telemetry.timesync_hz) <= 1
    up, down, est = [], [], []
    for t_rec, m in replies:
        assert m.get_srcSystem() == 1 and m.get_srcComponent() == 1 and m.tc1 > 0
        sent_true = m.ts1 // 1000 - st_us  # ts1: the station's send time in ns
        # tc1: the autopilot's boot time in ns at arrival
        arrived_true = clock.boot_epoch_us + m.tc1 // 1000
        up.append((arrived_true - sent_true) / 1e6)
        down.append((t_rec - st_us - arrived_true) / 1e6)
        # station µs at boot zero, from one exchange
        est.append((m.ts1 / 1e3 + t_rec) / 2 - m.tc1 / 1e3)
    up, down = np.array(up), np.array(down)
    d, j = sc.link.delay_s, sc.link.jitter_s
    assert up.min() >= d - 1e-6 and down.min() >= d + 0.0008 - 1e-6
    # symmetric on average
    assert np.median(up) < d + 3 * j and np.median(down) < d + 0.0008 + 3 * j
    # the usual estimate recovers the boot clock's zero on the station's clock to the link's asymmetry
    assert (
        np.abs(np.array(est) - (clock.boot_epoch_us + st_us)).max()
        < 0.5e6 * (up.max() + down.max() - 2 * d) + 1e3
    )


def test_gps_raw_int_is_the_reported_position_with_gnss_time(sessions):
    sc, path = sessions["clock_offset"]
    clock = Clock.of(sc)
    st_us = round(sc.clock.station_offset_s * 1e6)
    recs = read_tlog(path / "uav.tlog")
    gps = of_kind(recs, "GPS_RAW_INT")
    span = sc.telemetry.lead_s + sc.duration_s + 1.0
    assert (
        abs(len(gps) / span - sc.telemetry.gps_raw_hz) <= 0.1 * sc.telemetry.gps_raw_hz + 1 / span
    )
    gpi = [m for _, m in of_kind(recs, "GLOBAL_POSITION_INT")]
    t_gpi = np.array([clock.boot_epoch_us + 1000 * m.time_boot_ms for m in gpi]) / 1e6
    s = sc.site
    for t_rec, m in gps:
        assert (m.fix_type, m.satellites_visible, m.eph, m.epv) == (3, 14, 70, 110)
        assert (m.h_acc, m.v_acc) == (20, 40) and m.alt_ellipsoid - m.alt == round(
            s.geoid_separation_m * 1000
        )
        # true UNIX µs
        assert sc.link.delay_s <= (t_rec - st_us - m.time_usec) / 1e6 < sc.link.delay_s + 0.3
        t = m.time_usec / 1e6
        lat = np.interp(t, t_gpi, [g.lat for g in gpi]) / 1e7
        lon = np.interp(t, t_gpi, [g.lon for g in gpi]) / 1e7
        alt = np.interp(t, t_gpi, [g.alt for g in gpi]) / 1e3
        n, e, dd = pymap3d.geodetic2ned(m.lat / 1e7, m.lon / 1e7, m.alt / 1e3, lat, lon, alt)
        assert np.hypot(n, e) < 0.015 and abs(dd) < 0.005
        vn = np.interp(t, t_gpi, [g.vx for g in gpi]) / 100
        ve = np.interp(t, t_gpi, [g.vy for g in gpi]) / 100
        assert abs(m.vel / 100 - np.hypot(vn, ve)) < 0.015


def test_global_position_int_velocity_is_the_rate_of_its_positions(sessions):
    sc, path = sessions["clock_sync"]
    clock = Clock.of(sc)
    gpi = [m for _, m in of_kind(read_tlog(path / "uav.tlog"), "GLOBAL_POSITION_INT")]
    t = np.array([clock.boot_epoch_us + 1000 * m.time_boot_ms for m in gpi]) / 1e6
    lat, lon, alt = (
        np.array([getattr(m, k) for m in gpi]) / f
        for k, f in (("lat", 1e7), ("lon", 1e7), ("alt", 1e3))
    )
    ned = np.array(pymap3d.geodetic2ned(lat, lon, alt, lat[0], lon[0], alt[0])).T
    k = 5  # central differences over ~1 s: the 1e-7 deg quantization (1 cm) stays below 1 cm/s
    rate = (ned[2 * k :] - ned[: -2 * k]) / (t[2 * k :] - t[: -2 * k])[:, None]
    reported = np.array([(m.vx, m.vy, m.vz) for m in gpi])[k:-k] / 100
    assert np.abs(rate - reported).max() < 0.02
    assert np.abs(reported[:, :2]).max() > 0.03  # it does move


# --- attitude --------------------------------------------------------------------------------------


def euler_kinematics(rpy, rpy_dot):
    """Body rates (p, q, r) from Z-Y-X Euler angles and their time derivatives (the textbook relation)."""
    phi, theta = rpy[:, 0], rpy[:, 1]
    dphi, dtheta, dpsi = rpy_dot.T
    return np.column_stack(
        [
            dphi - dpsi * np.sin(theta),
            dtheta * np.cos(phi) + dpsi * np.sin(phi) * np.cos(theta),
            -dtheta * np.sin(phi) + dpsi * np.cos(phi) * np.cos(theta),
        ]
    )


@pytest.mark.parametrize("name", ["slow_attitude", "servo_mount", "nadir_vehicle_frame"])
def test_attitude_rates_are_body_rates(sessions, name):
    sc, path = sessions[name]
    motion, clock = Motion(sc), Clock.of(sc)
    att = [m for _, m in of_kind(read_tlog(path / "uav.tlog"), "ATTITUDE")]
    tau = clock.tau_s([m.time_boot_ms for m in att])
    h = 1e-5
    rpy = motion.uav_rpy(tau)
    rpy_dot = (motion.uav_rpy(tau + h) - motion.uav_rpy(tau - h)) / (2 * h)
    pqr = np.array([(m.rollspeed, m.pitchspeed, m.yawspeed) for m in att])
    assert np.abs(pqr - euler_kinematics(rpy, rpy_dot)).max() < 1e-5
    assert np.abs(pqr - rpy_dot).max() > 2e-3  # not the Euler angles' derivatives


def test_attitude_rates_match_the_reported_attitudes_own_motion(sessions):
    """Independent of the simulator's motion model: the rotation between consecutive ATTITUDE samples."""
    _, path = sessions["servo_mount"]
    att = [m for _, m in of_kind(read_tlog(path / "uav.tlog"), "ATTITUDE")]
    R = euler_to_R(*np.array([(m.roll, m.pitch, m.yaw) for m in att]).T)
    t = np.array([m.time_boot_ms for m in att]) / 1e3
    step = (
        Rotation.from_matrix(np.einsum("nji,njk->nik", R[:-1], R[1:])).as_rotvec()
        / np.diff(t)[:, None]
    )
    pqr = np.array([(m.rollspeed, m.pitchspeed, m.yawspeed) for m in att])
    assert np.abs(step - (pqr[:-1] + pqr[1:]) / 2).max() < 2e-3
    assert np.abs(pqr).max() > 0.02


def test_wobbling_airframe_at_slow_attitude_rate(sessions):
    sc, path = sessions["slow_attitude"]
    clock = Clock.of(sc)
    att = [m for _, m in of_kind(read_tlog(path / "uav.tlog"), "ATTITUDE")]
    span = sc.telemetry.lead_s + sc.duration_s + 1.0
    assert sc.telemetry.attitude_hz == 4.0 and abs(len(att) - 4.0 * span) <= 2
    tau = clock.tau_s([m.time_boot_ms for m in att])
    calm = Motion(with_overrides(sc, uav={"wobble_deg": 0.0})).uav_rpy(tau)
    wobble = np.degrees(np.array([(m.roll, m.pitch) for m in att]) - calm[:, :2])
    assert 1.5 < np.abs(wobble).max(axis=0).min() and np.abs(wobble).max() <= 2.0 + 1e-4
    dense = np.arange(0, 5, 0.01)  # a 1.2 Hz oscillation: its spectrum peaks there
    diff = (
        Motion(sc).uav_rpy(dense)[:, 0]
        - Motion(with_overrides(sc, uav={"wobble_deg": 0.0})).uav_rpy(dense)[:, 0]
    )
    f = np.fft.rfftfreq(len(dense), 0.01)
    assert f[np.argmax(np.abs(np.fft.rfft(diff)))] == pytest.approx(1.2, abs=0.2)


# --- mounts ----------------------------------------------------------------------------------------


def test_straight_down_in_the_vehicle_frame(sessions):
    sc, path = sessions["nadir_vehicle_frame"]
    motion, clock = Motion(sc), Clock.of(sc)
    gim = [m for _, m in of_kind(read_tlog(path / "uav.tlog"), "GIMBAL_DEVICE_ATTITUDE_STATUS")]
    assert {m.flags for m in gim} == {44} and {m.gimbal_device_id for m in gim} == {1}
    tau = clock.tau_s([m.time_boot_ms for m in gim])
    vehicle_yaw = motion.uav_rpy(tau)[:, 2]
    assert np.ptp(np.degrees(vehicle_yaw)) > 30  # the UAV yaws
    for m, yaw_v, R_true in zip(gim, vehicle_yaw, motion.R_ned_from_gimbal(tau)):
        R_q = quat_to_R(np.array(m.q, dtype=float))  # float32 on the wire
        assert np.degrees(np.arcsin(np.clip(-R_q[2, 0], -1, 1))) == pytest.approx(-90.0, abs=1e-4)
        down = R_q[
            :, 2
        ]  # the image's down direction: opposite to the gimbal's heading when looking down
        assert np.degrees(np.arctan2(-down[1], -down[0])) == pytest.approx(52.3, abs=1e-4)
        # truth: horizon-relative roll 0, pitch -90, heading = the vehicle's + 52.3 deg
        assert np.abs(R_true - euler_to_R(0.0, -np.pi / 2, yaw_v + np.radians(52.3))).max() < 1e-12
        assert np.abs(euler_to_R(0.0, 0.0, yaw_v) @ R_q - R_true).max() < 1e-6


def test_servo_mount_reports_target_minus_lean(sessions):
    sc, path = sessions["servo_mount"]
    motion, clock = Motion(sc), Clock.of(sc)
    recs = read_tlog(path / "uav.tlog")
    params = of_kind(recs, "PARAM_VALUE")
    assert len(params) == 1
    t_param, p = params[0]
    assert (p.param_id, p.param_value, p.param_type, p.param_index) == ("MNT1_TYPE", 1.0, 2, 65535)
    assert t_param < sc.start_unix * 1e6  # near the start, before the first frame
    att = [m for _, m in of_kind(recs, "ATTITUDE")]
    t_att = np.array([m.time_boot_ms for m in att])
    gim = [m for _, m in of_kind(recs, "GIMBAL_DEVICE_ATTITUDE_STATUS")]
    assert {m.flags for m in gim} == {44}
    t_g = np.array([m.time_boot_ms for m in gim])
    # the vehicle's lean from its own ATTITUDE
    roll_v = np.interp(t_g, t_att, [m.roll for m in att])
    pitch_v = np.interp(t_g, t_att, [m.pitch for m in att])
    R_q = quat_to_R(np.array([m.q for m in gim], dtype=float))
    yaw_r, pitch_r, roll_r = Rotation.from_matrix(R_q).as_euler("ZYX").T
    assert (
        np.degrees(np.abs(roll_v)).min() > 10 and np.degrees(np.hypot(roll_v, pitch_v)).max() > 15
    )
    assert np.abs(roll_r - (0.0 - roll_v)).max() < 2e-4
    assert np.abs(pitch_r - (np.radians(sc.mount.pitch_deg) - pitch_v)).max() < 2e-4
    assert np.abs(yaw_r).max() < 2e-4  # yaw relative to the vehicle: no pan
    # the camera's true attitude is the body's composed with the servo angles, not the report read
    # as horizon-relative: that reading is many degrees off
    tau = clock.tau_s(t_g)
    R_true = motion.R_ned_from_gimbal(tau)
    R_body = motion.R_ned_from_body(tau)
    assert np.abs(R_body @ R_q - R_true).max() < 1e-6
    naive = euler_to_R(0.0, 0.0, motion.uav_rpy(tau)[:, 2]) @ R_q
    angle = np.degrees(
        np.arccos(np.clip(np.einsum("ni,ni->n", naive[:, :, 0], R_true[:, :, 0]), -1, 1))
    )
    assert angle.min() > 8


# --- reboot ----------------------------------------------------------------------------------------


def test_reboot_restarts_the_boot_clock_and_silences_the_autopilot(sessions):
    sc, path = sessions["reboot"]
    clock = Clock.of(sc)
    recs = read_tlog(path / "uav.tlog")
    t_rec = np.array([t for t, _, _ in recs]) / 1e6
    gap = np.argmax(np.diff(t_rec))
    assert np.diff(t_rec)[gap] == pytest.approx(sc.link.reboot_down_s, abs=0.1)
    before, after = recs[: gap + 1], recs[gap + 1 :]
    assert {m.get_type() for _, _, m in after} == UAV_KINDS == {m.get_type() for _, _, m in before}
    boot0 = round(sc.link.boot_s_at_start * 1000)
    reboot_ms = round(sc.link.reboot_at_s * 1000)
    ms_before = [m.time_boot_ms for _, _, m in before if hasattr(m, "time_boot_ms")]
    ms_after = [m.time_boot_ms for _, _, m in after if hasattr(m, "time_boot_ms")]
    assert (
        boot0 - 1000 * sc.telemetry.lead_s - 100 <= min(ms_before)
        and max(ms_before) < boot0 + reboot_ms
    )
    down_ms = round(sc.link.reboot_down_s * 1000)
    assert down_ms <= min(ms_after) < down_ms + 50  # the boot clock restarted at the reboot
    for _, _, m in recs:
        if m.get_type() == "SYSTEM_TIME":  # GNSS time keeps running; the boot clock's zero moved
            rebooted = m.time_boot_ms < boot0 - 10_000
            zero = clock.reboot_us if rebooted else clock.boot_epoch_us
            assert m.time_unix_usec - 1000 * m.time_boot_ms == zero
            assert zero == (
                round(sc.start_unix * 1e6) + reboot_ms * 1000 if rebooted else clock.boot_epoch_us
            )
    for _, m in of_kind(after, "TIMESYNC"):  # answered on the new boot clock
        assert (
            sc.link.reboot_down_s <= m.tc1 / 1e9 < sc.duration_s + 1.0 - sc.link.reboot_at_s + 0.5
        )
    for _, m in of_kind(before, "TIMESYNC"):
        assert boot0 / 1e3 - sc.telemetry.lead_s <= m.tc1 / 1e9 < boot0 / 1e3 + sc.link.reboot_at_s
    truth = read_csv(path / "truth.csv")
    assert len(truth) == round(sc.duration_s * sc.fps)  # the UAV flies on; the truth is continuous
    lat = np.array([float(r["lat"]) for r in truth])
    assert np.abs(np.diff(lat)).max() < 1e-6


# --- rates and the in-sync twin's video -------------------------------------------------------------


def test_message_rates_are_knobs(tmp_path):
    sc = scenario_from_dict(
        {
            "name": "rates",
            "duration_s": 2.0,
            "telemetry": {
                "attitude_hz": 4.0,
                "position_hz": 3.0,
                "system_time_hz": 2.0,
                "gps_raw_hz": 10.0,
                "timesync_hz": 0,
                "gps_raw_time": "boot",
            },
        }
    )
    report = generate(sc, tmp_path / "s", video=False)
    span = sc.telemetry.lead_s + sc.duration_s + 1.0
    for kind, hz in (
        ("ATTITUDE", 4),
        ("GLOBAL_POSITION_INT", 3),
        ("SYSTEM_TIME", 2),
        ("GPS_RAW_INT", 10),
    ):
        assert abs(report.messages[kind] - hz * span) <= 1, kind
    assert "TIMESYNC" not in report.messages
    clock = Clock.of(sc)
    for t_rec, m in of_kind(
        read_tlog(tmp_path / "s" / "uav.tlog"), "GPS_RAW_INT"
    ):  # ArduPilot's boot µs
        assert (
            sc.link.delay_s
            <= (t_rec - clock.boot_epoch_us - m.time_usec) / 1e6
            < sc.link.delay_s + 0.3
        )


def test_clock_twins_render_the_same_video(tmp_path):
    paths = []
    for name in ("clock_offset", "clock_sync"):
        sc = with_overrides(load_scenario(SCENARIOS / f"{name}.toml"), duration_s=0.4)
        paths.append(generate(sc, tmp_path / name).session)
    a, b = paths
    assert (a / "video.mp4").read_bytes() == (b / "video.mp4").read_bytes()
    toml_a, toml_b = ((p / "session.toml").read_text().splitlines() for p in paths)
    assert [x for x in toml_a if not x.startswith(("init_t", "#"))] == [
        x for x in toml_b if not x.startswith(("init_t", "#"))
    ]

"""The drone's sensor errors (``[sensors]``) in the generated telemetry, checked against the scenario's truth.

The reported ATTITUDE is off by the configured biases; the camera as the telemetry states it (the messages
decoded by pymavlink and composed by the localizer's attitude functions, not the simulator's) carries the
compass's error and, with a stabilised gimbal, its own levelling error, with a servo mount or a fixed camera the
AHRS's whole error; the EKF's position walks with the configured RMS, GPS_RAW_INT follows the same walk and
claims what the GNSS mode says; ``truth_errors.csv`` holds what was injected; and with the sensors off the
telemetry is byte for byte the bundled sessions'.
"""

import csv
import dataclasses
from pathlib import Path

import numpy as np
import pymap3d
import pytest
from test_sim_knobs import SCENARIOS, of_kind, read_tlog

from groundstation.session.read import load_session
from localizer.attitude import (
    R_ned_from_fixed_mount,
    R_ned_from_gimbal_device,
    R_ned_from_mount_orientation,
    euler_to_R,
    rotvec,
)
from localizer.calibration import ConfigError
from sim_fixtures.bundle import BUNDLED, BUNDLED_DIR
from sim_fixtures.generate import TRUTH_ERRORS_HEADER, generate
from sim_fixtures.motion import Motion
from sim_fixtures.scenario import SensorsSpec, load_scenario, scenario_from_dict, with_overrides
from sim_fixtures.sensors import gnss_claim, position_error_ne_m, video_time_error_s
from sim_fixtures.tlog import Clock, write_tlog

BIAS = {
    "roll_bias_deg": 0.3,
    "pitch_bias_deg": -0.2,
    "yaw_bias_deg": 2.0,
    "gimbal_level_deg": (0.25, -0.15),
    "gnss_mode": "plain",
    "gnss_white_m": 0.0,
    "baro_wander_m": 0.15,
}
SMALL = {"duration_s": 2.0, "fps": 10.0, "camera": {"width": 320, "height": 180}}
MOUNTS = (
    "oblique_2m",
    "vehicle_yaw",
    "nadir_vehicle_frame",
    "mount_orientation",
    "servo_mount",
    "fixed_camera",
)


def biased(name, **sensors):
    sc = load_scenario(SCENARIOS / f"{name}.toml")
    return with_overrides(
        sc, **SMALL, sensors=dataclasses.replace(SensorsSpec(), **{**BIAS, **sensors})
    )


@pytest.fixture(scope="module")
def sessions(tmp_path_factory):
    root = tmp_path_factory.mktemp("sensors")
    out = {}
    for name in MOUNTS:
        sc = biased(name)
        generate(sc, root / name, video=False)
        out[name] = (sc, read_tlog(root / name / "uav.tlog"), root / name)
    return out


def boot_tau(sc, msgs):
    return Clock.of(sc).tau_s([m.time_boot_ms for m in msgs])


def attitude(sc, records):
    """ATTITUDE: (scenario times, reported roll, pitch, yaw (N, 3) in radians)."""
    att = [m for _, m in of_kind(records, "ATTITUDE")]
    return boot_tau(sc, att), np.array([[m.roll, m.pitch, m.yaw] for m in att])


def reported_camera(sc, records):
    """The camera's attitude as a ground station composes the telemetry: (times, R_ned_from_gimbal (N, 3, 3))."""
    t_att, rpy = attitude(sc, records)
    yaw = np.unwrap(rpy[:, 2])
    if sc.mount.attitude_source == "fixed":
        return t_att, R_ned_from_fixed_mount(euler_to_R(*rpy.T), sc.mount.fixed_rpy_deg)
    kind = (
        "MOUNT_ORIENTATION"
        if sc.mount.attitude_source == "mount_orientation"
        else "GIMBAL_DEVICE_ATTITUDE_STATUS"
    )
    gim = [m for _, m in of_kind(records, kind)]
    inside = (boot_tau(sc, gim) >= t_att[0]) & (
        boot_tau(sc, gim) <= t_att[-1]
    )  # ATTITUDE on both sides
    gim = [m for m, ok in zip(gim, inside) if ok]
    tau = boot_tau(sc, gim)
    vehicle_yaw = np.interp(tau, t_att, yaw)
    body = None
    if sc.mount.kind == "servo":
        body = euler_to_R(
            np.interp(tau, t_att, rpy[:, 0]), np.interp(tau, t_att, rpy[:, 1]), vehicle_yaw
        )
    if kind == "MOUNT_ORIENTATION":
        return tau, R_ned_from_mount_orientation(
            *np.array([[m.roll, m.pitch, m.yaw] for m in gim]).T, vehicle_yaw, body
        )
    q = np.array([m.q for m in gim], dtype=float)
    return tau, R_ned_from_gimbal_device(q, np.array([m.flags for m in gim]), vehicle_yaw, body)


def error_ned_deg(R_reported, R_true):
    """The error rotation R_reported·R_trueᵀ as a rotation vector in NED (degrees)."""
    return np.degrees(rotvec(R_reported @ np.swapaxes(R_true, -1, -2)))


def read_errors(path):
    with open(path / "truth_errors.csv", newline="") as f:
        rows = list(csv.reader(f))
    assert tuple(rows[0]) == TRUTH_ERRORS_HEADER
    return dict(zip(rows[0], np.array(rows[1:], dtype=float).T))


@pytest.mark.parametrize("name", MOUNTS)
def test_attitude_reports_the_ahrs_biases(sessions, name):
    sc, records, _ = sessions[name]
    tau, rpy = attitude(sc, records)
    true = Motion(sc).uav_rpy(tau)
    err = np.degrees(rpy - true)
    err[:, 2] = (err[:, 2] + 180) % 360 - 180
    assert np.abs(err - [0.3, -0.2, 2.0]).max() < 1e-4  # float32 on the wire
    gpi = [m for _, m in of_kind(records, "GLOBAL_POSITION_INT")]
    heading = np.degrees(Motion(sc).uav_rpy(boot_tau(sc, gpi))[:, 2]) + 2.0
    hdg_err = (np.array([m.hdg for m in gpi]) / 100 - heading + 180) % 360 - 180
    assert np.abs(hdg_err).max() < 0.006  # the EKF's heading is the compass's too (cdeg)


@pytest.mark.parametrize("name", MOUNTS)
def test_the_camera_as_reported_carries_what_a_real_mount_would(sessions, name):
    sc, records, _ = sessions[name]
    motion = Motion(sc)
    tau, R_rep = reported_camera(sc, records)
    err = error_ned_deg(R_rep, motion.R_ned_from_gimbal(tau))
    if sc.mount.kind == "servo" or sc.mount.attitude_source == "fixed":
        # no IMU of its own: the camera is off exactly as the airframe's reported attitude is
        t_att, rpy = attitude(sc, records)
        R_body = euler_to_R(
            *(np.interp(tau, t_att, a) for a in (rpy[:, 0], rpy[:, 1], np.unwrap(rpy[:, 2])))
        )
        assert np.abs(err - error_ned_deg(R_body, motion.R_ned_from_body(tau))).max() < 2e-3
        assert np.abs(np.hypot(err[:, 0], err[:, 1]) - np.hypot(0.3, 0.2)).max() < 0.02
        # about Down the compass's bias, and the roll bias about the body's forward axis, which leans down by pitch
        pitch = motion.uav_rpy(tau)[:, 1]
        assert np.abs(err[:, 2] - (2.0 - 0.3 * np.sin(pitch))).max() < 0.01
    else:
        # a stabilised gimbal: its own levelling error about its heading's forward and right axes, the compass's
        # bias about Down, none of the autopilot's tilt bias (to first order: 0.02 deg)
        heading = motion.gimbal_target(tau)[:, 3]
        level_n = 0.25 * np.cos(heading) + 0.15 * np.sin(heading)
        level_e = 0.25 * np.sin(heading) - 0.15 * np.cos(heading)
        assert np.abs(err[:, 0] - level_n).max() < 0.02 and np.abs(err[:, 1] - level_e).max() < 0.02
        assert np.abs(err[:, 2] - 2.0).max() < 0.02


def test_straight_down_the_levelling_error_tilts_the_optical_axis(sessions):
    sc, records, _ = sessions["nadir_vehicle_frame"]
    _, R_rep = reported_camera(sc, records)
    # the optical axis from straight down
    off_nadir = np.degrees(np.arccos(np.clip(R_rep[:, 2, 0], -1, 1)))
    assert np.abs(off_nadir - np.hypot(0.25, 0.15)).max() < 1e-3


@pytest.mark.parametrize("name", MOUNTS)
def test_truth_errors_holds_what_the_telemetry_carries(sessions, name):
    sc, records, path = sessions[name]
    motion, errors = Motion(sc), read_errors(path)
    tau = errors["t"] - sc.start_unix
    assert np.allclose(errors["roll_err_deg"], 0.3) and np.allclose(errors["yaw_err_deg"], 2.0)
    t_cam, R_rep = reported_camera(sc, records)
    err = error_ned_deg(R_rep, motion.R_ned_from_gimbal(t_cam))
    for i, axis in enumerate("ned"):
        assert np.abs(np.interp(tau, t_cam, err[:, i]) - errors[f"cam_err_{axis}_deg"]).max() < 5e-3
    s = sc.site
    for kind in ("GLOBAL_POSITION_INT", "GPS_RAW_INT"):  # the EKF follows the receiver's walk
        msgs = [m for _, m in of_kind(records, kind)]
        t_msg = (
            boot_tau(sc, msgs)
            if kind == "GLOBAL_POSITION_INT"
            else np.array([m.time_usec for m in msgs]) / 1e6 - sc.start_unix
        )
        n, e, _ = pymap3d.geodetic2ned(
            np.array([m.lat for m in msgs]) / 1e7,
            np.array([m.lon for m in msgs]) / 1e7,
            0.0,
            s.lat_deg,
            s.lon_deg,
            0.0,
        )
        true, within = (
            motion.uav_ned(t_msg),
            (t_msg >= tau[0]) & (t_msg <= tau[-1]),
        )  # the frames' span
        for got, column in ((n - true[:, 0], "north_err_m"), (e - true[:, 1], "east_err_m")):
            # 1e-7 deg rounding
            assert np.abs(got - np.interp(t_msg, tau, errors[column]))[within].max() < 0.007
    gpi = [m for _, m in of_kind(records, "GLOBAL_POSITION_INT")]
    t_gpi = boot_tau(sc, gpi)
    rel_err = np.array([m.relative_alt for m in gpi]) / 1e3 - (
        -motion.uav_ned(t_gpi)[:, 2] - s.takeoff_height_above_surface_m
    )
    within = (t_gpi >= tau[0]) & (t_gpi <= tau[-1])
    assert np.abs(rel_err - np.interp(t_gpi, tau, errors["height_err_m"]))[within].max() < 0.002
    assert 0.01 < np.abs(errors["height_err_m"]).max() < 0.6  # the barometer's wander is there


def test_gps_raw_int_claims_what_the_gnss_mode_says(sessions, tmp_path):
    _, records, _ = sessions["oblique_2m"]
    plain = {(m.fix_type, m.h_acc, m.v_acc, m.eph) for _, m in of_kind(records, "GPS_RAW_INT")}
    assert plain == {(3, 2000, 4000, 100)}
    rtk = biased("oblique_2m", gnss_mode="rtk", gnss_white_m=None)
    assert gnss_claim(rtk) == (6, 0.02, 0.7)
    given = with_overrides(rtk, uav={"gnss_h_acc_m": 0.05, "gnss_fix_type": 5})
    assert gnss_claim(given) == (5, 0.05, 0.7)  # [uav]'s own keys win
    generate(given, tmp_path, video=False)
    raw = {
        (m.fix_type, m.h_acc, m.eph)
        for _, m in of_kind(read_tlog(tmp_path / "uav.tlog"), "GPS_RAW_INT")
    }
    assert raw == {(5, 50, 70)}


@pytest.mark.parametrize("mode, rms_m", [("plain", 1.2), ("rtk", 0.015)])
def test_the_ekf_position_walks_with_the_configured_rms(tmp_path, mode, rms_m):
    """An hour of GLOBAL_POSITION_INT at 1 Hz (fixed seed), a walk of 30 s: the horizontal RMS as configured, and
    a walk, not white noise (its autocorrelation after one correlation time is about 1/e)."""
    sc = scenario_from_dict(
        {
            "name": "walk",
            "seed": 7,
            "duration_s": 3600.0,
            "sensors": {"gnss_mode": mode, "gnss_walk_s": 30.0, "gnss_white_m": 0.0},
            "telemetry": {
                "attitude_hz": 1.0,
                "position_hz": 1.0,
                "gimbal_hz": 1.0,
                "gps_raw_hz": 0.0,
                "system_time_hz": 0.0,
                "timesync_hz": 0.0,
            },
        }
    )
    write_tlog(tmp_path / "uav.tlog", sc, Motion(sc), Clock.of(sc))
    gpi = [m for _, m in of_kind(read_tlog(tmp_path / "uav.tlog"), "GLOBAL_POSITION_INT")]
    tau = boot_tau(sc, gpi)
    n, e, _ = pymap3d.geodetic2ned(
        np.array([m.lat for m in gpi]) / 1e7,
        np.array([m.lon for m in gpi]) / 1e7,
        0.0,
        sc.site.lat_deg,
        sc.site.lon_deg,
        0.0,
    )
    true = Motion(sc).uav_ned(tau)
    err = np.column_stack([n - true[:, 0], e - true[:, 1]])
    assert np.sqrt(np.mean(np.sum(err**2, axis=1))) == pytest.approx(rms_m, rel=0.15)
    if mode == "plain":  # the degE7 rounding (about 1 cm) would hide an RTK walk's correlation
        lag = round(30.0 / np.median(np.diff(tau)))
        corr = np.mean([np.corrcoef(err[:-lag, i], err[lag:, i])[0, 1] for i in range(2)])
        assert corr == pytest.approx(np.exp(-1), abs=0.12)
    assert np.allclose(position_error_ne_m(sc, tau), err, atol=0.012)
    # [sensors] draw: another walk of the same size over the same flight
    again = position_error_ne_m(with_overrides(sc, sensors={"draw": 1}), tau)
    assert np.sqrt(np.mean(np.sum(again**2, axis=1))) == pytest.approx(rms_m, rel=0.15)
    assert abs(np.corrcoef(again[:, 0], position_error_ne_m(sc, tau)[:, 0])[0, 1]) < 0.3


def test_sensors_off_the_telemetry_is_byte_for_byte_the_bundled(tmp_path):
    for name in BUNDLED:
        sc = load_scenario(SCENARIOS / f"{name}.toml")
        for label, same in (
            ("default", sc),
            (
                "explicit",
                with_overrides(
                    sc,
                    sensors=scenario_from_dict(
                        {"name": "x", "sensors": {"gnss_mode": "exact", "wander_deg": 0.0}}
                    ).sensors,
                ),
            ),
        ):
            out = tmp_path / f"{name}_{label}"
            generate(same, out, video=False)
            for f in ("uav.tlog", "truth.csv", "depth.jsonl", "video_frames.csv"):
                assert (out / f).read_bytes() == (BUNDLED_DIR / name / f).read_bytes(), (
                    name,
                    label,
                    f,
                )
            assert not (out / "truth_errors.csv").exists()


def test_an_exact_gnss_refuses_a_walk():
    with pytest.raises(ConfigError, match=r"^s.toml: sensors.gnss_walk_m = 1.0: needs gnss_mode"):
        scenario_from_dict({"name": "x", "sensors": {"gnss_walk_m": 1.0}}, "s.toml")


def test_sensors_scenarios_load():
    for path in sorted(Path(SCENARIOS).glob("sensors_*.toml")):
        sc = load_scenario(path)
        assert sc.sensors.yaw_bias_deg and sc.sensors.gnss_mode in ("rtk", "plain"), path


def stamp_error_s(out) -> np.ndarray:
    """The generated session's video_frames.csv times less its frames' true exposures (truth.csv's), per frame (s)."""
    stamped = np.loadtxt(out / "video_frames.csv", delimiter=",", skiprows=1)[:, 1]
    return stamped - np.loadtxt(out / "truth.csv", delimiter=",", skiprows=1)[:, 0]


def test_the_frames_stamps_carry_a_time_error_drawn_per_flight(tmp_path):
    """``[sensors] video_time_sigma_s``: video_frames.csv's times are off the frames' true exposures (truth.csv's) by
    one constant per flight, a new one with each ``[sensors] draw``, of that 1-sigma over many flights; the session
    states it as ``[uncertainty] time_s``; the telemetry is the same as without it."""
    sc = biased("oblique_2m", video_time_sigma_s=0.02)
    errors = []
    for name, flight in (
        ("draw0", sc),
        ("draw1", with_overrides(sc, sensors={"draw": 1})),
        ("none", with_overrides(sc, sensors={"video_time_sigma_s": 0.0})),
    ):
        generate(flight, tmp_path / name, video=False)
        error = stamp_error_s(tmp_path / name)
        assert np.ptp(error) < 2e-6  # one constant (to the file's microseconds)
        errors.append(float(np.mean(error)))
    assert load_session(tmp_path / "draw0").calibration.sigmas.time_s == 0.02
    assert abs(errors[0] - errors[1]) > 1e-4 and errors[2] == pytest.approx(0.0, abs=2e-6)
    assert (tmp_path / "none" / "uav.tlog").read_bytes() == (
        tmp_path / "draw0" / "uav.tlog"
    ).read_bytes()
    # over many flights, the error's RMS is the sigma stated
    drawn = [video_time_error_s(with_overrides(sc, sensors={"draw": d})) for d in range(400)]
    assert drawn[:2] == pytest.approx(errors[:2], abs=2e-6)
    assert np.sqrt(np.mean(np.square(drawn))) == pytest.approx(0.02, rel=0.1)
    assert abs(np.mean(drawn)) < 0.004

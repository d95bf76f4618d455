"""The simulator's height knobs, each checked in the generated tlog against the scenario's truth.

The barometer's bias and drift (GLOBAL_POSITION_INT's alt and relative_alt only), the GNSS altitude's own
wandering error and its accuracy fields (reported, or only the DOPs), the HEARTBEAT's arming, a downward
rangefinder (DISTANCE_SENSOR and RANGEFINDER: along the tilted body axis, noise, range, dropouts, no return,
the seafloor) and the UUV at the surface. Truth: the scenario's motion (true heights) and the tlog's own
ATTITUDE (the airframe's tilt); no localizer code.
"""

import numpy as np
import pytest
from test_sim_knobs import SCENARIOS, of_kind, read_tlog
from test_sim_render import pixel_of_reference_point

from groundstation.mavlink.ingest import mavutil
from sim_fixtures.generate import camera_of, frame_truth, generate
from sim_fixtures.motion import Motion
from sim_fixtures.render import Renderer
from sim_fixtures.scenario import load_scenario, with_overrides
from sim_fixtures.tlog import Clock

RTK = with_overrides(load_scenario(SCENARIOS / "height_rtk_drift.toml"), duration_s=120.0)
PLAIN = with_overrides(load_scenario(SCENARIOS / "height_gnss_drift.toml"), duration_s=120.0)
RANGEFINDER = with_overrides(
    load_scenario(SCENARIOS / "height_rangefinder.toml"),
    duration_s=60.0,
    rangefinder={"dropouts": ((20.0, 25.0),)},
)


@pytest.fixture(scope="module")
def tlogs(tmp_path_factory):
    root = tmp_path_factory.mktemp("height_knobs")
    out = {}
    for name, sc in (
        ("rtk", RTK),
        ("rtk_noisy", with_overrides(RTK, uav={"gnss_alt_noise_m": 0.02})),
        ("plain", PLAIN),
        ("rangefinder", RANGEFINDER),
        ("nothing", with_overrides(RANGEFINDER, rangefinder={"sees": "nothing"})),
        ("floor", with_overrides(RANGEFINDER, rangefinder={"sees": "floor", "noise_m": 0.0})),
    ):
        generate(sc, root / name, video=False)
        out[name] = (sc, read_tlog(root / name / "uav.tlog"), root / name)
    return out


def true_height(sc, tau):
    """The reported position's true height above the water (the world's down = 0 is the surface)."""
    return -Motion(sc).uav_ned(tau)[:, 2]


def gpi(sc, records):
    """GLOBAL_POSITION_INT: (scenario times, alt m, relative_alt m)."""
    msgs = [m for _, m in of_kind(records, "GLOBAL_POSITION_INT")]
    tau = Clock.of(sc).tau_s([m.time_boot_ms for m in msgs])
    return (
        tau,
        np.array([m.alt for m in msgs]) / 1e3,
        np.array([m.relative_alt for m in msgs]) / 1e3,
    )


def test_baro_bias_and_drift_are_in_the_ekf_heights_only(tlogs):
    for name in ("rtk", "plain"):
        sc, records, _ = tlogs[name]
        u, s = sc.uav, sc.site
        tau, alt, rel = gpi(sc, records)
        h = true_height(sc, tau)
        expected = u.baro_bias_m + u.baro_drift_m * tau / sc.duration_s  # the knobs' stated meaning
        # mm rounding, flat-earth altitude
        assert np.abs(alt - (s.surface_amsl_m + h) - expected).max() < 0.003
        assert np.abs(rel - (h - s.takeoff_height_above_surface_m) - expected).max() < 0.002
        raw = [m for _, m in of_kind(records, "GPS_RAW_INT")]
        t_raw = np.array([m.time_usec for m in raw]) / 1e6 - sc.start_unix
        gnss_err = np.array([m.alt for m in raw]) / 1e3 - (
            s.surface_amsl_m + true_height(sc, t_raw)
        )
        # not the barometer's ramp
        assert abs(np.corrcoef(gnss_err, u.baro_drift_m * t_raw)[0, 1]) < 0.9
        rms = np.sqrt(np.mean(gnss_err**2))
        assert 0.3 * u.gnss_alt_error_m < rms < 2.0 * u.gnss_alt_error_m, (name, rms)
        # a slow wander: from one fix to the next (0.2 s) it moves by a small share of its size
        assert np.abs(np.diff(gnss_err)).max() < 0.05 * u.gnss_alt_error_m + 0.002
        assert all(m.alt_ellipsoid - m.alt == round(s.geoid_separation_m * 1000) for m in raw)


def test_gnss_altitude_white_noise_in_gps_raw_int_only(tlogs):
    """gnss_alt_noise_m: new with each GPS_RAW_INT (alt and alt_ellipsoid alike), of that 1-sigma; nothing else in the
    tlog changes (its own random stream)."""
    (sc, quiet, _), (_, noisy, _) = tlogs["rtk"], tlogs["rtk_noisy"]
    raw = [[m for _, m in of_kind(records, "GPS_RAW_INT")] for records in (quiet, noisy)]
    noise = np.array([b.alt - a.alt for a, b in zip(*raw)]) / 1e3
    assert len(noise) == len(raw[0]) == len(raw[1]) > 500
    assert 0.9 * 0.02 < noise.std() < 1.1 * 0.02 and abs(noise.mean()) < 0.003
    assert abs(np.corrcoef(noise[1:], noise[:-1])[0, 1]) < 0.1  # white: no two messages alike
    assert all(m.alt_ellipsoid - m.alt == round(sc.site.geoid_separation_m * 1000) for m in raw[1])
    others = [
        [frame for _, frame, m in records if m.get_type() != "GPS_RAW_INT"]
        for records in (quiet, noisy)
    ]
    assert others[0] == others[1]


def test_gnss_accuracy_fields_true_to_the_fix_type(tlogs):
    rtk = {
        (m.fix_type, m.h_acc, m.v_acc, m.eph, m.epv)
        for _, m in of_kind(tlogs["rtk"][1], "GPS_RAW_INT")
    }
    assert rtk == {(6, 14, 25, 70, 110)}  # RTK fixed: cm, v_acc 2.5 cm
    plain = {(m.fix_type, m.h_acc, m.v_acc) for _, m in of_kind(tlogs["plain"][1], "GPS_RAW_INT")}
    assert plain == {(3, 1200, 1600)}
    dop_only = {
        (m.fix_type, m.h_acc, m.v_acc, m.eph, m.epv)
        for _, m in of_kind(tlogs["rangefinder"][1], "GPS_RAW_INT")
    }
    assert dop_only == {(3, 0, 0, 90, 140)}  # only HDOP 0.9 and VDOP 1.4


def test_heartbeat_arms_at_its_time(tlogs):
    sc, records, _ = tlogs["plain"]
    clock = Clock.of(sc)
    armed = mavutil().mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    beats = [
        (clock.tau_of_us(round(t) - clock.station_offset_us), m.base_mode & armed != 0)
        for t, m in of_kind(records, "HEARTBEAT")
    ]
    # received a link delay after being sent: those just after the arming time may still be disarmed
    assert all(a for tau, a in beats if tau > sc.uav.armed_at_s + 0.3)
    assert not any(a for tau, a in beats if tau < sc.uav.armed_at_s)
    assert [a for _, a in beats][:1] == [False] and any(a for _, a in beats)
    # unset: armed throughout
    assert all(m.base_mode & armed for _, m in of_kind(tlogs["rtk"][1], "HEARTBEAT"))


def _attitude_at(records, boot_ms):
    att = [m for _, m in of_kind(records, "ATTITUDE")]
    t = np.array([m.time_boot_ms for m in att], dtype=float)
    return (
        np.interp(boot_ms, t, [m.roll for m in att]),
        np.interp(boot_ms, t, [m.pitch for m in att]),
    )


def test_downward_rangefinder_reads_along_the_tilted_body_axis(tlogs):
    sc, records, _ = tlogs["rangefinder"]
    rf = sc.rangefinder
    ds = [m for _, m in of_kind(records, "DISTANCE_SENSOR")]
    assert {(m.orientation, m.min_distance, m.max_distance, m.type) for m in ds} == {
        (25, 20, 4000, 0)
    }
    ms = np.array([m.time_boot_ms for m in ds], dtype=float)
    tau = Clock.of(sc).tau_s(ms)
    roll, pitch = _attitude_at(records, ms)  # the tlog's own attitude
    vertical = np.array([m.current_distance for m in ds]) / 100 * np.cos(roll) * np.cos(pitch)
    err = vertical - true_height(sc, tau)
    assert np.abs(err).max() < 5 * rf.noise_m and 0.5 * rf.noise_m < err.std() < 1.5 * rf.noise_m
    tilt = np.degrees(np.arccos(np.cos(roll) * np.cos(pitch)))
    assert tilt.mean() > 5  # a windy day: the slant range is ~1 % long, 12 cm at 12 m
    # the dropout
    assert not np.any((tau >= 20.0) & (tau < 25.0)) and np.any((tau >= 25.0) & (tau < 26.0))
    span = sc.telemetry.lead_s + sc.duration_s + 1.0 - 5.0
    assert abs(len(ds) - rf.rate_hz * span) <= 2
    rng = [m for _, m in of_kind(records, "RANGEFINDER")]  # ArduPilot's copy of the same reading
    assert np.allclose([m.distance for m in rng], [m.current_distance / 100 for m in ds], atol=1e-6)


def test_a_lidar_without_return_or_seeing_the_seafloor(tlogs):
    sc, records, _ = tlogs["nothing"]
    assert {m.current_distance for _, m in of_kind(records, "DISTANCE_SENSOR")} == {
        4100
    }  # max + 1 m
    sc, records, _ = tlogs["floor"]
    ds = [m for _, m in of_kind(records, "DISTANCE_SENSOR")]
    ms = np.array([m.time_boot_ms for m in ds], dtype=float)
    roll, pitch = _attitude_at(records, ms)
    vertical = np.array([m.current_distance for m in ds]) / 100 * np.cos(roll) * np.cos(pitch)
    beyond = vertical - true_height(sc, Clock.of(sc).tau_s(ms))
    assert np.allclose(beyond, sc.site.refractive_index * sc.site.floor_depth_m, atol=0.02)


def test_the_uuv_at_the_surface_is_rendered_where_the_truth_says():
    sc = with_overrides(load_scenario(SCENARIOS / "surface_uuv.toml"), duration_s=1.0)
    camera = camera_of(sc)
    truth = frame_truth(sc, Motion(sc), camera)
    assert np.all(truth.uuv_ned[:, 2] == 0.0)  # the top face at the surface
    renderer = Renderer(sc, camera)
    for i in (0, len(truth.u) - 1):
        _, box = renderer.render(truth.view(i))
        x, y, w, h = box
        assert x <= truth.u[i] <= x + w and y <= truth.v[i] <= y + h
        p = pixel_of_reference_point(renderer, truth.view(i), truth.u[i] + 2.0, truth.v[i] - 3.0)
        assert np.hypot(p[0] - truth.u[i], p[1] - truth.v[i]) < 1e-4

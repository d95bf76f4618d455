"""A buoy reporting its RTK GNSS over MAVLink fixes a plain-GNSS drone's absolute offset ([buoy] in sim_fixtures,
groundstation/offline/reference.py, localizer.reference.reported_at): the buoy found in the rendered video around its
reported position's projection, the fixes against the simulator's truth; a buoy heard from a system id that
reference.toml does not name is not used."""

import dataclasses
import shutil
from pathlib import Path

import numpy as np
import pytest

from groundstation.mavlink.ingest import mavutil
from groundstation.offline import process
from groundstation.offline.evaluate import error_ne_m
from groundstation.offline.reference import (
    BOOT_WINDOW_S,
    FILE,
    BootClock,
    Buoy,
    BuoyReports,
    apply,
    buoy_track,
    read_reference,
    sightings,
    sigma_seen,
)
from groundstation.session.read import load_session, read_table
from groundstation.session.tlog import read_tlog
from localizer.geodesy import geodetic_to_ned, ned_to_geodetic
from localizer.pose import camera_pose
from localizer.reference import MAX_GAP_S, Reports, correct, offsets, reported_at
from localizer.reference import sightings as ref_sightings
from sim_fixtures.generate import generate
from sim_fixtures.scenario import load_scenario, with_overrides

ROOT = Path(__file__).resolve().parents[1]
LAT0, LON0 = 63.44, 10.40


def test_reported_position_is_interpolated_at_the_frames_time():
    """Reports at 5 Hz of a point moving 0.5 m/s north-east with a stated 2 cm: between two reports the position is
    the straight line's (checked in metres against the motion), its sigma 2 cm with the speed times the time's sigma;
    none before the first report, after the last, or in a gap longer than MAX_GAP_S."""
    t = np.concatenate([np.arange(0.0, 4.0, 0.2), np.arange(4.0 + MAX_GAP_S + 0.5, 10.0, 0.2)])
    velocity = np.array([0.3, 0.4])
    lat, lon, _ = ned_to_geodetic(t * velocity[0], t * velocity[1], 0.0, LAT0, LON0, 0.0)
    reports = Reports(t, lat, lon, np.full(len(t), 0.02))
    at = reported_at(reports, np.array([1.05, 2.5, -1.0, 5.0, 11.0]), 0.0, time_sigma_s=0.1)
    n, e, _ = geodetic_to_ned(at.lat_deg[:2], at.lon_deg[:2], 0.0, LAT0, LON0, 0.0)
    assert np.allclose(n, [1.05 * 0.3, 2.5 * 0.3], atol=1e-6)
    assert np.allclose(e, [1.05 * 0.4, 2.5 * 0.4], atol=1e-6)
    assert np.allclose(at.sigma_m[:2], np.hypot(0.02, 0.5 * 0.1))
    assert np.all(np.isnan(at.lat_deg[2:])) and np.all(np.isnan(at.sigma_m[2:]))


@pytest.fixture(scope="module")
def buoy_session(tmp_path_factory) -> Path:
    """sensors_plain_nadir's drone (plain GNSS walk, AHRS and compass biases) for 4 s at 10 fps, 640x360, with the
    [buoy] drifting on the surface, rendered."""
    sc = load_scenario(ROOT / "sim_fixtures" / "scenarios" / "sensors_plain_nadir.toml")
    sc = with_overrides(
        sc,
        duration_s=4.0,
        fps=10.0,
        camera={"width": 640, "height": 360},
        buoy={"enabled": True, "drift_mps": (0.1, -0.05)},
    )
    out = tmp_path_factory.mktemp("buoy")
    generate(sc, out)
    return out


def errors(s, fixes) -> np.ndarray:
    ok = fixes.status == "ok"
    return np.hypot(*error_ne_m(fixes.t_unix, fixes.lat, fixes.lon, ok, s.truth)[ok].T)


def test_a_buoy_corrects_a_plain_gnss_drone(buoy_session):
    """The buoy found in every frame searched within 1 px of the simulator's reference_track.csv; the fixes' absolute
    MAE below 0.2 m and a quarter of the uncorrected one, at least 90 % within 2 h_acc, and positions.csv's cells
    filled for every ok fix."""
    s = load_session(buoy_session)
    buoy, radius_m = read_reference(s)
    assert isinstance(buoy, Buoy) and buoy.system_id == 42
    fixes = process.process_session(s, use_track=True)
    better, cells = apply(s, fixes, "auto")
    assert cells is not None
    before, after = errors(s, fixes), errors(s, better)
    assert np.mean(after) < min(0.2, 0.25 * np.mean(before)), (np.mean(after), np.mean(before))
    ok = better.status == "ok"
    assert np.mean(after <= 2 * better.h_acc_m[ok]) >= 0.9
    assert all(c != "" for c, good in zip(cells["ref_offset_n_m"], ok) if good)

    where, _ = buoy_track(s, buoy)
    t, u, v = sightings(s, where, radius_m)
    truth = read_table(buoy_session / "reference_track.csv", ("t", "u", "v"))
    i = np.searchsorted(truth["t"], t)
    assert np.all(np.isfinite(u))
    assert np.median(np.hypot(u - truth["u"][i], v - truth["v"][i])) < 1.0


def test_a_buoy_from_another_system_id_is_not_used(buoy_session, tmp_path):
    """The same session, its reference.toml naming system 7 (the buoy sends as 42): no correction, the fixes
    unchanged, a warning naming the configured id and the system heard."""
    shutil.copytree(buoy_session, tmp_path, dirs_exist_ok=True)
    toml = tmp_path / FILE
    toml.write_text(toml.read_text().replace("system_id = 42", "system_id = 7"))
    s = load_session(tmp_path)
    fixes = process.process_session(s, use_track=True)
    same, cells = apply(s, fixes, "auto")
    assert cells is None
    ok = fixes.status == "ok"
    assert np.array_equal(same.lat[ok], fixes.lat[ok]) and np.array_equal(
        same.h_acc_m, fixes.h_acc_m
    )
    assert any("system_id = 7" in w and "42" in w for w in s.warnings), s.warnings


def test_buoy_reports_as_they_come(buoy_session):
    """The buoy's messages fed one by one as a live service hears them: only system 42's GPS_RAW_INT are taken, in
    order, and keep_s bounds the history; its position at a frame is within 5 cm of buoy_truth.csv (its RTK error
    1.5 cm per axis)."""
    s = load_session(buoy_session)
    buoy, _ = read_reference(s)
    live = BuoyReports(buoy, keep_s=1.0)
    records = read_tlog(buoy_session / "uav.tlog")
    taken = [live.add(m, t, s.telemetry.station_minus_gnss_s) for t, m in records]
    mine = [m.get_type() == "GPS_RAW_INT" and m.get_srcSystem() == 42 for _, m in records]
    assert taken == mine and sum(taken) > 10
    assert 5 <= len(live) <= 6  # 1 s of reports at 5 Hz
    t_last, last = next((t, m) for (t, m), mine_ in zip(records[::-1], mine[::-1]) if mine_)
    assert not live.add(last, t_last, s.telemetry.station_minus_gnss_s)  # heard twice: once
    truth = read_table(buoy_session / "buoy_truth.csv", ("t", "lat", "lon"))
    t = truth["t"][-3:-1]
    at = live.at(t)
    n, e, _ = geodetic_to_ned(
        at.lat_deg, at.lon_deg, 0.0, truth["lat"][-3:-1], truth["lon"][-3:-1], 0.0
    )
    assert np.all(np.hypot(n, e) < 0.05), np.hypot(n, e)


def test_a_fast_boat_is_taken_where_it_was_at_each_frame(tmp_path):
    """A boat swinging at up to ~1 m/s (swing 2 m, period 12 s) whose reports reach the station 0.25 s late over its
    radio, seen at its simulator pixel (geometry only, 30 s at 5 fps): its reports at their GNSS times correct the
    plain-GNSS drone's fixes to an absolute MAE below 0.15 m; the same reports at their receive times as if there
    were no latency (latency_s 0, no GNSS time) leave at least 4 cm more: the alignment is what makes it work."""
    sc = load_scenario(ROOT / "sim_fixtures" / "scenarios" / "sensors_plain_nadir.toml")
    boat = {"enabled": True, "north_m": 0.0, "east_m": -2.5, "swing_m": 2.0, "swing_period_s": 12.0}
    generate(with_overrides(sc, duration_s=30.0, fps=5.0, buoy=boat), tmp_path, video=False)
    s = load_session(tmp_path)
    cal, tel = s.calibration, s.telemetry
    fixes = process.process_session(s, use_track=True)
    buoy, _ = read_reference(s)
    seen_at = read_table(tmp_path / "reference_track.csv", ("t", "u", "v"), allow_empty=("u", "v"))
    t = seen_at["t"]
    records = read_tlog(tmp_path / "uav.tlog")

    def mae(track: BuoyReports, station_minus_gnss_s) -> float:
        for t_recv, msg in records:
            track.add(msg, t_recv, station_minus_gnss_s)
        at = track.at(t)
        off, seen, jac = ref_sightings(
            cal, camera_pose(cal, tel, t), seen_at["u"], seen_at["v"], at
        )
        assert seen.mean() > 0.9
        found = offsets(t[seen], off[seen], jac[seen], fixes.t_unix, sigma_seen(at, seen))
        return float(
            np.mean(errors(s, correct(cal, camera_pose(cal, tel, fixes.t_unix), fixes, found)))
        )

    aligned = mae(BuoyReports(buoy), tel.station_minus_gnss_s)
    late = mae(BuoyReports(dataclasses.replace(buoy, latency_s=0.0)), None)
    assert aligned < 0.15 and late > aligned + 0.04, (aligned, late)


#: the buoy's boot in the tests' GLOBAL_POSITION_INT: this long before the UNIX epoch's session (s)
BOOT_BEFORE_S = 4321.5


def as_global_position(msg, boot_unix_s: float):
    """A GPS_RAW_INT as the same system's and component's GLOBAL_POSITION_INT (an ArduPilot boat's EKF) stamped on a
    boot clock started at ``boot_unix_s`` (its GNSS time less that)."""
    mav = mavutil().mavlink.MAVLink(
        None, srcSystem=msg.get_srcSystem(), srcComponent=msg.get_srcComponent()
    )
    boot_ms = round((msg.time_usec / 1e6 - boot_unix_s) * 1e3)
    out = mav.global_position_int_encode(
        boot_ms, msg.lat, msg.lon, msg.alt, 0, msg.vel, 0, 0, msg.cog
    )
    out.pack(mav)
    return out


def global_position_records(records, system_id: int) -> list:
    """``records`` (a tlog's) with ``system_id``'s GPS_RAW_INT as GLOBAL_POSITION_INT (:func:`as_global_position`),
    its boot :data:`BOOT_BEFORE_S` before its first report's GNSS time."""
    first = next(
        m for _, m in records if m.get_type() == "GPS_RAW_INT" and m.get_srcSystem() == system_id
    )
    boot = first.time_usec / 1e6 - BOOT_BEFORE_S
    return [
        (t, as_global_position(m, boot))
        if m.get_type() == "GPS_RAW_INT" and m.get_srcSystem() == system_id
        else (t, m)
        for t, m in records
    ]


def test_a_buoy_sending_global_position_int(buoy_session):
    """The buoy's reports as GLOBAL_POSITION_INT (boot time, no accuracy) fed as heard: only system 42's are taken
    (not the UAV's own); each one's time on the station clock within 2 sigma (half the buoy's latency_s) of its fix's
    true GNSS time there, its sigma the buoy's sigma_m; its position at a frame within 5 cm of buoy_truth.csv. Once a
    GPS_RAW_INT comes, the GLOBAL_POSITION_INT are no longer taken."""
    s = load_session(buoy_session)
    buoy, _ = read_reference(s)
    raw = read_tlog(buoy_session / "uav.tlog")
    records = global_position_records(raw, 42)
    track = BuoyReports(buoy)
    taken = [track.add(m, t, s.telemetry.station_minus_gnss_s) for t, m in records]
    mine = [m.get_type() == "GLOBAL_POSITION_INT" and m.get_srcSystem() == 42 for _, m in records]
    assert taken == mine and sum(taken) > 10
    assert any(m.get_type() == "GLOBAL_POSITION_INT" and not k for (_, m), k in zip(records, mine))
    gnss_t = np.array(
        [
            m.time_usec / 1e6
            for _, m in raw
            if m.get_type() == "GPS_RAW_INT" and m.get_srcSystem() == 42
        ]
    )
    got = track.reports()
    assert track.time_sigma_s == pytest.approx(buoy.latency_s / 2)
    late = got.t_unix - (gnss_t + s.telemetry.station_minus_gnss_s)
    assert np.all(np.abs(late) <= 2 * track.time_sigma_s), late
    assert np.all(got.sigma_m == buoy.sigma_m)
    truth = read_table(buoy_session / "buoy_truth.csv", ("t", "lat", "lon"))
    t = truth["t"][5:-5:5]
    at = track.at(t)
    n, e, _ = geodetic_to_ned(
        at.lat_deg, at.lon_deg, 0.0, truth["lat"][5:-5:5], truth["lon"][5:-5:5], 0.0
    )
    assert np.all(np.hypot(n, e) < 0.05), np.hypot(n, e)
    t_raw, first_raw = next(
        (t, m) for t, m in raw if m.get_type() == "GPS_RAW_INT" and m.get_srcSystem() == 42
    )
    both = BuoyReports(buoy)
    assert both.add(first_raw, t_raw, s.telemetry.station_minus_gnss_s)
    assert not any(
        both.add(m, t, s.telemetry.station_minus_gnss_s) for t, m in records if t > t_raw
    )


def test_a_boot_clock_on_the_station_clock():
    """Reports stamped on a boot clock, received 0.2-0.5 s later (0.2 s plus an exponential jitter of 0.1 s): each one
    put within 0.15 s (half the stated 0.3 s latency) of its true station time once the fastest report is in the
    window; the buoy restarting (its boot time back to 0) starts over on the new clock, as does a clock that drifted
    more than the window ago."""
    rng = np.random.default_rng(3)
    clock = BootClock()
    boot = np.arange(100.0, 400.0, 0.2)
    truth = 1.7e9 + boot  # station time of each fix
    recv = truth + 0.2 + rng.exponential(0.1, len(boot))
    got = np.array([clock.station(b, r, 0.3)[0] for b, r in zip(boot, recv)])
    assert clock.station(400.0, truth[-1] + 0.4, 0.3)[1] == pytest.approx(0.15)
    assert np.all(np.abs(got - truth)[50:] <= 0.15), np.abs(got - truth)[50:].max()
    restarted = clock.station(1.0, truth[-1] + 30.0 + 0.25, 0.3)[0]
    assert abs(restarted - (truth[-1] + 30.0)) <= 0.15
    drifting = BootClock()
    offsets = 1.7e9 + 0.002 * boot  # the buoy's clock slow by 2 ms a second: 0.6 s over the 300 s
    got = np.array([drifting.station(b, b + o + 0.25, 0.3)[0] for b, o in zip(boot, offsets)])
    assert np.all(np.abs(got - (boot + offsets))[-50:] <= 0.15 + 0.002 * BOOT_WINDOW_S)

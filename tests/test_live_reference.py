"""A surveyed marker in view, live (groundstation/live/reference_live.py): ``skyfix run --reference reference.toml``
over the replay of a generated session (sensors_plain_nadir's drone: a plain GNSS's walk, AHRS and compass biases;
8 s at 640x360 with the simulator's bullseye on the floor). The fixes on Zenoh carry the offset added, its sigma, the
sightings and the last one's age; against the simulator's truth they are within 2 h_acc and several times closer
than the same fixes without the offset; GPS_INPUT sends them with that h_acc; the status names the reference and the
offset (its schema's). The correction lapses when the marker has not been seen for the window; a bad reference file
is refused in one line naming the key."""

import argparse
import json
import multiprocessing
import os
import re
import shutil
import signal
import threading
import time

import numpy as np
import pytest
import zenoh
from jsonschema import Draft202012Validator
from live_helpers import ROOT, LiveRun, read_jsonl, ui_url, wait_for
from scipy.interpolate import CubicSpline
from test_reference_buoy import global_position_records
from ui_browser import available, chromium

from groundstation.contracts import GROUNDSTATION
from groundstation.live import config, reference_live
from groundstation.live.console import summary
from groundstation.live.reference_live import (
    BadReport,
    LiveBuoy,
    LiveReference,
    drift_line,
    malformed,
    parse_gps_raw,
    search,
)
from groundstation.live.side_process import ProcessLost
from groundstation.mavlink.ingest import mavutil
from groundstation.offline.reference import read_file
from groundstation.runtime.zenoh_mavlink import mavlink_json
from groundstation.session.read import load_session, read_table
from groundstation.session.tlog import read_tlog, tlog_record
from localizer.contract import ConfigError
from localizer.fix import Fix
from localizer.geodesy import geodetic_to_ned, ned_to_geodetic
from localizer.pose import uav_pose
from localizer.reference import WINDOW_S
from sim_fixtures.generate import generate
from sim_fixtures.scenario import load_scenario, with_overrides
from sim_fixtures.sensors import gauss_markov


@pytest.fixture(scope="module")
def plain(tmp_path_factory):
    """sensors_plain_nadir, 8 s at 15 fps and 640x360, with its [marker]."""
    return generated(tmp_path_factory.mktemp("plain"), marker={"enabled": True})


def generated(session, **reference):
    """sensors_plain_nadir (a plain GNSS's walk, AHRS and compass biases), 8 s at 15 fps and 640x360, with
    ``reference`` (its [marker] or [buoy]), generated into ``session``."""
    sc = load_scenario(ROOT / "sim_fixtures" / "scenarios" / "sensors_plain_nadir.toml")
    sc = with_overrides(
        sc, duration_s=8.0, fps=15.0, camera={"width": 640, "height": 360}, **reference
    )
    generate(sc, session)
    return session


def refusal(reference_toml) -> str:
    """skyfix run's refusal of ``--reference reference_toml``."""
    parser = argparse.ArgumentParser()
    config.add_arguments(parser)
    args = parser.parse_args(
        [
            "--calibration",
            "cal.toml",
            "--video",
            "udp://127.0.0.1:5600",
            "--reference",
            str(reference_toml),
        ]
    )
    with pytest.raises(ConfigError) as e:
        config.run_config(args)
    return str(e.value)


def corrected_fixes(live: LiveRun):
    """The run's fixes with the reference's offset (at least 10, the first ok fix without), checked against the
    simulator's truth: within 2 h_acc, a quarter of the error of the same fixes without the offset (the reported
    pose's positions); their offsets (K, 2) and those errors without it."""
    ok = [f for f in live.fixes() if f["status"] == "ok"]
    fixed = [f for f in ok if f["ref_offset_n_m"] is not None]
    assert len(fixed) >= 10 and ok[0]["ref_offset_n_m"] is None, (len(ok), len(fixed))
    after = live.fix_errors_m(fixed)
    h_acc = np.array([f["h_acc_m"] for f in fixed])
    off = np.array([[f["ref_offset_n_m"], f["ref_offset_e_m"]] for f in fixed])
    lat, lon, _ = ned_to_geodetic(
        -off[:, 0], -off[:, 1], 0.0, [f["lat"] for f in fixed], [f["lon"] for f in fixed], 0.0
    )
    raw = [f | {"lat": a, "lon": b} for f, a, b in zip(fixed, lat, lon)]
    before = live.fix_errors_m(raw)
    print(
        f"{len(ok)} ok fixes, {len(fixed)} with the reference's offset: MAE {after.mean():.3f} m "
        f"(without it {before.mean():.3f} m), h_acc median {np.median(h_acc):.3f} m, "
        f"{np.mean(after <= 2 * h_acc):.0%} within 2 h_acc; offset {off.mean(axis=0).round(3)} m, "
        f"sightings {fixed[-1]['ref_sightings']}, last {fixed[-1]['ref_age_s']:.2f} s old"
    )
    assert after.mean() < 0.25 * before.mean()
    assert np.mean(after <= 2 * h_acc) >= 0.9
    assert all(0 < f["ref_sigma_n_m"] < f["h_acc_m"] and f["ref_sightings"] >= 3 for f in fixed)
    assert all(0 <= f["ref_age_s"] <= 2.0 for f in fixed)
    return fixed, off, before


def statuses(live: LiveRun) -> list[dict]:
    """The run's status messages on Zenoh, each checked against the status schema."""
    schema = Draft202012Validator(json.loads(GROUNDSTATION.path_of("status").read_text()))
    status = [
        json.loads(s["payload"]) for s in read_jsonl(live.sub_out) if s["key"] == "skyfix/status"
    ]
    assert [e.message for m in status for e in schema.iter_errors(m)] == []
    return status


def test_the_live_fixes_take_the_markers_offset(plain, tmp_path):
    live = LiveRun(
        tmp_path, plain, "--reference", str(plain / "reference.toml"), video_latency_ms=0
    )
    # the session's own calibration: its [tracker] init_bbox locks the UUV on the first frame, before the marker's
    # offset is known (the fixes then step by it)
    live.run_cmd[live.run_cmd.index("--calibration") + 1] = str(plain / "session.toml")
    with live:
        live.finish()
    fixed, off, before = corrected_fixes(live)

    # GPS_INPUT: the corrected position and its h_acc
    t0 = fixed[0]["t"]
    valid = [g for g in live.gps_input() if g["fix_type"] == 3 and g["time_usec"] / 1e6 > t0]
    assert len(valid) >= 10
    sent = live.gps_errors_m(valid)
    claim = np.array([g["horiz_accuracy"] for g in valid])
    print(
        f"GPS_INPUT after the offset: {len(valid)} valid, MAE {sent.mean():.3f} m, "
        f"horiz_accuracy median {np.median(claim):.3f} m"
    )
    assert sent.mean() < 0.25 * before.mean() and np.mean(sent <= 2 * claim) >= 0.9
    assert np.median(claim) < 0.5 * np.median(before)

    # the status names the reference and its offset, as its schema has it
    status = statuses(live)
    applied = [s["reference"] for s in status if s["reference"]["state"] == "applied"]
    assert applied, [s["reference"] for s in status]
    last = applied[-1]
    assert last["file"].endswith("reference.toml") and last["seen"] >= 3 and last["sightings"] >= 3
    assert last["kind"] == "marker" and last["buoy"] is None
    assert abs(last["offset_n_m"] - off[-1, 0]) < 3 * last["sigma_n_m"] + 0.05
    assert status[0]["reference"]["state"] == "searching"
    # skyfix status's lines, the last status applied (the video's end is more than the line's horizon before the
    # last status: lapsed there)
    said = summary(next(s for s in reversed(status) if s["reference"]["state"] == "applied"))
    assert re.search(r"reference applied: offset north [-+]\d\.\d{3} ± 0\.\d{3} m, east", said), (
        said
    )


def test_the_line_follows_a_walk_the_windows_mean_trails():
    """Sightings at 5 Hz of an offset walking 5 cm/s plus 3 cm white noise, over the 10 s before t: the line's
    offset at t within 3 sigma of the truth there, where the window's mean is more than 0.2 m behind."""
    rng = np.random.default_rng(5)
    t = np.arange(90.0, 100.0, 0.2)
    true = np.column_stack([0.05 * t, -0.02 * t])
    obs = true + rng.normal(0.0, 0.03, true.shape)
    at, sigma = drift_line(t, obs, 100.0)
    assert np.all(np.abs(at - [5.0, -2.0]) < 3 * sigma), (at, sigma)
    assert np.all(sigma < 0.03)
    assert abs(obs[:, 0].mean() - 5.0) > 0.2
    assert drift_line(t[-10:], obs[-10:], 100.0) is None  # 2 s of sightings: no line


def test_the_lines_claim_covers_a_walk_up_to_its_horizon_and_no_further():
    """Sightings at 5 Hz (3 cm white noise) over 10 s of a plain GNSS's walk (the simulator's model, independent of
    the line: a Gauss-Markov of 0.85 m per axis and 120 s at knots 12 s apart, joined by a cubic spline): at the
    newest sighting and up to HORIZON_S after it the line's offset is within 2 sigma of the walk on >= 90 % of 400
    drones (the line's standard error alone held 65 %); the same sightings' sigma grows with the time since; past
    the horizon there is no line."""
    rng = np.random.default_rng(28)
    horizon = reference_live.HORIZON_S
    t = np.arange(0.0, 10.0, 0.2)
    knots = np.arange(-36.0, 36.0, 12.0)
    walks = CubicSpline(knots, gauss_markov(rng, 0.85, 120.0, 12.0, (len(knots), 400)))
    for age_s in (0.0, horizon / 2, horizon):
        at = t[-1] + age_s
        within = []
        for i in range(400):
            obs = walks(t)[:, i, None] + rng.normal(0.0, 0.03, (len(t), 2))
            offset, sigma = drift_line(t, obs, at)
            within += list(np.abs(offset - walks(at)[i]) <= 2 * sigma)
        assert np.mean(within) >= 0.90, (age_s, np.mean(within))
    obs = walks(t)[:, 0, None] + rng.normal(0.0, 0.03, (len(t), 2))
    sigmas = [drift_line(t, obs, t[-1] + a)[1] for a in (0.0, horizon / 2, horizon)]
    assert np.all(np.diff(sigmas, axis=0) > 0), sigmas
    assert drift_line(t, obs, t[-1] + horizon + 0.01) is None


@pytest.mark.skipif(available() is not None, reason=str(available()))
def test_the_operator_page_shows_the_reference(plain, tmp_path):
    """In Chromium: the health table's reference row says the offset is added to every fix, with its sigma and the
    sightings, and the fix line says the offset added."""
    live = LiveRun(
        tmp_path,
        plain,
        "--reference",
        str(plain / "reference.toml"),
        video_latency_ms=0,
        replay_now=False,
    )
    live.run_cmd[live.run_cmd.index("--calibration") + 1] = str(plain / "session.toml")
    with live:
        url = ui_url(tmp_path / "run.log")
        with chromium(tmp_path, url.split("?")[0].rstrip("/")) as browser:
            page = browser.page
            page.goto(url)
            page.wait_for_selector("#conn.ok", timeout=20_000)
            live.start_replay()

            def row() -> str:
                cells = page.query_selector('#health tr[data-input="reference"]')
                return cells.inner_text() if cells else ""

            wait_for(
                lambda: "added to every fix" in row() and "m added" in page.inner_text("#fix-text"),
                30,
                "the reference row applied and a corrected fix",
            )
            text, fix_text = row(), page.inner_text("#fix-text")
            browser.screenshot("reference")
            assert not browser.errors, browser.errors
        live.finish(early=True)
    print(f"{text!r}; {fix_text!r}")
    assert re.search(
        r"offset N [-\d.]+ m ± 0\.\d{3} m, E [-\d.]+ m ± 0\.\d{3} m added to every fix", text
    )
    assert re.search(r"\d+ sightings in 10 s", text) and text.split("\t")[1].strip() == "ok"
    assert re.search(r"reference offset N [-\d.]+, E [-\d.]+ m added", fix_text), fix_text


def test_the_correction_lapses_without_sightings(plain, caplog):
    """The session's own frames searched directly (the search's function, not its thread): the sightings the search's
    process found are exactly those :func:`search` finds in this process; an offset at the last frame, none the line's
    horizon after it (nor a window after it); a fix then goes out as it came. The search's process is 10 nice levels
    below this one (at least at nice 10); killed, it is one line in the log and a new one that searches on."""
    s = load_session(plain)
    ref, radius_m = read_file(plain / "reference.toml")
    before = set(multiprocessing.active_children())
    live = LiveReference(s.calibration, s.telemetry, "reference.toml", ref, radius_m, 0.2)
    try:
        t_of = dict(zip(s.frames["frame"][::3].astype(int), s.frames["t"][::3]))
        here = []  # (t, the sighting) of the same search in this process
        with s.open_video(grey=True) as video:
            for vf in video.prefetch():
                if vf.index in t_of:
                    pose = uav_pose(s.calibration, s.telemetry, t_of[vf.index])
                    live.look(vf.image, pose)
                    here.append(
                        (t_of[vf.index], search(s.calibration, radius_m, vf.image, pose, ref))
                    )
                    last = vf.image, pose
        found_here = [(t, *hit) for t, hit in here if hit is not None]
        assert len(found_here) >= 10 and len(live._sightings) == len(found_here)
        for (t, off, jac, _), (t_here, off_here, jac_here) in zip(live._sightings, found_here):
            assert t == t_here and np.array_equal(off, off_here) and np.array_equal(jac, jac_here)
        (child,) = [c for c in multiprocessing.active_children() if c not in before]
        assert os.getpriority(os.PRIO_PROCESS, child.pid) == min(
            max(os.getpriority(os.PRIO_PROCESS, 0) + 10, 10), 19
        )
        os.kill(child.pid, signal.SIGKILL)
        with pytest.raises(ProcessLost):
            live.look(*last)
        seen = live.seen
        live.look(*last)  # a new process
        assert live.seen == seen + 1
        lost = [r for r in caplog.records if "process ended" in r.getMessage()]
        assert len(lost) == 1 and lost[0].levelname == "ERROR", caplog.text
        t_end = float(s.frames["t"][-1])
        found, age_s = live.offsets(t_end)
        assert np.isfinite(found.offset_ne_m[0]).all() and age_s < 0.5
        assert live.status(t_end)["state"] == "applied"
        for later in (t_end + reference_live.HORIZON_S + 0.01, t_end + WINDOW_S):
            assert not np.isfinite(live.offsets(later)[0].offset_ne_m[0]).any()
            assert live.status(later)["state"] == "lapsed"
        fix = Fix(later, "ok", lat=63.4, lon=10.4, h_acc_m=1.5)
        assert live.correct(fix, None) is fix
    finally:
        live.close()


def test_the_references_sensitivity_is_taken_at_the_fixs_time(plain):
    """A reference moving across the image (its pose_jacobian's compass column growing linearly over 10 s of
    sightings, as a drifting buoy's): the offset's jacobian, which the corrected fix's claim subtracts from the UUV's,
    is the line's at the fix's time, where the offset is taken, not the window's mean (half the window behind: a
    buoy's fixes claimed its compass term 20-30 % short, 90-94 % within 2 h_acc). Closed, its search's process ends."""
    s = load_session(plain)
    ref, radius_m = read_file(plain / "reference.toml")
    before = set(multiprocessing.active_children())
    live = LiveReference(s.calibration, s.telemetry, "reference.toml", ref, radius_m, 0.2)
    (child,) = [c for c in multiprocessing.active_children() if c not in before]
    try:
        t = np.arange(90.0, 100.0, 0.2)
        jac = np.zeros((len(t), 2, 4))
        jac[:, :, 2] = np.outer(t - 90.0, [0.1, -0.05])
        off = np.random.default_rng(3).normal(0.0, 0.03, (len(t), 2))
        live._sightings.extend(zip(t, off, jac, np.full(len(t), 0.01)))
        found, _ = live.offsets(100.0)
        assert np.allclose(found.jacobian[0, :, 2], [1.0, -0.5]), found.jacobian[0]
    finally:
        live.close()
    # the search's process ends with it, whether it had started or not (a stop waits for no start-up)
    wait_for(lambda: not child.is_alive(), 10.0, "the search's process's end")


def test_a_bad_reference_file_is_refused_in_one_line(tmp_path):
    bad = tmp_path / "reference.toml"
    bad.write_text("lat_deg = 63.4\nlon_deg = 10.4\ndepth_m = 2.0\n")
    said = refusal(bad)
    assert said.startswith(f"options: --reference = '{bad}': KeyError: 'radius_m'")
    assert "\n" not in said


# a second buoy on the link, three metres north of the first: not the configured one
FOREIGN_SYSID = 43
FOREIGN_NORTH_1E7_DEG = 270  # ~3 m of latitude


@pytest.fixture(scope="module")
def buoy(tmp_path_factory):
    """sensors_plain_nadir, 8 s at 15 fps and 640x360, with the [buoy] drifting on the surface (system 42 at 5 Hz);
    uav.tlog also gets, beside each of its reports, the same report from system 43 three metres north, and every
    fifth of them a copy from system 42 with its latitude out of range (malformed)."""
    session = generated(
        tmp_path_factory.mktemp("buoy"), buoy={"enabled": True, "drift_mps": (0.1, -0.05)}
    )
    mav = mavutil().mavlink
    foreign = mav.MAVLink(None, srcSystem=FOREIGN_SYSID, srcComponent=1)
    bad = mav.MAVLink(None, srcSystem=42, srcComponent=1)
    records, k = [], 0
    for t, m in read_tlog(session / "uav.tlog"):
        t_us = round(t * 1e6)
        records.append((t_us, bytes(m.get_msgbuf())))
        if m.get_type() == "GPS_RAW_INT" and m.get_srcSystem() == 42:
            fields = {f: getattr(m, f) for f in m.get_fieldnames()}
            other = mav.MAVLink_gps_raw_int_message(
                **(fields | {"lat": m.lat + FOREIGN_NORTH_1E7_DEG})
            )
            records.append((t_us + 100, bytes(other.pack(foreign))))
            if k % 5 == 0:
                broken = mav.MAVLink_gps_raw_int_message(**(fields | {"lat": 2**31 - 1}))
                records.append((t_us + 200, bytes(broken.pack(bad))))
            k += 1
    (session / "uav.tlog").write_bytes(b"".join(tlog_record(t, b) for t, b in records))
    return session


def test_the_live_fixes_take_a_buoys_offset(buoy, tmp_path):
    """A buoy reporting its RTK GNSS on the UAV's link: the fixes corrected by its offset within 2 h_acc of the truth
    and a quarter of the error without it; the other system's reports, three metres off, refused and counted (they
    would move the fixes by that much), the malformed ones refused; the status says buoy and its last report's age."""
    live = LiveRun(tmp_path, buoy, "--reference", str(buoy / "reference.toml"), video_latency_ms=0)
    live.run_cmd[live.run_cmd.index("--calibration") + 1] = str(buoy / "session.toml")
    with live:
        live.finish()
    corrected_fixes(live)
    status = statuses(live)
    applied = [s["reference"] for s in status if s["reference"]["state"] == "applied"]
    assert applied, [s["reference"] for s in status]
    last = applied[-1]
    print(f"status: {last}")
    assert last["kind"] == "buoy" and last["seen"] >= 3
    b = last["buoy"]
    assert b["system_id"] == 42 and b["reports"] >= 20
    assert min(a["buoy"]["last_report_age_s"] for a in applied) < 1.0  # while the reports came
    assert b["foreign"].get(f"{FOREIGN_SYSID}:1", 0) >= 20 and b["refused"] >= 4
    assert status[-1]["uav"]["sysid"] == 1
    said = summary(status[-1])  # skyfix status's lines
    assert re.search(
        r"buoy system 42: \d+ reports, the last \d+\.\d s ago, \d+ malformed and \d+ of", said
    )
    log = (tmp_path / "run.log").read_text()
    assert f"GPS_RAW_INT of system {FOREIGN_SYSID} component 1 refused" in log
    assert "the buoy's GPS_RAW_INT #1 refused: lat 2147483647" in log


def hear(live: LiveBuoy, session, records, until_t: float = np.inf) -> None:
    """What the UAV's link hands LiveBuoy: the messages of the systems other than the UAV's received before
    ``until_t``."""
    for t, m in records:
        if t < until_t and m.get_srcSystem() != session.uav_sysid:
            live.on_mavlink(m, t)


def heard(buoy, records, component: int | None = None):
    """``(LiveBuoy, buoy_truth.csv, its position's miss there (m))``: a LiveBuoy of ``component`` fed ``records``
    (:func:`hear`), its position at the middle of the truth's times against the truth there."""
    s = load_session(buoy)
    ref, _ = read_file(buoy / "reference.toml")
    live = LiveBuoy(s.telemetry, ref, component)
    hear(live, s, records)
    truth = read_table(buoy / "buoy_truth.csv", ("t", "lat", "lon"))
    mid = len(truth["t"]) // 2
    at = live.at(float(truth["t"][mid]))
    n, e, _ = geodetic_to_ned(
        at.lat_deg, at.lon_deg, 0.0, truth["lat"][mid], truth["lon"][mid], 0.0
    )
    return live, truth, float(np.hypot(n, e)[0])


def test_a_buoys_reports_taken_only_from_its_own_system(buoy):
    """LiveBuoy fed uav.tlog's messages directly: only system 42's well-formed reports are kept, so its position at a
    frame's time is within 5 cm of buoy_truth.csv (its RTK error 1.5 cm per axis); system 43's are counted; a
    component_id the buoy does not send from refuses all of them; the search's wait ends at WAIT_S without a report."""
    records = read_tlog(buoy / "uav.tlog")
    live, truth, miss_m = heard(buoy, records)
    assert miss_m < 0.05, miss_m
    st = live.status(float(truth["t"][-1]))
    assert st["foreign"][f"{FOREIGN_SYSID}:1"] == st["reports"] and st["refused"] >= 4
    only, _, _ = heard(buoy, records, 7)
    assert only.status(0.0)["reports"] == 0 and only.status(0.0)["foreign"]["42:1"] > 0
    mid = len(truth["t"]) // 2
    assert not np.isfinite(only.at(float(truth["t"][mid])).lat_deg).any()


def test_a_buoys_global_position_int_taken_only_from_its_own_system(buoy):
    """The same reports as GLOBAL_POSITION_INT (boot time, no accuracy: an ArduPilot boat's EKF), system 42's and
    43's, fed to LiveBuoy directly: only 42's kept, its position at a frame's time within 5 cm of buoy_truth.csv; 43's
    counted, the malformed ones refused."""
    tlog = read_tlog(buoy / "uav.tlog")
    records = global_position_records(global_position_records(tlog, 42), FOREIGN_SYSID)
    live, truth, miss_m = heard(buoy, records)
    assert miss_m < 0.05, miss_m
    st = live.status(float(truth["t"][-1]))
    assert st["reports"] >= 20 and st["refused"] >= 4
    assert st["foreign"][f"{FOREIGN_SYSID}:1"] == st["reports"]
    assert live.reports.time_sigma_s == live.buoy.latency_s / 2 and not live.reports.gps_raw


def test_the_buoys_correction_lapses_when_its_reports_stop(buoy, monkeypatch):
    """The buoy's reports heard for the first 5 s only, the session's frames searched directly (the search's
    function, not its thread, no wait for a report): frames after the last report are not searched (no_report); the
    offset applies at the last sighting and up to the line's horizon after it, and has lapsed at the end (3 s after
    the last report) and a window after it; the status says buoy and the age."""
    monkeypatch.setattr(reference_live, "WAIT_S", 0.0)
    s = load_session(buoy)
    ref, radius_m = read_file(buoy / "reference.toml")
    live = LiveReference(
        s.calibration, s.telemetry, str(buoy / "reference.toml"), ref, radius_m, 0.2
    )
    try:
        t_cut = float(s.frames["t"][0]) + 5.0
        hear(live.buoy, s, read_tlog(buoy / "uav.tlog"), t_cut)
        t_of = dict(zip(s.frames["frame"][::3].astype(int), s.frames["t"][::3]))
        with s.open_video(grey=True) as video:
            for vf in video.prefetch():
                if vf.index in t_of:
                    live.look(vf.image, uav_pose(s.calibration, s.telemetry, t_of[vf.index]))
        after = sum(t > t_cut for t in t_of.values())
        assert live.no_report >= after - 2 and live.seen >= 10, (live.no_report, after, live.seen)
        t_seen = max(t for t, *_ in live._sightings)
        assert t_cut - 1.0 <= t_seen <= t_cut
        for t in (t_seen, t_seen + reference_live.HORIZON_S):
            assert live.status(t)["state"] == "applied", t - t_seen
        t_end = float(s.frames["t"][-1])
        st = live.status(t_end)
        assert st["kind"] == "buoy" and st["state"] == "lapsed" and st["offset_n_m"] is None
        assert t_end - t_cut <= st["buoy"]["last_report_age_s"] <= t_end - t_cut + 1.0
        later = live.status(t_cut + WINDOW_S)
        assert later["state"] == "lapsed" and later["offset_n_m"] is None
    finally:
        live.close()


def test_a_bad_component_id_is_refused_in_one_line(buoy, tmp_path):
    bad = tmp_path / "reference.toml"
    bad.write_text((buoy / "reference.toml").read_text() + "component_id = 300\n")
    assert refusal(bad) == (
        f"options: --reference = '{bad}': component_id = 300: a MAVLink component id, 1-255"
    )


@pytest.fixture(scope="module")
def buoy_zenoh(buoy, tmp_path_factory):
    """The buoy session without its reports in uav.tlog: ``(session, [(t_record, message)])`` of the GPS_RAW_INT of
    the other systems (the buoy's, system 43's, the malformed copies) to publish on Zenoh instead."""
    session = tmp_path_factory.mktemp("buoy_zenoh")
    shutil.copytree(buoy, session, dirs_exist_ok=True)
    uav_sysid = load_session(buoy).uav_sysid
    records = read_tlog(buoy / "uav.tlog")
    kept = [(t, m) for t, m in records if m.get_srcSystem() == uav_sysid]
    (session / "uav.tlog").write_bytes(
        b"".join(tlog_record(round(t * 1e6), bytes(m.get_msgbuf())) for t, m in kept)
    )
    return session, [(t, m) for t, m in records if m.get_srcSystem() != uav_sysid]


def publish(endpoint: str, heard, shift_s: float, stop: threading.Event) -> None:
    """Each of ``heard``'s GPS_RAW_INT on Zenoh as BlueOS's mavlink-server publishes it
    (``mavlink/{sys}/{comp}/GPS_RAW_INT``, JSON), each at its record time + ``shift_s`` with its time shifted by
    that (as the replay sends the UAV's), and one payload that is not JSON halfway."""
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    with zenoh.open(conf) as z:
        for k, (t, m) in enumerate(heard):
            if stop.wait(max(0.0, t + shift_s - time.time())):
                return
            key = f"mavlink/{m.get_srcSystem()}/{m.get_srcComponent()}/GPS_RAW_INT"
            fields = {f: getattr(m, f) for f in m.get_fieldnames()}
            fields["time_usec"] += round(
                shift_s * 1e6
            )  # its GNSS time shifted as the replay shifts the UAV's
            head = {"system_id": m.get_srcSystem(), "component_id": m.get_srcComponent()}
            body = {"header": head | {"sequence": k % 256, "message_id": m.get_msgId()}}
            z.put(key, json.dumps(body | {"message": mavlink_json("GPS_RAW_INT", fields)}))
            if k == len(heard) // 2:
                z.put(key, b"not json")


def test_a_buoys_reports_on_zenoh(buoy_zenoh, tmp_path):
    """The buoy's reports published on Zenoh as BlueOS does (none in uav.tlog), the service subscribed to every
    system's (--reference-zenoh-key mavlink/*/*/GPS_RAW_INT): the fixes take the buoy's offset as over MAVLink; system
    43's refused and counted, the malformed ones and a payload that is not JSON refused."""
    session, heard = buoy_zenoh
    live = LiveRun(
        tmp_path,
        session,
        "--reference",
        str(session / "reference.toml"),
        "--reference-zenoh-key",
        "mavlink/*/*/GPS_RAW_INT",
        video_latency_ms=0,
    )
    live.run_cmd[live.run_cmd.index("--calibration") + 1] = str(session / "session.toml")
    stop = threading.Event()
    with live:
        publisher = threading.Thread(target=publish, args=(live.ep, heard, live.shift, stop))
        publisher.start()
        try:
            live.finish()
        finally:
            stop.set()
            publisher.join()
    corrected_fixes(live)
    last = [s["reference"] for s in statuses(live)][-1]
    print(f"status: {last}")
    b = last["buoy"]
    assert last["kind"] == "buoy" and b["reports"] >= 20
    assert b["foreign"].get(f"{FOREIGN_SYSID}:1", 0) >= 20 and b["refused"] >= 5
    log = (tmp_path / "run.log").read_text()
    assert "GPS_RAW_INT on mavlink/42/1/GPS_RAW_INT refused: not JSON" in log


def test_a_zenoh_report_is_read_or_refused_in_one_line():
    """BlueOS's JSON of a GPS_RAW_INT (mavlink_json's, the project's encoder for mavlink-server): its header's system
    and component, its fix type's enum name as the number; NaN or out-of-range coordinates read but malformed; a
    GLOBAL_POSITION_INT read with its boot time (refused without one); what is not such a message refused naming
    why."""
    fields = {"time_usec": 1_700_000_000_000_000, "fix_type": 6, "lat": 634400000, "lon": 103999000}
    fields |= {"alt": 0, "eph": 70, "epv": 120, "vel": 0, "cog": 0, "satellites_visible": 20}
    head = {"system_id": 42, "component_id": 3, "sequence": 0, "message_id": 24}
    good = {"header": head, "message": mavlink_json("GPS_RAW_INT", fields | {"h_acc": 21})}
    assert good["message"]["fix_type"] == {"type": "GPS_FIX_TYPE_RTK_FIXED"}
    r = parse_gps_raw(json.dumps(good).encode())
    assert (r.get_srcSystem(), r.get_srcComponent(), r.fix_type, r.lat, r.h_acc) == (
        42,
        3,
        6,
        634400000,
        21,
    )
    assert malformed(r) is None
    nan = json.dumps(good | {"message": good["message"] | {"lat": float("nan")}}).encode()
    assert "out of range" in malformed(parse_gps_raw(nan))
    assert "out of range" in malformed(
        parse_gps_raw(json.dumps(good).replace("634400000", "950000000").encode())
    )
    fields = {"time_boot_ms": 123456, "lat": 634400000, "lon": 103999000, "alt": 0}
    fields |= {"relative_alt": 0, "vx": 0, "vy": 0, "vz": 0, "hdg": 0}
    ekf = {"header": head, "message": mavlink_json("GLOBAL_POSITION_INT", fields)}
    r = parse_gps_raw(json.dumps(ekf).encode())
    assert r.get_type() == "GLOBAL_POSITION_INT" and (r.get_srcSystem(), r.time_boot_ms) == (
        42,
        123456,
    )
    assert malformed(r) is None and (r.lat, r.lon) == (634400000, 103999000)
    with pytest.raises(BadReport, match="time_boot_ms = None"):
        parse_gps_raw(
            json.dumps(
                ekf | {"message": {"type": "GLOBAL_POSITION_INT", "lat": 1, "lon": 1}}
            ).encode()
        )
    for bad, why in (
        (b"{", "not JSON"),
        (json.dumps({"message": good["message"]}).encode(), "no 'header'"),
        (json.dumps(good | {"message": {"type": "HEARTBEAT"}}).encode(), "is not GPS_RAW_INT"),
        (
            json.dumps(good | {"message": good["message"] | {"lon": "10.4"}}).encode(),
            "lon = '10.4'",
        ),
        (json.dumps(good | {"header": {"system_id": True}}).encode(), "system = True"),
    ):
        with pytest.raises(BadReport, match=why):
            parse_gps_raw(bad)

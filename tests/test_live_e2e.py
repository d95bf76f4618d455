"""End to end on loopback with real parts: ``skyfix replay`` of a bundled session → ``skyfix run`` →
an independent Zenoh subscriber (its own process) and the replay's pymavlink UUV endpoint.

Checked: fixes arrive on Zenoh (JSON, timestamped) and match truth, within 1.5× the offline error of
the same session with the same tracker; every fix and status message validates against its JSON Schema
(groundstation/schemas/, with the jsonschema package); GPS_INPUT arrives at ≥ 5 Hz and healthy by ArduPilot's rule,
from skyfix's system/component, valid fixes matching truth (MAE ≤ 0.1 m) and explicit no-fix messages
otherwise; the run's recording loads as a session. Also run on ``clock_offset``: a station clock 2.5 s
behind GNSS time and a UUV clock 291 s ahead, which the status reports while the fixes stay right."""

from __future__ import annotations

import json
import os
import socket
import sys
from pathlib import Path

import numpy as np
import pytest
from jsonschema import Draft202012Validator
from live_helpers import (
    MIN_SHARE,
    ROOT,
    SUBSCRIBER,
    free_port,
    read_jsonl,
    replay_shift,
    skyfix,
    start,
    stop,
    truth_errors_m,
    wait_for,
)

from groundstation.contracts import GROUNDSTATION
from groundstation.offline.process import process_session
from groundstation.session.read import load_session
from groundstation.testing.ardupilot import ardupilot_gps_unhealthy

BUNDLED = ROOT / "sim_fixtures" / "bundled"
# SKYFIX_LIVE_SESSION may name another session (with truth.csv) to rehearse
SESSIONS = (
    [Path(os.environ["SKYFIX_LIVE_SESSION"])]
    if "SKYFIX_LIVE_SESSION" in os.environ
    else [BUNDLED / "nadir_hover", BUNDLED / "clock_offset"]
)
# Glass to first packet of this replay chain: the replay sends each frame at its exposure time.
VIDEO_LATENCY_MS = 0


def _offline_mae(session: Path) -> float:
    """MAE of ``skyfix process`` (tracking the video) on the same session."""
    s = load_session(session)
    fixes = process_session(s, use_track=False)
    ok = fixes.status == "ok"
    return float(truth_errors_m(session, fixes.t_unix[ok], fixes.lat[ok], fixes.lon[ok]).mean())


@pytest.mark.parametrize("SESSION", SESSIONS, ids=lambda p: p.name)
def test_replay_run_subscriber_uuv(tmp_path, SESSION):
    mav, video, uuv = free_port(), free_port(), free_port()
    zport = free_port(socket.SOCK_STREAM)
    zenoh_ep = f"tcp/127.0.0.1:{zport}"
    record = tmp_path / "recorded"
    run_cmd = skyfix(
        "run",
        "--calibration",
        str(SESSION / "session.toml"),
        "--mavlink",
        f"udpin:127.0.0.1:{mav}",
        "--video",
        f"udp://127.0.0.1:{video}",
        "--video-latency-ms",
        str(VIDEO_LATENCY_MS),
        "--zenoh-listen",
        zenoh_ep,
        "--gps-input",
        f"udpout:127.0.0.1:{uuv}",
        "--record",
        str(record),
        "--duration-s",
        "28",
        "--stats",
        str(tmp_path / "stats.json"),
        "--realtime-priority",  # as deploy/field.toml: realtime where allowed, else one line and on as before
        "1",
    )
    replay_cmd = skyfix(
        "replay",
        str(SESSION),
        "--mavlink-out",
        f"udpout:127.0.0.1:{mav}",
        "--video-out",
        f"udp://127.0.0.1:{video}",
        "--zenoh-connect",
        zenoh_ep,
        "--uuv-listen",
        f"udpin:127.0.0.1:{uuv}",
        "--uuv-log",
        str(tmp_path / "uuv.jsonl"),
        "--tail-s",
        "1.5",
    )
    sub_out = tmp_path / "zenoh.jsonl"
    procs = []
    try:
        procs.append(start(run_cmd, tmp_path / "run.log"))
        procs.append(
            start(
                [sys.executable, "-c", SUBSCRIBER, zenoh_ep, "skyfix/**", str(sub_out)],
                tmp_path / "sub.log",
            )
        )
        wait_for(
            lambda: any(r["key"] == "skyfix/status" for r in read_jsonl(sub_out)),
            15,
            "skyfix status on Zenoh",
        )
        replay = start(replay_cmd, tmp_path / "replay.log")
        procs.append(replay)
        replay.wait(25)
        stop(procs[0])
        stop(procs[1])
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()
    run_log = (tmp_path / "run.log").read_text()
    assert procs[0].returncode == 0, run_log[-3000:]
    said = [line for line in run_log.splitlines() if "scheduling: " in line]
    assert len(said) == 1 and (
        "SCHED_RR priority 1 (realtime" in said[0] or "not realtime" in said[0]
    ), said
    assert replay.returncode == 0, (tmp_path / "replay.log").read_text()[-3000:]

    shift = replay_shift(tmp_path / "replay.log")
    n_frames = len((SESSION / "video_frames.csv").read_text().splitlines()) - 1

    # Fixes over Zenoh, seen by an independent process
    samples = read_jsonl(sub_out)
    fixes = [s for s in samples if s["key"] == "skyfix/uuv/fix"]
    assert len(fixes) >= MIN_SHARE * n_frames, (
        f"{len(fixes)} fixes for {n_frames} frames\n{run_log[-3000:]}"
    )
    assert all(s["encoding"] == "application/json" and s["timestamp"] for s in fixes)
    fix = [json.loads(s["payload"]) for s in fixes]
    ok = [f for f in fix if f["status"] == "ok"]
    assert len(ok) >= MIN_SHARE * n_frames and len(ok) >= 0.9 * len(fix), {f["status"] for f in fix}
    # every frame decoded was tracked or dropped
    final = json.loads((tmp_path / "stats.json").read_text())
    video, pipeline = final["video"], final["pipeline"]
    assert (
        pipeline["processed"] + pipeline["dropped"] == video["frames"]
        and video["frames"] > MIN_SHARE * n_frames
    )
    assert final["fixes_published"] == pipeline["processed"] == len(fix), (
        final["fixes_published"],
        pipeline,
    )
    err = truth_errors_m(
        SESSION,
        np.array([f["t"] for f in ok]) - shift,
        np.array([f["lat"] for f in ok]),
        np.array([f["lon"] for f in ok]),
    )
    offline = _offline_mae(SESSION)
    print(
        f"Zenoh: {len(fix)} fixes, {len(ok)} ok, MAE {err.mean():.4f} m, max {err.max():.4f} m; "
        f"offline MAE {offline:.4f} m"
    )
    assert err.mean() <= 0.1, f"Zenoh fixes: MAE {err.mean():.3f} m, max {err.max():.3f} m"
    assert err.mean() <= 1.5 * offline, f"live MAE {err.mean():.4f} m vs offline {offline:.4f} m"
    status = [json.loads(s["payload"]) for s in samples if s["key"] == "skyfix/status"]
    assert status[-1]["uav"]["bad_data"] == 0 and status[-1]["pipeline"]["processed"] > 0
    clocks = status[-1]["uav"]["clocks"]
    assert clocks["uav_link_latency_source"] == "timesync"
    if SESSION.name == "clock_offset":  # the status names the clocks that disagree
        assert (
            abs(clocks["station_minus_gnss_s"] + 2.5) < 0.01
            and clocks["depth_aligned_by"] == "arrival"
        )
        assert 293.0 < clocks["uuv_clock_minus_station_s"] < 294.0

    # Every message as its schema says: the contract, checked by an independent validator
    for name, messages in (("fix", fix), ("status", status)):
        schema = Draft202012Validator(json.loads(GROUNDSTATION.path_of(name).read_text()))
        bad = [(m, e.message) for m in messages for e in schema.iter_errors(m)]
        assert not bad, (
            f"{len(bad)} {name} messages break {GROUNDSTATION.path_of(name).name}, first: {bad[0]}"
        )
    # and as the service's own model says, where it is assembled
    assert "does not fit its schema" not in run_log
    assert all(
        f["alt_ellipsoid_m"] is not None and f["t_gnss"] is not None and f["sigma_n_m"] > 0
        for f in ok
    )
    assert {"video", "gps_input", "latency", "record", "height_from_size"} <= set(status[-1])
    size = status[-1][
        "height_from_size"
    ]  # the default, check: frames measured (or why not), nothing applied
    assert (
        size["mode"] == "check"
        and size["measured"] + sum(size["rejected"].values()) > 10
        and size["applied"] == 0
    )

    # GPS_INPUT at the UUV's endpoint while the service runs
    gps = read_jsonl(tmp_path / "uuv.jsonl")
    t_recv = np.array([g["t_recv"] for g in gps])
    assert len(gps) > 20
    rate_hz = (len(t_recv) - 1) / (t_recv[-1] - t_recv[0])
    assert rate_hz >= 5.0
    unhealthy = ardupilot_gps_unhealthy(t_recv)
    assert unhealthy is None, f"ArduPilot would call GPS_INPUT unhealthy: {unhealthy}"
    assert {(g["sysid"], g["compid"]) for g in gps} == {(245, 220)}
    valid = [g for g in gps if g["fix_type"] == 3]
    # Which fixes went out valid is the gates' account, not a share of the messages (a loaded machine's late fixes
    # are refused by age and the no-fix messages between them keep the rate): every ok fix judged once, refused
    # only while a new target is confirmed or for its age, and every valid message sent arrived (a valid one is
    # never older than the gates' max age, so the replay's tail outlasts it)
    sent, gates = final["gps_input"], final["gps_input"]["gates"]
    refused = {reason: n for reason, n in gates["rejected"].items() if n}
    assert gates["accepted"] + sum(refused.values()) == len(ok), (
        gates["accepted"],
        refused,
        len(ok),
    )
    assert set(refused) <= {"unconfirmed", "age"}, (refused, gates["last_refusal"])
    assert gates["accepted"] >= 10 and sent["sent_valid"] >= 10, (
        gates["accepted"],
        sent["sent_valid"],
    )
    assert sent["sent_valid"] >= len(valid) >= 0.9 * sent["sent_valid"], (
        len(valid),
        sent["sent_valid"],
    )
    assert all(g["satellites_visible"] >= 6 and g["time_week"] > 2000 for g in valid)
    # GPS_INPUT carries GNSS time: back to the station clock with the offset the status measured
    to_station = clocks["station_minus_gnss_s"] or 0.0
    err = truth_errors_m(
        SESSION,
        np.array([g["time_usec"] / 1e6 for g in valid]) + to_station - shift,
        np.array([g["lat"] / 1e7 for g in valid]),
        np.array([g["lon"] / 1e7 for g in valid]),
    )
    print(
        f"GPS_INPUT: {len(gps)} messages, {rate_hz:.1f} Hz, largest gap {np.diff(t_recv).max() * 1000:.0f} ms, "
        f"{len(valid)} valid, MAE {err.mean():.4f} m, max {err.max():.4f} m"
    )
    assert err.mean() <= 0.1, f"GPS_INPUT: MAE {err.mean():.3f} m, max {err.max():.3f} m"
    no_fix = [g for g in gps if g["fix_type"] != 3]
    assert all(g["fix_type"] == 1 and g["ignore_flags"] == 255 for g in no_fix)

    # The recording is a session that loads, and that skyfix process tracks from where the live run started
    rec = load_session(record)
    assert (
        len(rec.telemetry.attitude) > 100
        and rec.frames is not None
        and len(rec.frames["t"]) > MIN_SHARE * n_frames
    )
    # the live run's first fix, not the calibration file's init_t
    assert rec.calibration.init_t == ok[0]["t"]
    # ... whose [timing] says what the run measured and used: the link delay TIMESYNC measured, the video latency
    timing = rec.calibration.timing
    assert (
        abs(timing.mavlink_latency_measured_s * 1000 - clocks["uav_link_latency_measured_ms"]) < 1.0
    )
    assert (timing.video_latency_s, timing.video_latency_source) == (
        VIDEO_LATENCY_MS / 1000,
        "configured",
    )
    sources = [
        f["time_source"] for f in ok
    ]  # unknown until the first TIMESYNC reply, then measured
    assert sources[-1] == "timesync" and sources == sorted(
        sources, key=lambda w: w == "timesync"
    ), set(sources)
    for use_track in (True, False):
        fixes = process_session(rec, use_track=use_track)
        good = fixes.status == "ok"
        assert good.sum() >= 0.8 * len(ok), (use_track, good.sum())
        err = truth_errors_m(SESSION, fixes.t_unix[good] - shift, fixes.lat[good], fixes.lon[good])
        assert err.mean() <= 0.1, (use_track, err.mean())

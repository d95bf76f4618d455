"""The target's life in the live service, on loopback with real parts: ``skyfix replay`` of a bundled session →
``skyfix run`` started WITHOUT ``init_bbox`` → an independent Zenoh subscriber and the replay's UUV endpoint.

1. Acquisition from the UUV's own position estimate: this test publishes the truth position moved a few metres as
   BlueOS publishes the UUV autopilot's GLOBAL_POSITION_INT. Before acquisition GPS_INPUT says no fix; then fixes
   are ``ok`` and as accurate as with ``init_bbox`` (tests/test_live_e2e.py: MAE ≤ 0.1 m). ``skyfix status``
   reports the target; the fix and status keys answer late joiners.
2. Selection and release over the Zenoh queryables: bad payloads get one-line error replies; a box on a frame the
   operator saw starts the fixes; after a release GPS_INPUT says no fix; a click selects again and fixes resume.
"""

from __future__ import annotations

import json
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pymap3d
from live_helpers import MIN_SHARE, ROOT, LiveRun, skyfix, track_pixel, wait_for

from groundstation.runtime.zenoh_session import open_session

SESSION = ROOT / "sim_fixtures" / "bundled" / "nadir_hover"
VIDEO_LATENCY_MS = 0  # the replay sends each frame at its exposure time (see test_live_e2e)
POSITION_KEY = "mavlink/1/1/GLOBAL_POSITION_INT"
ESTIMATE_OFF_M = (2.5, -2.0)  # the UUV's own estimate: north, east of the truth


class Live(LiveRun):
    """``skyfix run`` without init_bbox on nadir_hover (see :class:`live_helpers.LiveRun`)."""

    def __init__(self, tmp_path: Path, *run_args: str):
        super().__init__(tmp_path, SESSION, *run_args, video_latency_ms=VIDEO_LATENCY_MS)


def _publish_estimate(live: Live, stop_: threading.Event) -> None:
    """The UUV autopilot's GLOBAL_POSITION_INT as BlueOS's mavlink-server publishes it, 5 Hz: truth moved a few metres."""
    truth = np.genfromtxt(SESSION / "truth.csv", delimiter=",", names=True)
    zs = open_session(connect=[live.ep])
    seq = 0
    try:
        while not stop_.wait(0.2):
            t = time.time() - live.shift
            lat, lon = (
                np.interp(t, truth["t"], truth["lat"]),
                np.interp(t, truth["t"], truth["lon"]),
            )
            lat, lon, _ = pymap3d.enu2geodetic(
                ESTIMATE_OFF_M[1], ESTIMATE_OFF_M[0], 0.0, lat, lon, 0.0
            )
            msg = {
                "header": {"system_id": 1, "component_id": 1, "sequence": seq, "message_id": 33},
                "message": {
                    "type": "GLOBAL_POSITION_INT",
                    "time_boot_ms": 1000 + 200 * seq,
                    "lat": round(float(lat) * 1e7),
                    "lon": round(float(lon) * 1e7),
                    "alt": -1300,
                    "relative_alt": -1300,
                    "vx": 0,
                    "vy": 0,
                    "vz": 0,
                    "hdg": 0,
                },
            }
            zs.put(POSITION_KEY, json.dumps(msg), encoding="application/json;mavlink")
            seq += 1
    finally:
        zs.close()


def _ask(session, key: str, payload=None, timeout_s: float = 5.0) -> tuple[bool, dict]:
    """(ok, JSON) of the first reply of a Zenoh query."""
    kw = (
        {"payload": json.dumps(payload) if not isinstance(payload, bytes) else payload}
        if payload is not None
        else {}
    )
    for reply in session.get(key, timeout=timeout_s, **kw):
        if reply.ok is not None:
            return True, json.loads(reply.ok.payload.to_string())
        return False, json.loads(reply.err.payload.to_string())
    raise AssertionError(f"no reply on {key}")


def test_run_without_init_bbox_acquires_near_the_uuvs_own_estimate(tmp_path):
    stop_publisher = threading.Event()
    with Live(tmp_path, "--uuv-position-key", POSITION_KEY) as live:
        publisher = threading.Thread(
            target=_publish_estimate, args=(live, stop_publisher), daemon=True
        )
        publisher.start()
        try:
            wait_for(lambda: sum(f["status"] == "ok" for f in live.fixes()) >= 20, 25, "ok fixes")
            # skyfix status against the running service: once as JSON, once as the operator's summary
            status = subprocess.run(
                skyfix("status", "--zenoh-connect", live.ep, "--json", "--timeout-s", "10"),
                capture_output=True,
                text=True,
                cwd=ROOT,
                timeout=60,
                check=False,
            )
            assert status.returncode == 0, status.stderr
            answer = json.loads(status.stdout)
            assert answer["target"]["state"] == "tracking" and answer["target"]["origin"] == "prior"
            assert answer["uuv_position"]["received"] > 0 and answer["fix"]["status"] == "ok"
            summary = subprocess.run(
                skyfix("status", "--zenoh-connect", live.ep, "--timeout-s", "10"),
                capture_output=True,
                text=True,
                cwd=ROOT,
                timeout=60,
                check=False,
            )
            assert summary.returncode == 0 and "target tracking (prior)" in summary.stdout, summary
            # the run's page (live_helpers: a free port)
            assert "web page http://127.0.0.1:" in summary.stdout
            # late joiners: the latest fix and status on their own keys
            zs = open_session(connect=[live.ep])
            try:
                ok, latest = _ask(zs, "skyfix/uuv/fix")
                assert ok and latest["schema"] == "skyfix.fix/1" and latest["frame"] > 0
                ok, latest_status = _ask(zs, "skyfix/status")
                assert (
                    ok and "target" in latest_status and abs(latest_status["t"] - time.time()) < 5.0
                )
            finally:
                zs.close()
            live.finish()
        finally:
            stop_publisher.set()
            publisher.join(5)

    fixes = live.fixes()
    n_frames = len((SESSION / "video_frames.csv").read_text().splitlines()) - 1
    statuses = [f["status"] for f in fixes]
    first_ok = statuses.index("ok")
    # before the first fix: frames awaiting the target (and frames out of the decoder's buffer: no time, no fix)
    assert statuses[:first_ok].count("awaiting_target") >= 2, statuses[: first_ok + 1]
    assert set(statuses[:first_ok]) <= {"awaiting_target", "buffered"}, statuses[: first_ok + 1]
    ok = [f for f in fixes if f["status"] == "ok"]
    assert len(ok) >= MIN_SHARE * n_frames, (
        f"{len(ok)} ok fixes for {n_frames} frames; {set(statuses)}"
    )
    err = live.fix_errors_m(ok)
    print(
        f"Zenoh: {len(fixes)} fixes, first ok #{first_ok}, {len(ok)} ok, MAE {err.mean():.4f} m, max {err.max():.4f} m"
    )
    assert err.mean() <= 0.1

    gps = live.gps_input()
    types = [g["fix_type"] for g in gps]
    first_valid = types.index(3)
    assert first_valid >= 3 and all(
        g["fix_type"] == 1 and g["ignore_flags"] == 255 for g in gps[:first_valid]
    )
    # nothing before the first ok fix
    assert gps[first_valid]["time_usec"] / 1e6 >= fixes[first_ok]["t"] - 1e-3
    valid = [g for g in gps if g["fix_type"] == 3]
    err = live.gps_errors_m(valid)
    print(
        f"GPS_INPUT: {len(gps)} messages, {first_valid} no-fix before the first valid, {len(valid)} valid, "
        f"MAE {err.mean():.4f} m, max {err.max():.4f} m"
    )
    assert err.mean() <= 0.1


def _track_pixel(t_session: float) -> tuple[float, float]:
    return track_pixel(SESSION, t_session)


def test_select_release_and_select_again_over_zenoh(tmp_path):
    with Live(tmp_path, "--select-history-s", "2") as live:
        zs = open_session(connect=[live.ep])
        try:
            # 1 s of frames awaiting a target: past the burst of frames out of the decoder's buffer at
            # connection, whose exposure times are unknown (the truth pixel at their time would be elsewhere);
            # a second of exposure times, not 30 frames: a loaded machine skips frames (the replay lasts 7 s)
            def awaiting_s() -> float:
                t = [f["t"] for f in live.fixes() if f["status"] == "awaiting_target"]
                return max(t) - min(t) if len(t) >= 2 else 0.0

            wait_for(lambda: awaiting_s() >= 1.0, 25, "a second of frames awaiting a target")
            # bad commands: one-line error replies, nothing changes
            for payload, why in [
                (b"\xff not json", "expected JSON"),
                ({"box": [1, 2]}, "expected 4 finite numbers"),
                ({"box": [300, 160, 36, 36], "frame": 10**9}, "frame 1000000000 is not held"),
                ({"point": [20, 20]}, "no vehicle-sized object stands out"),
                ({"box": [1, 1, 9, 9], "colour": "red"}, "unknown key 'colour'"),
            ]:
                ok, answer = _ask(zs, "skyfix/cmd/select", payload)
                assert not ok and why in answer["error"] and "\n" not in answer["error"], answer
            ok, answer = _ask(zs, "skyfix/cmd/release", b"garbage")
            assert not ok and "takes none" in answer["error"]

            # a box around the UUV on a frame the operator saw a moment ago (the simulator's truth pixel there): the
            # held frames after it span the box's check over frames (STEADY_S, 0.3 s), so it is taken at once
            seen = live.fixes()[-20]
            u, v = _track_pixel(seen["t"] - live.shift)
            w, h = 33, 34  # the vehicle's size in this session's first frame
            ok, answer = _ask(
                zs,
                "skyfix/cmd/select",
                {"box": [u - (w - 1) / 2, v - (h - 1) / 2, w, h], "frame": seen["frame"]},
            )
            assert ok, answer
            assert answer["frame"] == seen["frame"] and answer["target"]["state"] == "tracking"
            assert answer["caught_up"] >= 9, "selected on a past frame, then caught up"
            wait_for(
                lambda: sum(f["status"] == "ok" for f in live.fixes()) >= 15,
                10,
                "ok fixes after select",
            )

            ok, answer = _ask(zs, "skyfix/cmd/release")
            assert ok and answer["target"]["state"] == "released"
            t_released, released_after = time.time(), answer["latest_frame"]
            wait_for(
                lambda: (
                    sum(
                        f["status"] == "released" and f["frame"] > released_after
                        for f in live.fixes()
                    )
                    >= 10
                ),
                10,
                "released frames",
            )

            # a click selects again
            seen = live.fixes()[-1]
            u, v = _track_pixel(seen["t"] - live.shift)
            ok, answer = _ask(
                zs, "skyfix/cmd/select", {"point": [u + 2.0, v - 2.0], "frame": seen["frame"]}
            )
            assert ok, answer
            reselected_after = answer["latest_frame"]
            wait_for(
                lambda: (
                    sum(f["status"] == "ok" and f["frame"] > reselected_after for f in live.fixes())
                    >= 10
                ),
                10,
                "ok fixes after the second select",
            )
            ok, status = _ask(zs, "skyfix/cmd/status")
            assert (
                ok and status["target"]["origin"] == "click" and status["control"]["refused"] == 6
            )
        finally:
            zs.close()
        live.finish()

    fixes = live.fixes()
    by_frame = {f["frame"]: f for f in fixes}
    released = [f for f in fixes if released_after < f["frame"] <= reselected_after]
    assert len(released) >= 10 and {f["status"] for f in released} == {"released"}, {
        f["status"] for f in released
    }
    ok = [f for f in fixes if f["status"] == "ok"]
    err = live.fix_errors_m(ok)
    print(
        f"Zenoh: {len(fixes)} fixes, {len(ok)} ok, {len(released)} released, MAE {err.mean():.4f} m, "
        f"max {err.max():.4f} m"
    )
    assert err.mean() <= 0.1

    # GPS_INPUT after the release: the last fix repeated at most until the first released frame reaches the
    # sink, then no fix until a fix of a frame tracked after the new selection (exposure times: within a third
    # of a frame, the station clock's measured offset from GNSS time)
    gps = live.gps_input()
    after = [g for g in gps if g["t_recv"] > t_released]
    stop_at = next(i for i, g in enumerate(after) if g["fix_type"] != 3)
    t_last_before = by_frame[released_after]["t"]
    assert all(g["time_usec"] / 1e6 <= t_last_before + 0.01 for g in after[:stop_at]), (
        "a new fix after release"
    )
    resume_at = next(i for i, g in enumerate(after) if i > stop_at and g["fix_type"] == 3)
    assert resume_at - stop_at >= 3 and all(
        g["fix_type"] == 1 and g["ignore_flags"] == 255 for g in after[stop_at:resume_at]
    )
    t_first_new = min(f["t"] for f in fixes if f["frame"] > reselected_after)
    assert after[resume_at]["time_usec"] / 1e6 >= t_first_new - 0.01, (
        "fixes resume only from the new selection"
    )
    err = live.gps_errors_m([g for g in gps if g["fix_type"] == 3])
    print(
        f"GPS_INPUT: {len(gps)} messages, {stop_at} repeats of the old fix after the release, "
        f"{resume_at - stop_at} no-fix until the new selection, MAE {err.mean():.4f} m"
    )
    assert err.mean() <= 0.1

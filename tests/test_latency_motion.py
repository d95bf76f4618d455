"""The video's latency from the image's motion, on simulated sessions whose frames are stamped 80 ms
late (``[clock] video_time_error_s``): the UAV yaws (the camera follows its heading) and drifts.

- ``skyfix estimate-latency`` finds the stamps' error in a recording;
- live, a replay sends each frame at its stamped time, so the camera's glass-to-first-packet latency
  is 80 ms: with ``--video-latency-ms 80`` the online estimate agrees within 10 ms after 10 s (720p and
  1080p); with ``--video-latency-ms 0`` it warns; with ``auto`` (720p) it is applied, no GPS_INPUT before
  it is valid (the frames meanwhile are ``latency_unsettled``), and the fixes from then on are as accurate
  as with the right latency configured (MAE within 1.2×, +3 mm for noise)."""

from __future__ import annotations

import json
import socket
import subprocess
import tomllib
from collections.abc import Iterator
from datetime import datetime
from pathlib import Path

import ahead
import numpy as np
import pytest
from live_helpers import ROOT, free_port, read_jsonl, skyfix, start, stop, truth_errors_m
from scipy.spatial.transform import Rotation as Rot
from scipy.spatial.transform import Slerp

from groundstation.latency.estimate import AttitudeTrack, OffsetEstimate, OnlineLatency
from groundstation.session.read import load_session, read_table
from sim_fixtures.generate import generate
from sim_fixtures.scenario import scenario_from_dict

ERROR_S = 0.080
TOLERANCE_S = 0.010
SCENARIO = """
name = "motion_{name}"
description = "22 s, UAV yawing ±10° every 4 s (camera follows) and drifting, frames stamped 80 ms late"
seed = 7
duration_s = 22.0
[camera]
width = {w}
height = {h}
[mount]
attitude_source = "gimbal_device"
gimbal_frame = "earth"
pitch_deg = -90.0
yaw_mode = "vehicle"
[uav]
height_m = 10.0
yaw_swing_deg = 10.0
yaw_period_s = 4.0
drift_m = 0.6
[clock]
video_time_error_s = {error}
"""
SIZES = {"720p": (1280, 720), "1080p": (1920, 1080)}


def _scenario(size: str) -> str:
    w, h = SIZES[size]
    return SCENARIO.format(name=size, w=w, h=h, error=ERROR_S)


def render(tmp: Path, background: bool) -> ahead.Renders:
    """Both sessions, rendered from the run's start on CPU no test wants (``tests/ahead.py``): the largest
    renders of the tests, made while the tests before this module leave a core idle."""
    renders = ahead.Renders()
    for size in SIZES:
        (tmp / f"{size}.toml").write_text(_scenario(size))
        renders[size] = ahead.Render(
            tmp / f"{size}.toml", tmp / size, tmp / f"{size}.log", background
        )
    return renders


pytestmark = pytest.mark.ahead.with_args(render, at_start=True)


@pytest.fixture(scope="module")
def rendered() -> Iterator[ahead.Renders | None]:
    """The sessions rendered ahead, if they were (not when this module runs alone, or first)."""
    renders = ahead.taken(render)
    yield renders
    if renders is not None:
        renders.close()


@pytest.fixture(scope="module", params=list(SIZES))
def session(request, rendered, tmp_path_factory) -> Path:
    if rendered is not None:
        return rendered[request.param].wait(900)
    text = _scenario(request.param)
    out = tmp_path_factory.mktemp(f"motion_{request.param}")
    generate(scenario_from_dict(tomllib.loads(text)), out, text)
    return out


def test_sim_knob_stamps_frames_late(tmp_path):
    text = SCENARIO.format(name="knob", w=320, h=180, error=ERROR_S)
    generate(scenario_from_dict(tomllib.loads(text)), tmp_path, text, video=False)
    stamped = read_table(tmp_path / "video_frames.csv", ("frame", "t"))["t"]
    true = read_table(tmp_path / "truth.csv", ("t", "lat", "lon", "depth_m"))["t"]
    assert len(stamped) == len(true) > 300
    assert np.allclose(stamped - true, ERROR_S, atol=2e-6, rtol=0)


def test_estimate_latency_of_a_recording(session):
    out = subprocess.run(
        skyfix("estimate-latency", str(session)),
        capture_output=True,
        text=True,
        cwd=ROOT,
        check=False,
        timeout=300,
    )
    print(out.stdout)
    assert out.returncode == 0, out.stdout + out.stderr
    offset_ms = float(out.stdout.split("moved by ")[1].split(" ms")[0])
    assert abs(offset_ms / 1000 + ERROR_S) <= TOLERANCE_S


def _live(session: Path, latency: str, tmp: Path) -> tuple[dict, list[dict], float, str]:
    """``skyfix run`` fed by ``skyfix replay``: final status, GPS_INPUT at the UUV, the replay's shift, the log."""
    tmp.mkdir()
    mav, video, uuv, zport = free_port(), free_port(), free_port(), free_port(socket.SOCK_STREAM)
    ep = f"tcp/127.0.0.1:{zport}"
    run = start(
        skyfix(
            "run",
            "--calibration",
            str(session / "session.toml"),
            "--mavlink",
            f"udpin:127.0.0.1:{mav}",
            "--video",
            f"udp://127.0.0.1:{video}",
            "--video-latency-ms",
            latency,
            "--zenoh-listen",
            ep,
            "--gps-input",
            f"udpout:127.0.0.1:{uuv}",
            "--stats",
            str(tmp / "stats.json"),
        ),
        tmp / "run.log",
    )
    try:
        replay = subprocess.run(
            skyfix(
                "replay",
                str(session),
                "--mavlink-out",
                f"udpout:127.0.0.1:{mav}",
                "--video-out",
                f"udp://127.0.0.1:{video}",
                "--zenoh-connect",
                ep,
                "--uuv-listen",
                f"udpin:127.0.0.1:{uuv}",
                "--uuv-log",
                str(tmp / "uuv.jsonl"),
                "--lead-s",
                "3",
            ),
            capture_output=True,
            text=True,
            cwd=ROOT,
            timeout=120,
            check=False,
        )
    finally:
        stop(run, timeout_s=20)
    log = (tmp / "run.log").read_text()
    assert run.returncode == 0 and replay.returncode == 0, log[-3000:]
    (tmp / "replay.out").write_text(replay.stdout)
    shift = json.loads(replay.stdout.splitlines()[0])["shift_s"]
    return json.loads((tmp / "stats.json").read_text()), read_jsonl(tmp / "uuv.jsonl"), shift, log


def _errors(
    session: Path, gps: list[dict], shift: float, since_unix: float = 0.0
) -> dict[float, float]:
    """Horizontal error (m) of each new valid fix received after ``since_unix``, by its true frame time."""
    truth_t = load_session(session).truth["t"]
    fixes = {}
    for g in gps:
        if g["fix_type"] == 3 and g["t_recv"] >= since_unix:
            fixes.setdefault(g["time_usec"], g)
    t_fix = np.array(sorted(fixes)) / 1e6 - shift
    err = truth_errors_m(
        session,
        t_fix,
        [fixes[k]["lat"] / 1e7 for k in sorted(fixes)],
        [fixes[k]["lon"] / 1e7 for k in sorted(fixes)],
    )
    frame_t = truth_t[
        np.abs(truth_t[None, :] - t_fix[:, None]).argmin(axis=1)
    ]  # the same frame in either run
    return dict(zip(np.round(frame_t, 4), err))


def _applied_at(log: str) -> float:
    line = next(line for line in log.splitlines() if "from the image's motion, applied" in line)
    return datetime.strptime(line[:23], "%Y-%m-%d %H:%M:%S,%f").timestamp()


@pytest.fixture(scope="module")
def configured(session, tmp_path_factory) -> tuple[dict, list[dict], float, str]:
    """The live run with the right latency configured, once per session."""
    return _live(session, str(round(ERROR_S * 1000)), tmp_path_factory.mktemp("right") / "run")


def test_online_estimate(configured):
    right, _, _, log_right = configured
    est = right["video"]["latency_from_motion"]
    print(
        f"configured 80 ms: {est}; video { ({k: right['video'][k] for k in ('frames', 'skipped_behind')}) }"
    )
    assert abs(est["estimate_ms"] / 1000 - ERROR_S) <= TOLERANCE_S and est["sigma_ms"] <= 10
    assert "not the configured" not in log_right


def _latency_lines(log: str) -> str:
    """The auto run's account of its latency: each application (and what it replaced), warnings, failures."""
    return "\n".join(
        line for line in log.splitlines() if "skyfix.latency" in line or "video-latency" in line
    )


def _per_frame(err_auto: dict[float, float], err_right: dict[float, float], out: Path) -> str:
    """Each frame's error in both runs, written to ``out``; the ten worst in the auto run, for the message."""
    common = sorted(set(err_auto) & set(err_right))
    rows = [(t, err_auto[t], err_right[t]) for t in common]
    out.write_text(
        "t_truth,err_auto_m,err_configured_m\n"
        + "".join(f"{t},{a:.4f},{r:.4f}\n" for t, a, r in rows)
    )
    worst = sorted(rows, key=lambda r: -r[1])[:10]
    return f"worst frames (truth.csv t: auto m / configured m; all in {out}): " + ", ".join(
        f"{t:.2f}: {a:.3f}/{r:.3f}" for t, a, r in worst
    )


# auto at 720p only: at 1080p on a loaded 2-core CI the service decodes too few frames to settle within the
# session (52 of the 60 frame pairs one estimate needs, 19 s in; 149 on a quiet machine), which is the rule
# working, not the estimate failing; the 1080p measurement itself is checked above. On a failure the message
# says why: what was applied when (the service logs each application), the status, and each frame's errors.
@pytest.mark.parametrize("session", ["720p"], indirect=True)
def test_auto_applies_the_estimate(session, configured, tmp_path):
    _, gps_right, shift_right, _ = configured
    auto, gps_auto, shift_auto, log_auto = _live(session, "auto", tmp_path / "auto")
    applied = auto["video"]["latency_from_motion"]
    why = (
        f"auto: {applied}; video {auto['video'].get('frames')} frames, "
        f"{auto['video'].get('skipped_behind')} skipped behind; statuses {auto['pipeline']['statuses']}; "
        f"last target {auto.get('target')}\n{_latency_lines(log_auto)}"
    )
    print(why)
    assert (
        applied["applied_ms"] is not None
        and abs(applied["applied_ms"] / 1000 - ERROR_S) <= TOLERANCE_S
    ), why
    assert (
        0 < applied["applied_sigma_ms"] <= 5
        and auto["video"]["latency_ms"] == applied["applied_ms"]
    ), why
    applied_at = _applied_at(log_auto)  # logged before the first frame is stamped with it
    before = [g for g in gps_auto if g["t_recv"] < applied_at]
    assert len(before) > 20 and all(g["fix_type"] == 1 for g in before), (
        "a valid GPS_INPUT before auto settled"
    )
    assert auto["pipeline"]["statuses"].get("latency_unsettled", 0) > 20, auto["pipeline"][
        "statuses"
    ]
    assert "latency_unsettled" not in configured[0]["pipeline"]["statuses"]
    err_auto = _errors(session, gps_auto, shift_auto, since_unix=applied_at)
    err_right = _errors(session, gps_right, shift_right)
    common = sorted(set(err_auto) & set(err_right))
    assert len(common) >= 30, (
        f"only {len(common)} frames with fixes in both runs after the latency was applied "
        f"(auto: {len(err_auto)} frames {min(err_auto, default=None)} … "
        f"{max(err_auto, default=None)}; configured: {len(err_right)} frames)\n{why}"
    )
    mae_auto = float(np.mean([err_auto[t] for t in common]))
    mae_right = float(np.mean([err_right[t] for t in common]))
    print(
        f"MAE over {len(common)} frames after auto applied: auto {mae_auto:.4f} m, configured {mae_right:.4f} m"
    )
    assert mae_auto <= 1.2 * mae_right + 0.003, (
        f"{why}\n{_per_frame(err_auto, err_right, tmp_path / 'errors.csv')}"
    )


def test_a_wrong_configured_latency_is_warned_about(caplog):
    """The warning, from an estimate 80 ms off the configured 0 ms (the estimator's own judgement, no video)."""
    online = OnlineLatency(
        load_session(ROOT / "sim_fixtures" / "bundled" / "nadir_hover").calibration, None, 0.0
    )
    for offset_s in (-0.080, -0.081, -0.079):  # sure, and steady over three estimates: one warning
        online._judge(OffsetEstimate(offset_s, 0.004, 200, 0.1))
    for offset_s in (-0.020, -0.021, -0.020):  # within 30 ms of the configured: no warning
        online._judge(OffsetEstimate(offset_s, 0.004, 210, 0.1))
    for offset_s in (-0.200, -0.150, -0.250):  # far off but not steady: no warning
        online._judge(OffsetEstimate(offset_s, 0.004, 210, 0.1))
    lines = [r.getMessage() for r in caplog.records if "not the configured" in r.getMessage()]
    assert len(lines) == 1 and "79 ± 4 ms" in lines[0] and "configured 0 ms" in lines[0]


def test_auto_settles_on_new_frame_pairs_only():
    """A starved service (its decoder behind, its measuring process waiting for a core) estimates again from the
    same frame pairs: such repeats agree by themselves and must not settle; three from new pairs do, and the
    applied latency's sigma covers their spread."""
    applied = []
    online = OnlineLatency(
        load_session(ROOT / "sim_fixtures" / "bundled" / "nadir_hover").calibration,
        None,
        None,
        applied.append,
    )
    stale = OffsetEstimate(-0.060, 0.001, 70, 0.1, 12.0)
    for _ in range(5):  # the same pairs, once a second
        online._judge(stale)
    assert not online.settled and online.applied_s is None and applied == []
    for offset_s, t_to in ((-0.0615, 12.4), (-0.0630, 12.9)):
        online._judge(OffsetEstimate(offset_s, 0.001, 74, 0.1, t_to))
    spread_s = np.std([-0.060, -0.0615, -0.063], ddof=1)
    assert online.settled and applied == [0.063]
    assert online.applied_sigma_s == pytest.approx(np.hypot(0.001, spread_s), rel=1e-12)


def _rodrigues(rotvec: np.ndarray) -> np.ndarray:
    """Rotation matrices of rotation vectors (N, 3), written out here (Rodrigues' formula)."""
    angle = np.linalg.norm(rotvec, axis=1)
    k = rotvec / angle[:, None]
    kx = np.zeros((len(k), 3, 3))
    kx[:, 0, 1], kx[:, 0, 2], kx[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
    kx -= kx.transpose(0, 2, 1)
    s, c = np.sin(angle)[:, None, None], np.cos(angle)[:, None, None]
    return np.eye(3) + s * kx + (1 - c) * kx @ kx


def test_attitude_track_relative_rotations():
    """The track's relative rotations R(t1)ᵀ R(t0) between and on its samples, against rotations
    worked out independently: a steady turn of 4 rad/s about a fixed axis (through ±π, where the
    quaternions of neighbouring samples change sign) has R(t1)ᵀ R(t0) = a turn of −4 (t1 − t0) rad;
    a wobble about two axes is checked against scipy's Slerp on the same samples."""
    rng = np.random.default_rng(3)
    t = 0.01 + np.arange(0.0, 2.0, 0.005)  # no zero angle: the formula divides by it
    axis = np.array([0.6, -0.48, 0.64])
    track = AttitudeTrack(t, _rodrigues(4.0 * t[:, None] * axis))
    t0 = rng.uniform(0.01, 1.8, 2000)
    t1 = t0 + rng.uniform(0.0, 0.15, 2000)
    expected = -4.0 * (t1 - t0)[:, None] * axis
    assert np.abs(track.relative(t0, t1) - expected).max() < 1e-6
    assert np.abs(track.relative(t[10:20], t[30:40]) - (-4.0 * 0.1 * axis)).max() < 1e-9

    wobble = np.stack([0.8 * np.sin(3.0 * t), 0.5 * np.cos(2.0 * t), 0.3 + 0.0 * t], axis=1)
    R = _rodrigues(wobble)
    track = AttitudeTrack(t, R)
    slerp = Slerp(t, Rot.from_matrix(R))
    expected = (slerp(t1).inv() * slerp(t0)).as_rotvec()
    assert np.abs(track.relative(t0, t1) - expected).max() < 1e-6


def test_online_estimate_is_measured_in_a_nicer_process():
    """The live estimator's work runs in a process of its own 10 nice levels below the service (a thread of the
    service holding the interpreter's lock at a low priority kept the frames waiting beside busy programs), its
    handing thread at the service's priority, and it estimates exactly what the same work does in-process."""
    import asyncio
    import multiprocessing
    import os
    import time

    from groundstation.latency.estimate import MotionEstimator
    from groundstation.video.file import open_video

    session = load_session(ROOT / "sim_fixtures" / "bundled" / "nadir_hover")
    cal, tel = session.calibration, session.telemetry
    with open_video(session.video_path) as video:
        frames = [(float(session.frames["t"][f.index]), f.image) for f in video if f.index % 3 == 0]
    now = frames[-1][0] + 0.5
    online = OnlineLatency(cal, tel, 0.0)
    online._loop = loop = asyncio.new_event_loop()
    before = set(multiprocessing.active_children())
    online.worker.start()
    try:
        for frame in frames:
            online._frames.put(frame, timeout=30.0)
        deadline = time.monotonic() + 60.0
        while not online._frames.empty() and time.monotonic() < deadline:
            online.worker.stop.wait(0.01)
        # taken once the frame in hand is measured: the estimate has them all
        online._tel = (tel, now)
        while online.estimate is None and time.monotonic() < deadline:
            online.worker.stop.wait(0.05)
        children = [c for c in multiprocessing.active_children() if c not in before]
        assert len(children) == 1
        service_nice = os.getpriority(os.PRIO_PROCESS, 0)
        assert os.getpriority(os.PRIO_PROCESS, online.worker.thread.native_id) == service_nice
        assert os.getpriority(os.PRIO_PROCESS, children[0].pid) == min(service_nice + 10, 19)
    finally:
        online.worker.join(5.0)
        loop.close()
    in_process = MotionEstimator(cal, online.window_s, online.offsets)
    for t, image in frames:
        in_process.measure(t, image)
    expected = in_process.estimate(tel, now)
    assert expected is not None and online.estimate == expected

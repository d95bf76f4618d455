"""Priority inversion on the interpreter's lock, isolated: a frame thread beside background Python at a low priority.

    .venv/bin/python bench/gil_inversion.py [--session DIR] [--seconds 10] [--rounds 3] [--nice -10]
        [--modes none,...] [--out bench/results/gil_inversion.txt]

This process stands for ``skyfix run`` at the unit's priority (``--nice``, as deploy/skyfix.service's ``Nice=``;
negative needs root) beside two processes spinning ``while True: pass`` at the bench's own priority. Its frame
thread wakes at each slot of a 30 fps stream and runs 2 ms of Python (a frame's work holding the lock); measured:
slot → done, p50/p99/max, and the slots it missed. Beside it, once a second, the live latency estimate's main piece of
Python and NumPy (:meth:`AttitudeTrack.from_telemetry` over its 20-s window of the session's telemetry, some 80 ms
of CPU holding the lock), in one of four ways (interleaved, ``--rounds`` times):

- ``none``: no background work (the floor);
- ``thread_nice10``: in a thread of this process at nice 10 (``os.setpriority`` on its thread id: what the estimate's
  thread did before it moved to a process). Beside busy programs the thread gets a core seldom; preempted while it
  holds the lock, the frame thread waits for it until it runs again;
- ``thread_same``: in a thread at the process's own priority (it takes its share of the lock, at once);
- ``process``: in a process of its own 10 nice levels below this one (what the live estimate does now,
  :class:`groundstation.latency.estimate.OnlineLatency`): it takes a core's time, never this process's lock;
- ``feed_nice10``: instead, the operator page's feed encoder as it runs (a thread at nice 10,
  :func:`groundstation.live.ui.feed.lower_priority`): a frame of the session's video to JPEG
  (:func:`~groundstation.live.ui.feed.encode_jpeg`, 960 pixels wide) 10 times a second, its work in OpenCV with
  the lock released;
- ``mosaic_nice10``: instead, the live mosaic's painting as it ran before it moved to a process: a frame of the
  session's video painted once a second (:meth:`groundstation.live.mosaic_live.MosaicPainter.paint_frame`, floor 2 m
  below the surface) in a thread at nice 10;
- ``mosaic_process``: the live mosaic as it runs now (:class:`~groundstation.live.mosaic_live.LiveMosaic`): a
  thread at this process's priority hands the frame to the painting process (shared memory, the process 10 nice
  levels below this one) once a second and waits for it;
- ``reference_nice10``: instead, the search for a surveyed marker as it ran before it moved to a process: a 1080p
  frame of ``--marker-session`` searched 5 times a second (``reference_every_s``' default;
  :func:`groundstation.live.reference_live.search`) in a thread at nice 10;
- ``reference_process``: the search as it runs now (:meth:`groundstation.live.reference_live.LiveReference.look`, as
  its :class:`~groundstation.live.every_frame.EveryFrame` thread calls it: a thread at this process's priority hands
  the frame to the search's process and waits);
- ``bottom_nice10``: instead, the live bottom's work as it ran before it moved to processes: the 1080p frames of
  ``--bottom-session`` in turn, 4 a second (``bottom_every_s``' default), tracked into the window
  (:meth:`groundstation.live.bottom_live.BottomWindow.add`) in a thread at nice 10, and every 2 s of video the
  estimate fitted over the window (10 s) in a second thread at nice 10;
- ``bottom_process``: the bottom as it runs now (:meth:`groundstation.live.bottom_live.LiveBottom.look` from a thread
  at this process's priority: the frame to the tracking process, the window to the fitting process).

``--modes`` runs a subset.

Without ``--session``, ``bench/live_latency.py``'s 1080p session (``/tmp/skyfix-bench/live_1080p_20s``, rendered
by that bench). ``--marker-session`` (sensors_plain_nadir with its marker, 2 s at 1920x1080) and
``--bottom-session`` (bottom_survey, 6 s at 4 fps and 1920x1080) are generated there when missing.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import multiprocessing
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
from emit import emit

from groundstation.latency.estimate import AttitudeTrack
from groundstation.live.bottom_live import REFIT_S, BottomWindow, LiveBottom, Platform
from groundstation.live.mosaic_live import LiveMosaic, MosaicPainter
from groundstation.live.reference_live import LiveReference, search
from groundstation.live.ui.feed import encode_jpeg, lower_priority
from groundstation.offline.bottom import bias_headings, tilt_frame
from groundstation.offline.reference import read_file
from groundstation.session.read import load_session
from groundstation.video.file import open_video
from localizer.pose import camera_pose, take, uav_pose

ROOT = Path(__file__).resolve().parents[1]
MODES = (
    "none",
    "thread_nice10",
    "thread_same",
    "process",
    "feed_nice10",
    "mosaic_nice10",
    "mosaic_process",
    "reference_nice10",
    "reference_process",
    "bottom_nice10",
    "bottom_process",
)
FLOOR_DEPTH_M = 2.0  # the live mosaic's floor below the surface
FRAME_S = 1.0 / 30.0
FRAME_WORK_S = 0.002  # a frame's Python, holding the lock
WINDOW_S = 20.0  # the live estimate's window
REFERENCE_EVERY_S = 0.2  # reference_every_s' default
BOTTOM_EVERY_S = 0.25  # bottom_every_s' default
BOTTOM_WINDOW_S = 10.0  # bottom_window_s' default
BENCH_DIR = Path("/tmp/skyfix-bench")


def python_for(cpu_s: float) -> None:
    """Pure Python (the lock held) for ``cpu_s`` of this thread's CPU time."""
    t_end = time.thread_time() + cpu_s
    while time.thread_time() < t_end:
        sum(range(200))


def estimate_job(session_dir: str):
    """The latency estimate's attitude track over its window, as a call."""
    session = load_session(session_dir)
    cal, tel = session.calibration, session.telemetry
    t0 = float(session.frames["t"][0]) + 1.0
    return lambda: AttitudeTrack.from_telemetry(cal, tel, t0, t0 + WINDOW_S)


def once_a_second(job, stop, period_s: float = 1.0) -> None:
    """``job()`` every ``period_s`` (once a second) until ``stop``; a late one starts at once."""
    while not stop.is_set():
        t0 = time.monotonic()
        job()
        stop.wait(max(0.0, period_s - (time.monotonic() - t0)))


def ensure_session(name: str, scenario: str, **overrides) -> Path:
    """A session generated once into :data:`BENCH_DIR` (``scenario`` with ``overrides``, 1920x1080)."""
    path = BENCH_DIR / name
    if not (path / "session.toml").exists():
        from sim_fixtures.generate import generate
        from sim_fixtures.scenario import load_scenario, with_overrides

        sc = load_scenario(ROOT / "sim_fixtures" / "scenarios" / f"{scenario}.toml")
        sc = with_overrides(sc, camera={"width": 1920, "height": 1080}, **overrides)
        generate(sc, path, video=True)
    return path


def reference_thread(session_dir: str, stop, ready, in_process: bool) -> None:
    """The marker's search on one frame 5 times a second: in this thread at nice 10, or handed to its process."""
    session = load_session(session_dir)
    cal, tel = session.calibration, session.telemetry
    ref, radius_m = read_file(Path(session_dir) / "reference.toml")
    with open_video(session.video_path) as video:
        image = next(iter(video)).image
    pose = uav_pose(cal, tel, float(session.frames["t"][0]))
    if search(cal, radius_m, image, pose, ref) is None:
        raise SystemExit(f"{session_dir}: the marker is not found in its first frame")
    if in_process:
        live = LiveReference(cal, tel, "reference.toml", ref, radius_m, REFERENCE_EVERY_S)
        live._process.started.result()  # started
        work = live.look  # its EveryFrame thread's work
    else:  # its thread at nice 10, as it was
        lower_priority()
        work = lambda image, pose: search(cal, radius_m, image, pose, ref)
    ready.set()
    try:
        once_a_second(lambda: work(image, pose), stop, REFERENCE_EVERY_S)
    finally:
        if in_process:
            live.close()


def bottom_frames(session_dir: str):
    """The session's platform, the tilt's bias frame and its frames as the bottom takes them: (image, pose of one
    frame, bias-frame heading)."""
    session = load_session(session_dir)
    platform = Platform(session.calibration, session.telemetry)
    frame_tilt = tilt_frame(platform)
    t = np.asarray(session.frames["t"], float)
    pose = camera_pose(session.calibration, session.telemetry, t)
    headings = bias_headings(platform, pose, frame_tilt)
    with open_video(session.video_path) as video:
        frames = [(f.image, take(pose, [f.index]), float(headings[f.index])) for f in video]
    return platform, frame_tilt, frames


def bottom_thread(session_dir: str, stop, ready, in_process: bool) -> None:
    """The bottom's frames in turn 4 a second (their times moved on by the session's length at each turn), tracked and
    fitted in threads at nice 10, or handed to its processes."""
    platform, frame_tilt, frames = bottom_frames(session_dir)
    turn_s = len(frames) * BOTTOM_EVERY_S
    k = 0
    if in_process:
        live = LiveBottom(platform.calibration, platform.telemetry, BOTTOM_EVERY_S, BOTTOM_WINDOW_S)
        live._tracking.started.result()  # started
        live._fitting_process.started.result()

        def step(image, pose, heading: float) -> None:
            live._headings.append((float(pose.t_unix[0]), frame_tilt, heading))
            live.look(image, pose)  # its EveryFrame thread's work
    else:  # its threads at nice 10, as they were
        window = BottomWindow(platform, BOTTOM_WINDOW_S, frame_tilt)
        fitter = ThreadPoolExecutor(1, initializer=lower_priority)
        lower_priority()
        fitting, last_fit_t = [], [math.nan]

        def step(image, pose, heading: float) -> None:
            window.add(image, pose, heading, math.nan, math.nan)
            t = float(pose.t_unix[0])
            if math.isnan(last_fit_t[0]):
                last_fit_t[0] = t
            if t - last_fit_t[0] >= REFIT_S and not (fitting and not fitting[0].done()):
                last_fit_t[0] = t
                fitting[:] = [fitter.submit(window.fit, window.snapshot())]

    def next_frame() -> None:
        nonlocal k
        image, pose, heading = frames[k % len(frames)]
        moved = dataclasses.replace(pose, t_unix=pose.t_unix + (k // len(frames)) * turn_s)
        step(image, moved, heading)
        k += 1

    ready.set()
    try:
        once_a_second(next_frame, stop, BOTTOM_EVERY_S)
    finally:
        if in_process:
            live.close()
        else:
            fitter.shutdown(wait=True, cancel_futures=True)


def background_thread(session_dir: str, stop: threading.Event, nice: int | None) -> None:
    job = estimate_job(session_dir)
    if nice is not None:
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), nice)
    once_a_second(job, stop)


def feed_thread(session_dir: str, stop: threading.Event) -> None:
    session = load_session(session_dir)
    with open_video(session.video_path) as video:
        image = next(iter(video)).image
    lower_priority()
    while not stop.is_set():
        t0 = time.monotonic()
        encode_jpeg(image, 960, 80)
        stop.wait(max(0.0, 0.1 - (time.monotonic() - t0)))


def mosaic_thread(session_dir: str, stop: threading.Event, in_process: bool) -> None:
    """The live mosaic's painting once a second: in this thread at nice 10, or handed to its process."""
    session = load_session(session_dir)
    cal, tel = session.calibration, session.telemetry
    with open_video(session.video_path) as video:
        image = next(iter(video)).image
    pose = uav_pose(cal, tel, float(session.frames["t"][0]))
    with tempfile.TemporaryDirectory(prefix="skyfix-bench-mosaic-") as spill:
        if in_process:
            live = LiveMosaic(cal, tel, FLOOR_DEPTH_M, 1.0)
            paint = live._paint_frame  # its EveryFrame thread's work
        else:  # its thread at nice 10, as it was
            paint = MosaicPainter(cal, FLOOR_DEPTH_M, Path(spill)).paint_frame
            lower_priority()
        try:
            once_a_second(lambda: paint(image, pose), stop)
        finally:
            if in_process:
                live.close()


def background_process(session_dir: str, stop) -> None:
    os.nice(10)
    once_a_second(estimate_job(session_dir), stop)


def frames(seconds: float) -> tuple[np.ndarray, int]:
    """The frame thread (this one) for ``seconds``: slot → done of each frame (ms) and the slots missed."""
    done, missed = [], 0
    t_slot = time.monotonic() + FRAME_S
    t_end = time.monotonic() + seconds
    while t_slot < t_end:
        time.sleep(max(0.0, t_slot - time.monotonic()))
        python_for(FRAME_WORK_S)
        done.append(time.monotonic() - t_slot)
        t_slot += FRAME_S
        while t_slot < time.monotonic():  # slots gone by while this one was late: missed
            t_slot += FRAME_S
            missed += 1
    return np.array(done) * 1000.0, missed


def one_run(mode: str, session_dir: str, seconds: float, sessions: dict[str, str]) -> dict:
    stop, ready = threading.Event(), threading.Event()
    spawn = multiprocessing.get_context("spawn")
    pstop = spawn.Event()
    worker = None
    side = {"reference": reference_thread, "bottom": bottom_thread}.get(mode.split("_")[0])
    if mode.startswith("thread"):
        nice = 10 if mode == "thread_nice10" else None
        worker = threading.Thread(
            target=background_thread, args=(session_dir, stop, nice), daemon=True
        )
    elif mode == "feed_nice10":
        worker = threading.Thread(target=feed_thread, args=(session_dir, stop), daemon=True)
    elif mode.startswith("mosaic"):
        worker = threading.Thread(
            target=mosaic_thread, args=(session_dir, stop, mode == "mosaic_process"), daemon=True
        )
    elif mode == "process":
        worker = spawn.Process(target=background_process, args=(session_dir, pstop), daemon=True)
    elif side is not None:
        worker = threading.Thread(
            target=side,
            args=(sessions[mode.split("_")[0]], stop, ready, mode.endswith("_process")),
            daemon=True,
        )
    if worker is not None:
        worker.start()
    if side is not None:  # its frames read, its processes started
        ready.wait(120.0)
    time.sleep(2.0)  # the background's imports and the session's loading done
    load = os.getloadavg()[0]
    done_ms, missed = frames(seconds)
    stop.set()
    pstop.set()
    if worker is not None:
        worker.join(30.0)
    return {
        "p50_ms": round(float(np.percentile(done_ms, 50)), 1),
        "p99_ms": round(float(np.percentile(done_ms, 99)), 1),
        "max_ms": round(float(done_ms.max()), 1),
        "frames": len(done_ms),
        "missed": missed,
        "load_average": round(load, 1),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--session", default=str(BENCH_DIR / "live_1080p_20s"))
    ap.add_argument("--marker-session", type=Path, default=None)
    ap.add_argument("--bottom-session", type=Path, default=None)
    ap.add_argument("--seconds", type=float, default=10.0, help="frames per run, s")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--nice", type=int, default=-10, help="this process's nice (the service's)")
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "gil_inversion.txt")
    ap.add_argument(
        "--modes", default=",".join(MODES), help="comma-separated, of: " + ", ".join(MODES)
    )
    args = ap.parse_args()
    modes = args.modes.split(",")
    if set(modes) - set(MODES):
        ap.error(f"--modes {args.modes}: each of {', '.join(MODES)}")
    sessions = {}
    if any(m.startswith("reference") for m in modes):
        sessions["reference"] = str(
            args.marker_session
            or ensure_session(
                "marker_1080p",
                "sensors_plain_nadir",
                duration_s=2.0,
                fps=15.0,
                marker={"enabled": True},
            )
        )
    if any(m.startswith("bottom") for m in modes):
        sessions["bottom"] = str(
            args.bottom_session
            or ensure_session("bottom_1080p", "bottom_survey", duration_s=6.0, fps=4.0)
        )
    spinners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    os.setpriority(os.PRIO_PROCESS, 0, args.nice)  # after the spinners: they keep the bench's own
    lines = [
        (
            f"interpreter-lock inversion bench, {time.strftime('%Y-%m-%d %H:%M:%S %Z')}, {os.cpu_count()} cores, "
            f"load average {os.getloadavg()[0]:.1f}; frame thread at nice {os.getpriority(os.PRIO_PROCESS, 0)}, "
            f"2 busy processes at nice {os.getpriority(os.PRIO_PROCESS, spinners[0].pid)}; {args.seconds:g} s a run"
        )
    ]
    results: dict[str, list[dict]] = {m: [] for m in modes}
    try:
        for rnd in range(1, args.rounds + 1):
            for mode in modes:
                r = one_run(mode, args.session, args.seconds, sessions)
                results[mode].append(r)
                lines.append(
                    f"round {rnd} {mode:17s} slot -> done p50 {r['p50_ms']} ms, p99 {r['p99_ms']} ms, max "
                    f"{r['max_ms']} ms; {r['frames']} frames, {r['missed']} slots missed (load {r['load_average']})"
                )
                print(lines[-1], flush=True)
    finally:
        for p in spinners:
            p.kill()
            p.wait()

    def spread(key: str, runs: list[dict]) -> str:
        v = [r[key] for r in runs]
        return f"{statistics.median(v):.1f} [{min(v):.1f}-{max(v):.1f}]"

    lines.append(f"median [min-max] over {args.rounds} rounds:")
    lines += [
        f"  {mode:17s} p99 {spread('p99_ms', runs)} ms, p50 {spread('p50_ms', runs)} ms, missed "
        f"{spread('missed', runs)}, load {spread('load_average', runs)}"
        for mode, runs in results.items()
    ]
    emit(lines, args.out, results)
    return 0


if __name__ == "__main__":
    sys.exit(main())

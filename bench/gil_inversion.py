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
  levels below this one) once a second and waits for it.

``--modes`` runs a subset.

Without ``--session``, ``bench/live_latency.py``'s 1080p session (``/tmp/skyfix-bench/live_1080p_20s``, rendered
by that bench).
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
from emit import emit

from groundstation.latency.estimate import AttitudeTrack
from groundstation.live.mosaic_live import LiveMosaic, MosaicPainter
from groundstation.live.ui.feed import encode_jpeg, lower_priority
from groundstation.session.read import load_session
from groundstation.video.file import open_video
from localizer.pose import uav_pose

ROOT = Path(__file__).resolve().parents[1]
MODES = (
    "none",
    "thread_nice10",
    "thread_same",
    "process",
    "feed_nice10",
    "mosaic_nice10",
    "mosaic_process",
)
FLOOR_DEPTH_M = 2.0  # the live mosaic's floor below the surface
FRAME_S = 1.0 / 30.0
FRAME_WORK_S = 0.002  # a frame's Python, holding the lock
WINDOW_S = 20.0  # the live estimate's window


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


def once_a_second(job, stop) -> None:
    while not stop.is_set():
        t0 = time.monotonic()
        job()
        stop.wait(max(0.0, 1.0 - (time.monotonic() - t0)))


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


def one_run(mode: str, session_dir: str, seconds: float) -> dict:
    stop = threading.Event()
    spawn = multiprocessing.get_context("spawn")
    pstop = spawn.Event()
    worker = None
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
    if worker is not None:
        worker.start()
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
    ap.add_argument("--session", default="/tmp/skyfix-bench/live_1080p_20s")
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
                r = one_run(mode, args.session, args.seconds)
                results[mode].append(r)
                lines.append(
                    f"round {rnd} {mode:14s} slot -> done p50 {r['p50_ms']} ms, p99 {r['p99_ms']} ms, max "
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
        f"  {mode:14s} p99 {spread('p99_ms', runs)} ms, p50 {spread('p50_ms', runs)} ms, missed "
        f"{spread('missed', runs)}, load {spread('load_average', runs)}"
        for mode, runs in results.items()
    ]
    emit(lines, args.out, results)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Where ``skyfix process``'s milliseconds go: per frame and per stage, wall time, CPU time and time holding the
interpreter, at 720p and 1080p with one, two and three UUVs (issue 30).

    .venv/bin/python bench/profile_stages.py [--sizes 720p,1080p] [--counts 1,2,3] [--duration-s 20] [--frames 150]
                                      [--out bench/results/profile.txt]

The session is ``bench/uuvs.py``'s three-UUV session (``three_uuvs_crossing``, three vehicles in the video, as
``bench/offline_speed.py --uuvs`` times it) at 1280x720 or 1920x1080 (``--duration-s``, generated once into
``/tmp/skyfix-bench/``); its first ``--frames`` frames are profiled (every frame is kept decoded: 3 MB each at
1080p). One, two and three UUVs are that many :class:`~localizer.tracking.session.TrackingSession` on the same
frames.

Stages, each run as ``skyfix process`` runs it (the same functions, the same arguments):

- ``decode``: FFmpeg (PyAV) demux + decode to the luma plane, frame threads as
  :func:`~groundstation.video.file.open_video` reads grey; every frame is decoded first and kept, so the decoder's
  threads run during this stage alone and the process CPU of the others is theirs;
- ``colour``: the luma plane's frame made ready for BGR (:meth:`~groundstation.video.frames.VideoFrame.bgr_regions`),
  for the frames the height from size measures; the windows a measurement reads are converted in its ``size`` stage;
- ``motion``: the camera's rotation between frames (:class:`~groundstation.latency.video_motion.RotationMeter`),
  in the frames ``skyfix process`` measures (:func:`~groundstation.latency.video_motion.measured_every` of the
  whole session's frames); the command measures it only where the link's delay is unknown (not in this session);
- ``track ID``: one UUV's :meth:`~localizer.tracking.session.TrackingSession.step`;
- ``size ID``: one UUV's height from its size (:class:`~groundstation.height_from_size.HeightFromSize`), the UUVs
  sharing one estimate and one measuring schedule as ``skyfix process --uuv all`` has them
  (:func:`~groundstation.height_from_size.shared_sizes`: the UUVs measured at the rate of one, in turns);
- ``load``: the session read as each UUV's (:func:`~groundstation.session.read.load_sessions`: the telemetry log
  parsed once), before the pass (``skyfix process`` decodes meanwhile: :func:`~groundstation.video.file.decoding_early`);
- ``pose``: every frame's camera pose at once (:func:`localizer.pose.camera_pose`), as the tracker shares it;
- ``offset``: the frames' offset to the telemetry from the rotations
  (:func:`~groundstation.latency.estimate.offset_from_rotations`);
- ``geometry ID``: the fixes of one UUV's pixels (:func:`groundstation.offline.process.locate_frames`);
- ``output ID``: positions.csv, the smoothed track and positions_smoothed.csv of one UUV.

The batch stages (load, pose, offset, geometry, output) are shown per frame (their total over the frames). ``start-up``:
``skyfix process --help`` in a child process (the interpreter and the command's imports), once per run.

**Method.** Per stage: wall time (``time.perf_counter``), the main thread's CPU (``time.thread_time``) and the
process's CPU (``time.process_time``: every thread, so OpenCV's and FFmpeg's worker threads count).
**Time holding the interpreter** is sampled by a probe thread: it sleeps ``PROBE_PERIOD_S`` again and again and
measures how late it wakes. A sleeping thread needs the interpreter lock (GIL) to return from ``time.sleep``: when
the lock is free it returns at once, when the main thread holds it (Python bytecode, or a C call that keeps it, as
most of numpy's small-array work does) it waits until the holder lets go or the switch interval
(``sys.setswitchinterval``, set to ``SWITCH_INTERVAL_S`` here) asks it to. A wake-up later than ``LATE_S`` is a
sample of "held"; each sample belongs to the stage whose interval holds its due time; a stage's held time is its
late share × its wall. Native work that releases the lock (FFmpeg's decoding, most OpenCV calls) is not held.
The probe is checked in the same run: its late share while the main thread sleeps (nothing holds the lock: the
machine's own scheduling delays, the floor) and while it runs pure Python (everything held: near 1) is printed;
stage shares are not corrected for either. The probe costs the main thread a lock hand-over per sample at most
(a few microseconds each). This needs no external profiler (py-spy) and runs on the loaded machine as it is; on a
machine shared with other work the wall and held times carry its noise, the CPU times much less.

Printed: a table per size and UUV count (ms per frame: wall, main-thread CPU, process CPU, held, held share of
the wall) and the totals, and what each extra UUV adds. Results: ``--out`` and ``.json`` beside it.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections import defaultdict
from contextlib import contextmanager
from pathlib import Path
from typing import Self

import numpy as np
from emit import emit
from uuvs import ensure_session as uuvs_session

from groundstation.height_from_size import shared_sizes
from groundstation.latency.estimate import offset_from_rotations
from groundstation.latency.video_motion import RotationMeter, measured_every
from groundstation.offline.process import Pixels, locate_frames
from groundstation.offline.smoothed import NAME as SMOOTHED_NAME
from groundstation.offline.smoothed import offline_track, write_smoothed_csv
from groundstation.session.positions import write_positions_csv
from groundstation.session.read import load_sessions
from groundstation.video.file import open_video
from localizer.fix_gate import MAX_ACCEL_MPS2, MAX_SPEED_MPS
from localizer.pose import camera_pose
from localizer.tracking.session import TrackingSession

SIZES = {"720p": (1280, 720), "1080p": (1920, 1080)}
UUVS = ("uuv1", "uuv2", "uuv3")
PROBE_PERIOD_S = 0.0005
SWITCH_INTERVAL_S = 0.0005
LATE_S = 0.0002
ROOT = Path(__file__).resolve().parents[1]


class Probe:
    """The interpreter-lock probe (see the module doc): ``samples`` of (due time, late) on the perf_counter clock."""

    def __init__(self):
        self.samples: list[tuple[float, bool]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="gil-probe", daemon=True)

    def _run(self) -> None:
        while not self._stop.is_set():
            t0 = time.perf_counter()
            time.sleep(PROBE_PERIOD_S)
            late = time.perf_counter() - t0 - PROBE_PERIOD_S
            self.samples.append((t0 + PROBE_PERIOD_S, late > LATE_S))

    def __enter__(self) -> Self:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()

    def late_share(self, t0: float, t1: float) -> float:
        """The share of the samples due in [t0, t1) that woke late (NaN: none due)."""
        late = [x for t, x in self.samples if t0 <= t < t1]
        return float(np.mean(late)) if late else float("nan")


def probe_checks(probe: Probe, seconds: float = 0.3) -> dict:
    """The probe's late share with the lock free (main thread asleep) and held (main thread in pure Python)."""
    t0 = time.perf_counter()
    time.sleep(seconds)
    t1 = time.perf_counter()
    x = 0
    while time.perf_counter() - t1 < seconds:
        for i in range(1000):
            x += i
    t2 = time.perf_counter()
    return {"free": probe.late_share(t0, t1), "held": probe.late_share(t1, t2)}


class Stages:
    """Per-stage intervals: ``rec[stage]`` lists (t0, t1, wall, thread CPU, process CPU), one per call."""

    def __init__(self):
        self.rec: dict[str, list[tuple[float, float, float, float, float]]] = defaultdict(list)

    @contextmanager
    def __call__(self, stage: str):
        w0, c0, p0 = time.perf_counter(), time.thread_time(), time.process_time()
        try:
            yield
        finally:
            w1, c1, p1 = time.perf_counter(), time.thread_time(), time.process_time()
            self.rec[stage].append((w0, w1, w1 - w0, c1 - c0, p1 - p0))

    def table(self, probe: Probe, n_frames: int) -> dict:
        """Per stage: ms per frame (total / frames) of wall, thread CPU, process CPU, held; p50 wall per call."""
        out = {}
        for stage, rows in self.rec.items():
            wall = sum(r[2] for r in rows)
            held = 0.0
            for t0, t1, w, *_ in rows:
                share = probe.late_share(t0, t1)
                held += w * (0.0 if np.isnan(share) else share)
            out[stage] = {
                "calls": len(rows),
                "wall_ms": 1000 * wall / n_frames,
                "thread_cpu_ms": 1000 * sum(r[3] for r in rows) / n_frames,
                "process_cpu_ms": 1000 * sum(r[4] for r in rows) / n_frames,
                "held_ms": 1000 * held / n_frames,
                "held_share": held / wall if wall > 0 else float("nan"),
                "p50_call_ms": 1000 * statistics.median(r[2] for r in rows),
            }
        return out


def profile_run(path: Path, ids: tuple[str, ...], work: Path, max_frames: int) -> dict:
    """One pass of ``skyfix process``'s stages over the first ``max_frames`` frames of the session for the UUVs
    ``ids`` (see the module doc)."""
    stages = Stages()
    with Probe() as probe:
        checks = probe_checks(probe)
        with stages("load"):
            sessions = dict(zip(ids, load_sessions(path, list(ids)), strict=True))
        first = sessions[ids[0]]
        cal = first.calibration
        t = first.frames["t"]
        frame_idx = first.frames["frame"].astype(int)
        row_of = {int(f): i for i, f in enumerate(frame_idx)}
        frames = []
        with open_video(
            first.video_path,
            expected_size=(cal.camera.width, cal.camera.height),
            indices=frame_idx,
            grey=True,
        ) as video:
            while len(frames) < max_frames:
                with stages("decode"):
                    frame = video.read()
                if frame is None:
                    break
                frames.append(frame)
            n = len(frames)
            with stages("pose"):
                pose = camera_pose(cal, first.telemetry, t)
            trackers = {uuv: TrackingSession(s.calibration) for uuv, s in sessions.items()}
            # one estimate shared by the UUVs, as ``skyfix process --uuv all`` measures them (one UUV: its own)
            sizes = dict(zip(ids, shared_sizes(list(sessions.values()), "check"), strict=True))
            out = {
                uuv: {k: np.full(len(t), np.nan) for k in ("u", "v", "sigma")}
                | {"status": np.full(len(t), "no_video", dtype=object)}
                for uuv in ids
            }
            meter = RotationMeter(cal.camera)
            every = measured_every(len(t), float(np.median(np.diff(t))))
            rotations = []
            started: set[str] = set()
            for k, frame in enumerate(frames):
                row = row_of[frame.index]
                if k % every == 0:
                    with stages("motion"):
                        if (r := meter.measure(float(t[row]), frame.image)) is not None:
                            rotations.append(r)
                bgr = None
                for uuv in ids:
                    with stages(f"track {uuv}"):
                        tr = trackers[uuv]
                        if uuv in started:
                            result = tr.step(frame.image, pose, row)
                        else:
                            box = sessions[uuv].calibration.init_bbox
                            result = tr.select(frame.image, pose, row, box=box)
                            started.add(uuv)
                    o = out[uuv]
                    o["status"][row], o["u"][row], o["v"][row] = (
                        result.status,
                        result.u,
                        result.v,
                    )
                    o["sigma"][row] = result.sigma_px
                    size = sizes[uuv]
                    if result.ok and size.due(float(t[row])):
                        if bgr is None:
                            with stages("colour"):
                                bgr = frame.bgr_regions()
                        with stages(f"size {uuv}"):
                            size.take(size.measure(bgr, pose, row, result.u, result.v))
        with stages("offset"):
            offset_from_rotations(cal, first.telemetry, rotations)
        for uuv in ids:
            o = out[uuv]
            bad = o["status"] != "ok"
            o["u"][bad] = o["v"][bad] = o["sigma"][bad] = np.nan
            with stages(f"geometry {uuv}"):
                fixes = locate_frames(
                    sessions[uuv], Pixels(t, o["u"], o["v"], o["status"], o["sigma"])
                )
            with stages(f"output {uuv}"):
                write_positions_csv(work / f"positions_{uuv}.csv", fixes)
                smoothed, status = offline_track(
                    fixes, MAX_SPEED_MPS["bluerov2"], MAX_ACCEL_MPS2["bluerov2"]
                )
                write_smoothed_csv(work / f"{uuv}_{SMOOTHED_NAME}", fixes, smoothed, status)
        ok = {uuv: int(np.sum(out[uuv]["status"] == "ok")) for uuv in ids}
    return {"frames": n, "ok": ok, "probe": checks, "stages": stages.table(probe, n)}


def startup() -> dict:
    """``skyfix process --help`` in a child: wall and CPU seconds, median of 3."""
    import resource

    walls, cpus = [], []
    for _ in range(3):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        subprocess.run(
            [sys.executable, "-m", "groundstation.cli", "process", "--help"],
            check=True,
            capture_output=True,
            cwd=ROOT,
        )
        walls.append(time.perf_counter() - t0)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpus.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return {"wall_s": statistics.median(walls), "cpu_s": statistics.median(cpus)}


def table(size: str, count: int, res: dict) -> list[str]:
    st = res["stages"]
    lines = [
        f"{size}, {count} UUV{'s' if count > 1 else ''}: {res['frames']} frames, ok frames "
        + ", ".join(f"{k} {v}" for k, v in res["ok"].items())
        + f"; probe late share: lock free {res['probe']['free']:.2f}, held {res['probe']['held']:.2f}",
        (
            f"  {'stage':14s} {'calls':>5s} {'wall':>7s} {'thrCPU':>7s} {'procCPU':>7s} {'held':>7s} {'held%':>6s}"
            f" {'p50/call':>8s}   (ms per frame)"
        ),
    ]
    for stage, s in st.items():
        lines.append(
            f"  {stage:14s} {s['calls']:5d} {s['wall_ms']:7.2f} {s['thread_cpu_ms']:7.2f} "
            f"{s['process_cpu_ms']:7.2f} {s['held_ms']:7.2f} {100 * s['held_share']:5.0f}% {s['p50_call_ms']:8.2f}"
        )
    tot = {k: sum(s[k] for s in st.values()) for k in ("wall_ms", "process_cpu_ms", "held_ms")}
    lines.append(
        f"  {'total':14s} {'':5s} {tot['wall_ms']:7.2f} {'':7s} {tot['process_cpu_ms']:7.2f} {tot['held_ms']:7.2f} "
        f"{100 * tot['held_ms'] / tot['wall_ms']:5.0f}%   -> {1000 / tot['wall_ms']:.0f} fps one after another"
    )
    res["total"] = tot
    return lines


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sizes", default="720p,1080p")
    p.add_argument("--counts", default="1,2,3")
    p.add_argument("--duration-s", type=float, default=20.0)
    p.add_argument(
        "--frames", type=int, default=150, help="the first this many frames (default %(default)s)"
    )
    p.add_argument("--out", type=Path)
    args = p.parse_args(argv)
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    data = {"startup": startup(), "runs": {}}
    lines = [
        (
            f"start-up (skyfix process --help, child): wall {data['startup']['wall_s']:.2f} s, "
            f"CPU {data['startup']['cpu_s']:.2f} s"
        )
    ]
    with tempfile.TemporaryDirectory() as work:
        for size in args.sizes.split(","):
            path = uuvs_session(args.duration_s, SIZES[size])
            for count in (int(c) for c in args.counts.split(",")):
                res = profile_run(path, UUVS[:count], Path(work), args.frames)
                data["runs"][f"{size}_{count}"] = res
                lines += table(size, count, res)
                print("\n".join(lines[-len(res["stages"]) - 3 :]), flush=True)
    emit(lines, args.out, data)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Where the whole ``skyfix process`` command's wall time and CPU go, phase by phase and thread by thread (issue 30).

    .venv/bin/python bench/profile_process.py [--uuv all] [--duration-s 20] [--size 1080p] [--bucket-s 0.5]
                                              [--session DIR] [--out bench/results/profile_process.txt]

``bench/profile_stages.py`` times each stage alone (every frame decoded first); this runs the command itself, as a
user does (``groundstation.cli.main(["process", SESSION, "--quiet", "--uuv", ...])`` in this process, its imports
included), on ``bench/uuvs.py``'s three-UUV session (or ``--session``), and watches it three ways:

- **phase**: what the main thread is doing: the functions of :data:`PHASES` are wrapped to note, on the main thread,
  when each starts and ends (the innermost running names the phase: reading the session, within the pass over the
  video waiting for a decoded frame, tracking, the motion meter's hand-over, the heights from size, tracing back; the
  offset from the motion; each UUV's geometry, smoothing and files);
- **CPU per thread**: a child process (:func:`watch`: no interpreter lock to wait for) reads every thread's user +
  system ticks from ``/proc/PID/task/*/stat`` every ``--interval-ms``; threads are grouped as the main thread, the
  Python threads by name (``video-decode``: PyAV's reading loop, ``video-early``, ``video-motion``) and ``native``:
  threads no Python thread owns (FFmpeg's frame and slice threads, OpenCV's and BLAS's pools); each interval's CPU
  is the phase's the main thread was in at its middle;
- **interpreter lock**: a probe thread sleeps :data:`PROBE_S` again and again; the time it wakes late (it needs the
  lock to return from ``time.sleep``) is the lock held by others, or the machine's scheduler keeping it off a core
  under load (its floor: measured first with the main thread asleep, printed).

It also counts how the video is read: the files opened for decoding (:class:`~groundstation.video.file.Video`), the
demux-only passes (the frames' timestamps) and the frames decoded.

Printed: per phase its wall, the cores busy in each thread group and the probe's late share; then a timeline
(``--bucket-s`` a line: the cores each group kept busy, the main thread's phases), which shows whether decoding
overlaps tracking. Results: ``--out`` and ``.json`` beside it. The walls carry the machine's load (printed).
"""

from __future__ import annotations

import argparse
import importlib
import itertools
import os
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np

#: (module, attribute, phase): wrapped to note the main thread's phase while it runs (the innermost counts)
PHASES = (
    ("groundstation.offline.process", "load_sessions", "read session"),
    ("groundstation.offline.process", "load_session", "read session"),
    ("groundstation.offline.process", "shared_sizes", "height from size: setup"),
    ("groundstation.offline.process", "tracked_pixels", "pass: other"),
    ("groundstation.offline.track", "uav_pose", "pass: poses"),
    ("groundstation.video.file", "_queued", "pass: wait for a decoded frame"),
    ("groundstation.offline.track", "UuvTrack.step", "pass: track"),
    ("groundstation.offline.track", "_trace_back", "pass: trace back"),
    ("groundstation.offline.track", "MotionThread.feed", "pass: motion hand-over"),
    ("groundstation.offline.track", "MotionThread.finish", "pass: motion finish"),
    ("groundstation.height_from_size", "HeightFromSize.measure", "pass: height from size"),
    ("groundstation.offline.process", "offset_from_rotations", "offset from motion"),
    ("groundstation.offline.process", "located", "geometry"),
    ("groundstation.offline.process", "write_positions_csv", "write positions.csv"),
    ("groundstation.offline.process", "offline_track", "smooth"),
    ("groundstation.offline.process", "traced_back", "smooth"),
    ("groundstation.offline.process", "write_smoothed_csv", "write smoothed"),
)
GROUPS = ("main", "video-decode", "video-early", "native", "video-motion", "other python")
PROBE_S = 0.001
LATE_S = 0.001


def watch(pid: int, interval_s: float) -> None:
    """The child: every ``interval_s`` a line ``t tid:ticks ...`` (t: the monotonic clock, as ``perf_counter``)
    until stdin closes."""
    stop = threading.Event()
    threading.Thread(target=lambda: (sys.stdin.read(), stop.set()), daemon=True).start()
    out = []
    while not stop.is_set():
        t = time.perf_counter()
        cells = []
        for tid in os.listdir(f"/proc/{pid}/task"):
            try:
                with open(f"/proc/{pid}/task/{tid}/stat") as f:
                    fields = f.read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            cells.append(f"{tid}:{int(fields[11]) + int(fields[12])}")
        out.append(f"{t} {' '.join(cells)}")
        time.sleep(interval_s)
    sys.stdout.write("\n".join(out) + "\n")


class Phases:
    """The main thread's phase transitions: ``marks`` of (t, phase) (``None``: outside every wrapped function)."""

    def __init__(self):
        self.stack: list[str] = []
        self.marks: list[tuple[float, str]] = [(time.perf_counter(), "imports, arguments, other")]

    def wrap(self, module: str, attr: str, phase: str) -> None:
        mod = importlib.import_module(module)
        owner, name = (
            (getattr(mod, attr.split(".")[0]), attr.split(".")[1]) if "." in attr else (mod, attr)
        )
        inner = getattr(owner, name)
        main = threading.main_thread().ident

        def wrapped(*a, **k):
            if threading.get_ident() != main:
                return inner(*a, **k)
            self.stack.append(phase)
            self.marks.append((time.perf_counter(), phase))
            try:
                return inner(*a, **k)
            finally:
                self.stack.pop()
                self.marks.append(
                    (
                        time.perf_counter(),
                        self.stack[-1] if self.stack else "imports, arguments, other",
                    )
                )

        setattr(owner, name, wrapped)

    def at(self, t: float) -> str:
        import bisect

        i = bisect.bisect_right(self.times, t) - 1
        return self.marks[max(i, 0)][1]

    def done(self) -> None:
        self.times = [m[0] for m in self.marks]


class Probe:
    """The interpreter-lock probe: ``late`` of (t woke, seconds late)."""

    def __init__(self):
        self.late: list[tuple[float, float]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="profile-probe", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            t0 = time.perf_counter()
            time.sleep(PROBE_S)
            t = time.perf_counter()
            self.late.append((t, t - t0 - PROBE_S))

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()


def count_reads(counts: Counter) -> None:
    """Count the video files opened for decoding, the demux-only passes and the frames decoded."""
    from groundstation.video import file

    opened, times, decoded = file._opened, file._presentation_times, file.Video._next_decoded

    def _opened(*a, **k):
        counts["files opened for decoding"] += 1
        return opened(*a, **k)

    def _times(*a, **k):
        counts["demux-only passes"] += 1
        return times(*a, **k)

    def _decoded(self):
        item = decoded(self)
        counts["frames decoded"] += item is not None
        return item

    file._opened, file._presentation_times, file.Video._next_decoded = _opened, _times, _decoded


def profile(session: Path, uuv: str, interval_s: float, bucket_s: float) -> tuple[list[str], dict]:
    """One run of the command, watched (see the module doc): the printed lines and the numbers."""
    named: dict[int, str] = {threading.get_native_id(): "main"}
    bootstrap = threading.Thread._bootstrap_inner

    def noted(self):
        named[threading.get_native_id()] = self.name
        return bootstrap(self)

    threading.Thread._bootstrap_inner = noted
    child = subprocess.Popen(
        [
            sys.executable,
            __file__,
            "--watch",
            str(os.getpid()),
            "--interval-ms",
            str(interval_s * 1000),
        ],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    probe = Probe()
    load_before = os.getloadavg()[0]
    time.sleep(0.5)
    floor = [late for t, late in probe.late]
    floor_share = sum(x > LATE_S for x in floor) / max(len(floor), 1)
    t_start = time.perf_counter()
    phases = Phases()
    from groundstation import cli

    for module, attr, phase in PHASES:
        phases.wrap(module, attr, phase)
    counts: Counter = Counter()
    count_reads(counts)
    cpu0 = time.process_time()
    with tempfile.TemporaryDirectory() as out:
        code = cli.main(["process", str(session), "--quiet", "--uuv", uuv, "--out", out])
    t_end = time.perf_counter()
    wall, cpu = t_end - t_start, time.process_time() - cpu0
    probe.stop()
    phases.done()
    text, _ = child.communicate("")
    gaps = np.diff([float(line.split()[0]) for line in text.splitlines()])
    tick_s = 1.0 / os.sysconf("SC_CLK_TCK")
    samples = []
    for line in text.splitlines():
        t, *cells = line.split()
        samples.append((float(t), {int(c.split(":")[0]): int(c.split(":")[1]) for c in cells}))
    by_phase: dict[str, dict] = {}
    timeline: dict[int, dict] = defaultdict(lambda: defaultdict(float))
    me = [tid for tid, name in named.items() if name == "profile-probe"]
    for (ta, a), (tb, b) in itertools.pairwise(samples):
        lo, hi = max(ta, t_start), min(tb, t_end)
        if hi <= lo:
            continue
        phase = phases.at((ta + tb) / 2)
        p = by_phase.setdefault(phase, {"wall_s": 0.0, "late_s": 0.0} | {g: 0.0 for g in GROUPS})
        p["wall_s"] += hi - lo
        line = timeline[int((tb - t_start) / bucket_s)]
        line["wall"] += tb - ta
        line[phase] += tb - ta
        for tid, ticks in b.items():
            if tid in me:
                continue
            name = named.get(tid)
            group = "native" if name is None else name if name in GROUPS else "other python"
            used = (ticks - a.get(tid, 0)) * tick_s
            p[group] += used
            line["cpu " + group] += used
    for t, late in probe.late:
        if t_start <= t <= t_end and late > LATE_S:
            by_phase.setdefault(
                phases.at(t), {"wall_s": 0.0, "late_s": 0.0} | {g: 0.0 for g in GROUPS}
            )["late_s"] += late
    lines = [
        f"skyfix process {session.name} --uuv {uuv}: exit {code}, wall {wall:.2f} s (interpreter start not counted), "
        f"CPU {cpu:.2f} s ({cpu / wall:.2f} cores busy on average), load average (1 min) {load_before:.1f} before, "
        f"{os.getloadavg()[0]:.1f} after; "
        + ", ".join(f"{k} {v}" for k, v in counts.items())
        + f"; watcher: {len(gaps) + 1} samples, largest gap {gaps.max() * 1000:.0f} ms"
        + f"; probe late with the main thread asleep: {floor_share:.2f} of its wake-ups",
        f"  {'phase (main thread)':32s} {'wall s':>6s}  cores busy: "
        + " ".join(f"{g[:12]:>12s}" for g in GROUPS)
        + "   CPU s  main CPU s  lock/CPU wait",
    ]
    first_seen = {}
    for t, ph in phases.marks:
        first_seen.setdefault(ph, t)
    for phase in sorted(by_phase, key=lambda k: first_seen.get(k, 0)):
        p = by_phase[phase]
        w = p["wall_s"]
        if w < 0.005:
            continue
        lines.append(
            f"  {phase:32s} {w:6.2f}  {'':11s} "
            + " ".join(f"{p[g] / w:12.2f}" for g in GROUPS)
            + f"  {sum(p[g] for g in GROUPS):6.2f}  {p['main']:10.2f}  {p['late_s'] / w:8.0%}"
        )
    total = {g: sum(p[g] for p in by_phase.values()) for g in GROUPS}
    lines.append(
        f"  {'CPU seconds per group':32s} {wall:6.2f}  {'':11s} "
        + " ".join(f"{total[g]:12.2f}" for g in GROUPS)
    )
    lines.append(
        f"  timeline, {bucket_s:g} s a line: cores busy per group | the main thread's phases (share of the line)"
    )
    for b in sorted(timeline):
        line = timeline[b]
        w = line["wall"]
        busy = " ".join(
            f"{g[:6]} {line['cpu ' + g] / w:4.2f}" for g in GROUPS if line["cpu " + g] > 0.02 * w
        )
        top = sorted(
            ((v, k) for k, v in line.items() if k not in ("wall",) and not k.startswith("cpu ")),
            reverse=True,
        )
        lines.append(
            f"  {b * bucket_s:5.1f} s  {busy:62s} | "
            + ", ".join(f"{k} {v / w:.0%}" for v, k in top[:2])
        )
    data = {"uuv": uuv, "wall_s": wall, "cpu_s": cpu, "counts": dict(counts), "phases": by_phase}
    return lines, data


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--uuv", default="all", help="the command's --uuv (all, uuv1, ...)")
    p.add_argument("--duration-s", type=float, default=20.0)
    p.add_argument("--size", default="1080p", choices=("1080p", "4k"))
    p.add_argument(
        "--session", type=Path, help="this session instead (e.g. bench/offline_speed.py's)"
    )
    p.add_argument("--interval-ms", type=float, default=10.0)
    p.add_argument("--bucket-s", type=float, default=0.5)
    p.add_argument("--watch", type=int, help=argparse.SUPPRESS)
    p.add_argument("--out", type=Path)
    args = p.parse_args(argv)
    if args.watch:
        watch(args.watch, args.interval_ms / 1000)
        return 0
    from emit import emit
    from uuvs import ensure_session as uuvs_session

    size = {"1080p": (1920, 1080), "4k": (3840, 2160)}[args.size]
    session = args.session or uuvs_session(args.duration_s, size)
    lines, data = profile(session, args.uuv, args.interval_ms / 1000, args.bucket_s)
    emit(lines, args.out, data)
    return 0


if __name__ == "__main__":
    sys.exit(main())

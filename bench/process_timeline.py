"""The whole ``skyfix process`` command watched from outside: which phase runs when, and how many cores it keeps
busy in each (issue 30: the command's wall against decoding alone is idle cores, serial phases, not CPU).

    .venv/bin/python bench/process_timeline.py [--uuvs uuv1,all] [--repeats 3] [--tree LABEL=DIR ...]
                                               [--interval-ms 20] [--bucket-s 0.1]
                                               [--out bench/results/process_timeline.txt]

The command runs as a user runs it, a child process (``python -m groundstation.cli process SESSION --quiet --uuv
...`` on ``bench/uuvs.py``'s three-UUV 1080p session, 20 s), from this tree or each ``--tree``, interleaved over
``--repeats`` rounds. Its child here (:func:`child`) is the command itself with notes taken on the way: the moment its
first line of Python runs (what came before is the interpreter's start), and on the main thread the phase it is in:
importing a module (``imports``, the outermost import only) or within one of the functions of :data:`PHASES` (the
innermost names the phase), wrapped as their modules are imported, so nothing is imported earlier than the command
imports it. Events on any thread are noted too (:data:`EVENTS`): decoding early started, the first and the last frame
decoded. This process meanwhile reads, every ``--interval-ms``, every thread's ``/proc/PID/task/TID/schedstat`` of the
command and of any process it forks: the nanoseconds each ran on a core and waited for one (runnable, the machine's
other work on the cores).

Per interval: **busy** is the cores the command ran on, **wanted** the cores it ran on or waited for (busy + run
queue). On a machine shared with others busy drops when they take the cores; wanted does not: wanted below the
machine's cores is the command's own idleness. Not quite: a thread waiting for the interpreter's lock sleeps (it is
not wanting a core), so where the thread holding the lock waits for a core, the others waiting for the lock look
idle too: under a heavy load serial seconds grow beyond the command's own. Printed per phase of the main thread (medians of the runs): its wall,
the CPU of the command's threads in it, the cores busy and wanted on average, and its **serial** time, the intervals
with fewer than :data:`SERIAL_CORES` cores wanted (and, beside it, busy). Then one run's timeline (the run of median
wall), ``--bucket-s`` a line: busy, wanted, the decoding threads' share (FFmpeg's threads and ``video-decode``), the
main thread's, and the main thread's phases; and when decoding ran (early start, first and last frame decoded).
Results: ``--out`` and ``.json`` beside it, with the machine's load average.
"""

from __future__ import annotations

import time

T_FIRST = (
    time.perf_counter()
)  # the child's first line of Python: the interpreter's start is before it

import argparse
import bisect
import itertools
import json
import os
import statistics
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: (module, attribute, phase): wrapped, once the module is imported, to note the main thread's phase while it runs
#: (the innermost counts); a module or attribute a tree lacks is left out.
PHASES = (
    ("groundstation.offline.process", "_run", "run: other"),
    ("groundstation.offline.process", "load_sessions", "read session"),
    ("groundstation.offline.process", "load_session", "read session"),
    ("groundstation.offline.process", "shared_sizes", "height from size: setup"),
    ("groundstation.offline.process", "size_of", "height from size: setup"),
    ("groundstation.offline.process", "tracked_pixels", "pass: other"),
    ("groundstation.offline.track", "uav_pose", "pass: poses"),
    ("groundstation.offline.track", "UuvTrack.__init__", "pass: tracker setup"),
    ("groundstation.video.file", "open_video", "pass: open video"),
    ("groundstation.video.file", "_queued", "pass: wait for a frame"),
    ("groundstation.offline.track", "UuvTrack.step", "pass: track"),
    ("groundstation.offline.track", "_trace_back", "pass: trace back"),
    ("groundstation.offline.track", "MotionThread.feed", "pass: motion hand-over"),
    ("groundstation.offline.track", "MotionThread.finish", "motion: finish"),
    ("groundstation.height_from_size", "HeightFromSize.measure", "pass: height from size"),
    ("groundstation.offline.process", "offset_from_rotations", "offset from motion"),
    ("groundstation.offline.process", "print_warnings", "warnings"),
    ("groundstation.offline.process", "bottom_correction", "pose from bottom"),
    ("groundstation.offline.process", "located", "geometry"),
    ("groundstation.offline.process", "write_positions_csv", "write positions.csv"),
    ("groundstation.offline.process", "offline_track", "smooth"),
    ("groundstation.offline.process", "traced_back", "smooth"),
    ("groundstation.offline.process", "write_smoothed_csv", "write smoothed"),
    ("groundstation.height_from_size", "HeightFromSize.summary", "height from size: estimate"),
)
#: (module, attribute, event, when): noted on any thread with the command's CPU seconds and the frames decoded so far
#: (``first``: the first call only; ``none``: a call returning None; ``count``: no event, the frames decoded counted)
EVENTS = (
    ("groundstation.video.file", "Video._next_decoded", "", "count"),
    ("groundstation.video.file", "_Early.__init__", "decoding early started", "call"),
    ("groundstation.video.file", "Video._next_decoded", "first frame decoded", "first"),
    ("groundstation.offline.track", "UuvTrack.step", "tracking started", "first"),
    ("groundstation.video.file", "Video._next_decoded", "last frame decoded", "none"),
)
#: (module, attribute, what): the time any thread spends in it noted, span by span
WAITS = (("groundstation.video.file", "put_until", "decoder blocked, its queue full"),)
#: An interval with fewer cores wanted than this is serial (the machine's 2 cores: one idle at least half the time).
SERIAL_CORES = 1.5
#: The main thread outside every wrapped function and import.
OTHER = "other"


# --- the child: the command itself, with notes -------------------------------------------------------------------


class Notes:
    """The child's notes: the main thread's phase ``marks`` (t, phase), ``events`` (t, name), the threads' names."""

    def __init__(self) -> None:
        self.stack: list[str] = []
        self.marks: list[tuple[float, str]] = [(T_FIRST, OTHER)]
        self.events: list[tuple[float, str]] = []
        self.threads: dict[int, str] = {threading.get_native_id(): "main"}
        self.main = threading.get_ident()
        self.seen: set[str] = set()
        self.decoded = 0  # frames decoded so far
        self.waits: dict[str, list[tuple[float, float]]] = {}

    def enter(self, phase: str) -> None:
        self.stack.append(phase)
        self.marks.append((time.perf_counter(), phase))

    def leave(self) -> None:
        self.stack.pop()
        self.marks.append((time.perf_counter(), self.stack[-1] if self.stack else OTHER))

    def phase(self, phase: str, inner):
        def wrapped(*a, **k):
            if threading.get_ident() != self.main:
                return inner(*a, **k)
            self.enter(phase)
            try:
                return inner(*a, **k)
            finally:
                self.leave()

        return wrapped

    def event(self, name: str, when: str, inner):
        def wrapped(*a, **k):
            out = inner(*a, **k)
            if when == "count":
                self.decoded += out is not None
            elif (
                when == "call"
                or (when == "first" and name not in self.seen)
                or (when == "none" and out is None)
            ):
                self.events.append((time.perf_counter(), name, time.process_time(), self.decoded))
            self.seen.add(name)
            return out

        return wrapped

    def wait(self, what: str, inner):
        spans = self.waits.setdefault(what, [])

        def wrapped(*a, **k):
            t0 = time.perf_counter()
            try:
                return inner(*a, **k)
            finally:
                spans.append((t0, time.perf_counter()))

        return wrapped

    def imported(self, module) -> None:
        """Wrap ``module``'s functions of :data:`PHASES` and :data:`EVENTS`, once it is imported."""
        for mod, attr, name, *when in EVENTS + PHASES + WAITS:
            if mod != module.__name__:
                continue
            owner, _, leaf = attr.rpartition(".")
            owner = getattr(module, owner, None) if owner else module
            inner = getattr(owner, leaf, None) if owner is not None else None
            if inner is None:
                continue
            if (mod, attr, name) in WAITS:
                wrapped = self.wait(name, inner)
            elif when:
                wrapped = self.event(name, when[0], inner)
            else:
                wrapped = self.phase(name, inner)
            setattr(owner, leaf, wrapped)


class ImportNotes:
    """A ``sys.meta_path`` finder: every module's loading on the main thread is the phase ``imports`` (the outermost
    only), and :meth:`Notes.imported` wraps its functions once loaded."""

    def __init__(self, notes: Notes) -> None:
        self.notes = notes
        self.depth = 0

    def find_spec(self, name, path, target=None):
        for finder in sys.meta_path:
            if finder is self:
                continue
            spec = finder.find_spec(name, path, target) if hasattr(finder, "find_spec") else None
            if spec is not None:
                break
        else:
            return None
        if (
            spec.loader is None
            or isinstance(spec.loader, type)
            or not hasattr(spec.loader, "exec_module")
        ):
            return spec  # a built-in or frozen module: its loader is a class shared by all
        exec_module, notes, me = spec.loader.exec_module, self.notes, self

        def noted(module):
            on_main = threading.get_ident() == notes.main
            if on_main and me.depth == 0:
                notes.enter("imports")
            me.depth += on_main
            try:
                exec_module(module)
            finally:
                me.depth -= on_main
                if on_main and me.depth == 0:
                    notes.leave()
            notes.imported(module)

        spec.loader.exec_module = noted
        return spec


def child(notes_path: str, argv: list[str]) -> int:
    """Run ``skyfix`` with ``argv`` here, noting its phases; the notes written to ``notes_path`` at the end."""
    notes = Notes()
    bootstrap = threading.Thread._bootstrap_inner

    def named(thread):
        notes.threads[threading.get_native_id()] = thread.name
        return bootstrap(thread)

    threading.Thread._bootstrap_inner = named
    sys.meta_path.insert(0, ImportNotes(notes))
    notes.enter("imports")
    from groundstation import cli

    notes.leave()
    sys.argv = ["skyfix", *argv]
    code = cli.main()  # as the program runs it (its exit included)
    notes.marks.append((time.perf_counter(), "exit"))
    Path(notes_path).write_text(
        json.dumps(
            {
                "t_first": T_FIRST,
                "marks": notes.marks,
                "events": notes.events,
                "threads": notes.threads,
                "waits": notes.waits,
            }
        )
    )
    return code


# --- this process: the command run and watched --------------------------------------------------------------------


def descendants(root: int) -> list[int]:
    """``root`` and the processes it forked (and theirs): their parents read from ``/proc/PID/stat``."""
    parent = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit() and int(entry) > root:
            try:
                with open(f"/proc/{entry}/stat") as f:
                    parent[int(entry)] = int(f.read().rsplit(")", 1)[1].split()[1])
            except OSError:
                continue
    found = [root]
    for pid in sorted(parent):
        if parent[pid] in found:
            found.append(pid)
    return found


def sample(root: int) -> dict[tuple[int, int], tuple[int, int]]:
    """Every thread of ``root`` and its descendants: (pid, tid) -> (ns run on a core, ns waited for one)."""
    cells = {}
    for pid in descendants(root):
        try:
            tids = os.listdir(f"/proc/{pid}/task")
        except OSError:
            continue
        for tid in tids:
            try:
                with open(f"/proc/{pid}/task/{tid}/schedstat") as f:
                    run_ns, wait_ns, _ = f.read().split()
            except (OSError, ValueError):
                continue
            cells[pid, int(tid)] = (int(run_ns), int(wait_ns))
    return cells


def run_watched(cmd: list[str], tree: Path, interval_s: float) -> dict:
    """One run of ``skyfix`` ``cmd`` (its arguments) from ``tree``, watched: wall, the samples, the child's notes."""
    with tempfile.TemporaryDirectory() as tmp:
        notes = Path(tmp) / "notes.json"
        t_spawn = time.perf_counter()
        proc = subprocess.Popen(
            [sys.executable, __file__, "--child", str(notes), "--", *cmd],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            cwd=tree,
            env=dict(os.environ, PYTHONPATH=str(tree)),
        )
        samples = []
        status = None
        while status is None:
            samples.append((time.perf_counter(), sample(proc.pid)))
            pid, code, usage = os.wait4(proc.pid, os.WNOHANG)
            if pid:
                status = code
                break
            time.sleep(interval_s)
        t_end = time.perf_counter()
        err = proc.stderr.read().decode(errors="replace")
        proc.stderr.close()
        if os.waitstatus_to_exitcode(status):
            raise SystemExit(
                f"{' '.join(cmd)}: exit {os.waitstatus_to_exitcode(status)}\n{err[-2000:]}"
            )
        found = json.loads(notes.read_text())
    return {
        "t_spawn": t_spawn,
        "t_end": t_end,
        "wall_s": t_end - t_spawn,
        "cpu_s": usage.ru_utime + usage.ru_stime,
        "samples": samples,
        "notes": found,
    }


def phase_at(marks: list, t: float, t_first: float, t_last: float) -> str:
    if t < t_first:
        return "interpreter start"
    if t >= t_last:
        return "exit"
    return marks[max(bisect.bisect_right([tm for tm, _ in marks], t) - 1, 0)][1]


def intervals(run: dict) -> list[dict]:
    """The run's sampling intervals: start, length, cores busy and wanted, the decoding threads' and the main
    thread's cores, the main thread's phase at the middle."""
    notes = run["notes"]
    marks = notes["marks"]
    names = {int(tid): name for tid, name in notes["threads"].items()}
    t_last = marks[-1][0]
    out = []
    root = None
    for (ta, a), (tb, b) in itertools.pairwise(run["samples"]):
        dt = tb - ta
        if not b or dt <= 0:
            continue
        root = root or min(pid for pid, _ in b)
        run_s = wait_s = decode_s = main_s = 0.0
        for key, (r, w) in b.items():
            r0, w0 = a.get(key, (0, 0))
            dr, dw = (r - r0) / 1e9, (w - w0) / 1e9
            run_s, wait_s = run_s + dr, wait_s + dw
            pid, tid = key
            name = names.get(tid) if pid == root else "forked"
            if name == "main":
                main_s += dr
            elif name is None or name == "video-decode":
                decode_s += (
                    dr  # FFmpeg's threads (no Python thread owns them) and PyAV's reading loop
                )
        out.append(
            {
                "t": ta - run["t_spawn"],
                "dt": dt,
                "busy": run_s / dt,
                "wanted": (run_s + wait_s) / dt,
                "decode": decode_s / dt,
                "main": main_s / dt,
                "cpu_s": run_s,
                "phase": phase_at(marks, (ta + tb) / 2, notes["t_first"], t_last),
            }
        )
    return out


def per_phase(ivs: list[dict]) -> dict[str, dict]:
    """Per main-thread phase: wall, CPU, serial seconds (wanted, busy below :data:`SERIAL_CORES`)."""
    phases: dict[str, dict] = {}
    for iv in ivs:
        p = phases.setdefault(
            iv["phase"],
            {"wall_s": 0.0, "cpu_s": 0.0, "serial_s": 0.0, "serial_busy_s": 0.0, "wanted_s": 0.0},
        )
        p["wall_s"] += iv["dt"]
        p["cpu_s"] += iv["cpu_s"]
        p["wanted_s"] += iv["wanted"] * iv["dt"]
        p["serial_s"] += iv["dt"] * (iv["wanted"] < SERIAL_CORES)
        p["serial_busy_s"] += iv["dt"] * (iv["busy"] < SERIAL_CORES)
    return phases


def events_of(run: dict) -> dict[str, tuple[float, float, int]]:
    """When each event first happened (the last frame: the last time): s from the spawn, the command's CPU
    seconds until then (its threads', all of them: the machine's load does not change it) and the frames decoded."""
    found: dict[str, tuple[float, float, int]] = {}
    for t, name, cpu_s, decoded in run["notes"]["events"]:
        if name == "last frame decoded" or name not in found:
            found[name] = (t - run["t_spawn"], cpu_s, decoded)
    return found


def waits_of(run: dict) -> dict[str, tuple[float, float]]:
    """Per :data:`WAITS` entry: the seconds spent in it, and of those before the tracking started."""
    start = next((t for t, name, *_ in run["notes"]["events"] if name == "tracking started"), 0.0)
    return {
        what: (sum(b - a for a, b in spans), sum(min(b, start) - a for a, b in spans if a < start))
        for what, spans in run["notes"]["waits"].items()
    }


def table(label: str, runs: list[dict]) -> list[str]:
    """A variant's per-phase medians over its runs, in the order the phases first came."""
    per = [per_phase(intervals(r)) for r in runs]
    order: list[str] = []
    for r in runs:
        for iv in intervals(r):
            if iv["phase"] not in order:
                order.append(iv["phase"])
    med = lambda xs: statistics.median(xs) if xs else 0.0
    walls = [r["wall_s"] for r in runs]
    cpus = [r["cpu_s"] for r in runs]
    serial = [sum(p["serial_s"] for p in ph.values()) for ph in per]
    serial_busy = [sum(p["serial_busy_s"] for p in ph.values()) for ph in per]
    ev = [events_of(r) for r in runs]
    waits = [waits_of(r) for r in runs]
    lines = [
        f"{label}: wall {med(walls):.2f} s [{min(walls):.2f}-{max(walls):.2f}], CPU {med(cpus):.2f} s, "
        f"serial (< {SERIAL_CORES:g} cores wanted) {med(serial):.2f} s, (< {SERIAL_CORES:g} busy) {med(serial_busy):.2f} s; "
        + ", ".join(
            f"{name} at {med([e[name][0] for e in ev if name in e]):.2f} s "
            f"({med([e[name][1] for e in ev if name in e]):.2f} CPU-s, "
            f"{med([e[name][2] for e in ev if name in e]):.0f} frames decoded)"
            for name in dict.fromkeys(n for e in ev for n in e)
        ),
        "  "
        + "; ".join(
            f"{what} {med([w[what][0] for w in waits if what in w]):.2f} s, "
            f"{med([w[what][1] for w in waits if what in w]):.2f} s of it before the tracking started"
            for what in dict.fromkeys(x for w in waits for x in w)
        ),
        (
            f"  {'phase (main thread)':28s} {'wall s':>6s} {'CPU s':>6s} {'busy':>5s} {'wanted':>6s} "
            f"{'serial s':>8s} {'(busy)':>6s}   medians of {len(runs)} runs"
        ),
    ]
    for phase in order:
        cells = [p[phase] for p in per if phase in p]
        wall = med([c["wall_s"] for c in cells])
        if wall < 0.005:
            continue
        lines.append(
            f"  {phase:28s} {wall:6.2f} {med([c['cpu_s'] for c in cells]):6.2f} "
            f"{med([c['cpu_s'] / c['wall_s'] for c in cells]):5.2f} "
            f"{med([c['wanted_s'] / c['wall_s'] for c in cells]):6.2f} "
            f"{med([c['serial_s'] for c in cells]):8.2f} {med([c['serial_busy_s'] for c in cells]):6.2f}"
        )
    return lines


def timeline(run: dict, bucket_s: float) -> list[str]:
    """One run's timeline, ``bucket_s`` a line."""
    buckets: dict[int, dict] = {}
    for iv in intervals(run):
        b = buckets.setdefault(int(iv["t"] / bucket_s), {"dt": 0.0, "phases": {}})
        for key in ("busy", "wanted", "decode", "main"):
            b[key] = b.get(key, 0.0) + iv[key] * iv["dt"]
        b["dt"] += iv["dt"]
        b["phases"][iv["phase"]] = b["phases"].get(iv["phase"], 0.0) + iv["dt"]
    events = sorted((t, name) for name, (t, *_) in events_of(run).items())
    lines = [
        (
            f"  timeline of the run of median wall ({run['wall_s']:.2f} s), {bucket_s:g} s a line: cores busy, wanted, "
            "decoding's, the main thread's | its phases"
        )
    ]
    for k in sorted(buckets):
        b = buckets[k]
        dt = b["dt"]
        here = [name for t, name in events if k * bucket_s <= t < (k + 1) * bucket_s]
        top = sorted(b["phases"].items(), key=lambda kv: -kv[1])[:2]
        lines.append(
            f"  {k * bucket_s:5.1f} s  busy {b['busy'] / dt:4.2f} wanted {b['wanted'] / dt:4.2f} "
            f"decode {b['decode'] / dt:4.2f} main {b['main'] / dt:4.2f} | "
            + ", ".join(f"{name} {v / dt:.0%}" for name, v in top)
            + (f"  <- {', '.join(here)}" if here else "")
        )
    return lines


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--uuvs", default="uuv1,all", help="the command's --uuv values, comma-separated")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--tree", action="append", default=[], metavar="LABEL=DIR")
    p.add_argument("--interval-ms", type=float, default=20.0)
    p.add_argument("--bucket-s", type=float, default=0.1)
    p.add_argument("--extra", default="", help="more arguments for the command (space-separated)")
    p.add_argument("--out", type=Path)
    p.add_argument("--child", help=argparse.SUPPRESS)
    args, rest = p.parse_known_args(argv)
    if args.child:
        return child(args.child, rest[1:] if rest[:1] == ["--"] else rest)
    from emit import emit
    from uuvs import ensure_session

    session = ensure_session(20.0, (1920, 1080))
    trees = {"": ROOT} | {
        f" [{k}]": Path(d).resolve() for k, d in (t.split("=", 1) for t in args.tree)
    }
    runs: dict[str, list[dict]] = {}
    loads = []
    with tempfile.TemporaryDirectory() as work:
        for r in range(args.repeats):
            for label, tree in trees.items():
                for uuv in args.uuvs.split(","):
                    cmd = [
                        "process",
                        str(session),
                        "--quiet",
                        "--uuv",
                        uuv,
                        "--out",
                        f"{work}/{uuv}",
                    ]
                    name = f"process{label} --uuv {uuv}"
                    runs.setdefault(name, []).append(
                        run_watched(cmd + args.extra.split(), tree, args.interval_ms / 1000)
                    )
                    loads.append(os.getloadavg()[0])
                    print(
                        f"  round {r + 1}: {name}: {runs[name][-1]['wall_s']:.2f} s (load {loads[-1]:.1f})",
                        flush=True,
                    )
    lines = [
        (
            f"skyfix process {session.name} {args.extra} watched from outside every {args.interval_ms:g} ms "
            f"(/proc schedstat of every thread, forks included); {os.cpu_count()} cores, load average (1 min) "
            f"{min(loads):.1f}-{max(loads):.1f}; interleaved rounds"
        )
    ]
    data = {"load_1min": loads}
    for name, rs in runs.items():
        lines += table(name, rs)
        middle = sorted(rs, key=lambda r: r["wall_s"])[len(rs) // 2]
        lines += timeline(middle, args.bucket_s)
        data[name] = [
            {
                "wall_s": r["wall_s"],
                "cpu_s": r["cpu_s"],
                "phases": per_phase(intervals(r)),
                "events": events_of(r),
                "waits": waits_of(r),
            }
            for r in rs
        ]
    emit(lines, args.out, data)
    return 0


if __name__ == "__main__":
    sys.exit(main())

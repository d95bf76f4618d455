"""``skyfix process`` against decoding the same video alone, at 1080p and 4K (issue 18).

    .venv/bin/python bench/offline_speed.py [--sizes 1080p,4k] [--repeats 3] [--mil] [--lean] [--uuvs [1080p,4k]]
                                            [--tree LABEL=DIR ...]
                                            [--out bench/results/offline_speed.txt]

Sessions (generated once into /tmp/skyfix-bench: 40 s of 1080p, 10 s of 4K, 30 fps, a nadir hover with the
UUV hidden for a second) are timed end to end as child processes, interpreter start included, interleaved over
``--repeats`` rounds; medians count. Each round: decode-only with OpenCV (a ``cv2.VideoCapture`` read loop, BGR
frames) and with PyAV (frame and slice threads, BGR frames), then ``skyfix process`` (its defaults: the height from
the UUV's size measured), ``skyfix process --height-from-size off``, and with ``--mil`` the paper's MIL tracker
(first round only: it is slow). The ratio is process fps / OpenCV decode-only fps (target ≥ 0.95), of the medians and,
paired by round (each round's decode-only wall / its process wall: the machine's speed drifts between rounds), the
pairs' median [least-most]. The sessions' telemetry has no TIMESYNC (``[telemetry] timesync_hz = 0``, as many
recordings): the link's delay is unknown, so ``skyfix process`` also estimates the frames' offset from the video's
motion, as a user's run of such a recording does. Each process's peak RSS (``os.wait4``) and its CPU per second
of video are printed, and the numbers written as JSON beside ``--out``. CPU seconds
(the child's user + sys) show what the work costs beside the wall time: on a machine whose cores decoding alone
keeps busy, process cannot be faster than its CPU seconds over the cores. The machine's 1-minute load average
after each run is printed (its range in each size's heading), and each process run's line on the frames' offset to
the telemetry (the estimate, its σ, its thirds'; round 1's under the table): a change to the motion estimate shows
what it did to the offset beside what it did to the speed. ``skyfix process --help`` is timed too:
the start-up every process run pays (the interpreter and the command's imports). Each tree's modules are
byte-compiled first, as pip compiles a package's when it installs it: run from source where the environment sets
``PYTHONDONTWRITEBYTECODE`` (this machine's does), every run compiled its ~75 modules again (0.15-0.2 s).
``--tree LABEL=DIR`` also times ``skyfix process`` from another source tree (e.g. ``git archive HEAD | tar -x -C
DIR``: before and after in the same run). ``--uuvs [SIZES]``: also the session with three UUVs at 1080p (20 s) and 4K
(8 s) (:func:`bench_uuvs`): ``skyfix process --uuv all`` (one pass over the video for the three), with ``--beside``
(the heights from size and the UUVs' files in processes of their own) and ``--track-workers`` (each UUV tracked in a
worker process: :mod:`groundstation.offline.uuv_workers`), and ``--uuv uuv1`` alone (and with ``--beside``) against
decode-only of the same file, each ``--tree`` too, and whether each run's positions files are byte-identical to this
tree's (the last round's). Peak RSS is the largest of the command's processes (``os.wait4``), not their sum; CPU is
theirs together.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

from emit import emit

SIZES = {"1080p": (1920, 1080, 40), "4k": (3840, 2160, 10)}
#: The three-UUV sessions (``--uuvs``): (width, height), seconds (4K renders are slow: a short one)
UUVS_SIZES = {"1080p": ((1920, 1080), 20.0), "4k": ((3840, 2160), 8.0)}
SCENARIO = """\
name = "offline_{name}"
description = "{duration} s of {w}x{h} at 30 fps, nadir hover with a 1 s occlusion: the offline speed benchmark"
seed = 7
duration_s = {duration}
occlusions = [[1.5, 2.5]]

[camera]
width = {w}
height = {h}

[uav]
height_m = 12.0

[uuv]
depth_m = 1.5

[telemetry]
timesync_hz = 0.0  # no TIMESYNC, as many recordings: the link's delay is estimated from the video's motion
"""
BENCH_DIR = Path("/tmp/skyfix-bench")
#: ``skyfix process``'s stderr line on the frames' offset to the telemetry (its estimate, σ, thirds), kept per run
OFFSET_LINE = "offset to the telemetry from the video's motion"


def ensure_session(name: str) -> Path:
    """The benchmark session of one size, generated once."""
    w, h, duration = SIZES[name]
    path = BENCH_DIR / f"offline_{name}_{duration}s_motion"
    if (path / "video_frames.csv").exists():
        return path
    import tomllib

    from sim_fixtures.generate import generate
    from sim_fixtures.scenario import scenario_from_dict

    text = SCENARIO.format(name=name, duration=duration, w=w, h=h)
    print(f"generating {path} (once) ...", flush=True)
    generate(scenario_from_dict(tomllib.loads(text)), path, text)
    return path


def decode_only(kind: str, video: str) -> int:
    """Decode every frame of ``video`` to BGR: ``opencv`` or ``pyav``; the number of frames."""
    n = 0
    if kind == "opencv":
        import cv2

        cap = cv2.VideoCapture(video)
        while cap.read()[0]:
            n += 1
        return n
    import av

    with av.open(video) as container:
        stream = container.streams.video[0]
        stream.thread_type = "AUTO"
        for frame in container.decode(stream):
            frame.to_ndarray(format="bgr24")
            n += 1
    return n


def child(cmd: list[str], tree: Path = ROOT) -> tuple[float, float, float, str]:
    """Wall seconds, CPU seconds (user + sys), peak RSS (MB) and the stderr's line on the time offset
    (:data:`OFFSET_LINE`, "" without one) of a child process run from source ``tree``, which must succeed."""
    with tempfile.TemporaryFile() as err:
        t0 = time.perf_counter()
        proc = subprocess.Popen(
            cmd,
            stdout=subprocess.DEVNULL,
            stderr=err,
            cwd=tree,
            env=dict(os.environ, PYTHONPATH=str(tree)),
        )
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        if proc.returncode:
            err.seek(0)
            tail = err.read().decode(errors="replace")[-2000:]
            raise SystemExit(f"{' '.join(cmd)}: exit {proc.returncode}\n{tail}")
        err.seek(0)
        offset = next(
            (x for x in err.read().decode(errors="replace").splitlines() if OFFSET_LINE in x), ""
        )
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024, offset


def bench_size(
    name: str,
    repeats: int,
    mil: bool,
    trees: dict[str, Path],
    work: Path,
    data: dict,
    lean: bool = False,
) -> list[str]:
    """One size's rounds (see the module doc); its result lines, its numbers into ``data``."""
    session = ensure_session(name)
    video = str(next(session.glob("video.*")))
    frames = len((session / "video_frames.csv").read_text().splitlines()) - 1
    me = [sys.executable, str(Path(__file__).resolve())]
    runs: dict[str, list[tuple[float, float, float, str]]] = {}
    loads = []  # the machine's 1-minute load average after each run
    process = [
        sys.executable,
        "-m",
        "groundstation.cli",
        "process",
        str(session),
        "--quiet",
        "--out",
        str(work),
    ]
    variants = {
        "decode-only OpenCV": (me + ["--decode-only", "opencv", video], ROOT),
        "decode-only PyAV": (me + ["--decode-only", "pyav", video], ROOT),
    }
    if lean:
        del variants["decode-only PyAV"]
    for label, tree in trees.items():
        variants[f"process{label}"] = (process, tree)
        if lean:
            continue
        variants[f"process{label} --height-from-size off"] = (
            process + ["--height-from-size", "off"],
            tree,
        )
        variants[f"start-up{label}: process --help"] = (process[:4] + ["--help"], tree)
    for r in range(repeats):
        for variant, (cmd, tree) in variants.items():
            runs.setdefault(variant, []).append(child(cmd, tree))
            loads.append(os.getloadavg()[0])
            print(
                f"  {name} round {r + 1}: {variant}: {runs[variant][-1][0]:.2f} s (load {loads[-1]:.1f})",
                flush=True,
            )
        if mil and r == 0:
            runs["process --tracker mil"] = [child(process + ["--tracker", "mil"])]
    w, h, duration = SIZES[name]
    lines = [
        (
            f"{name}: {w}x{h}, {duration} s, {frames} frames; median of {repeats} interleaved rounds "
            f"(MIL: 1), {os.cpu_count()} cores, load average (1 min) {min(loads):.1f}-{max(loads):.1f}"
        )
    ]
    lines += table(runs, frames, duration, data)
    lines += [
        f"  {variant}, round 1's {rs[0][3][rs[0][3].index(OFFSET_LINE) :]}"
        for variant, rs in runs.items()
        if rs[0][3]
    ]
    data["load_1min"] = loads
    return lines


def table(runs: dict, frames: int, duration: float, data: dict) -> list[str]:
    """A line per variant of ``runs`` (its child runs, one a round; see :func:`child`) against the medians and
    each round's ``decode-only OpenCV``; its numbers into ``data``."""
    reference = frames / statistics.median(wall for wall, *_ in runs["decode-only OpenCV"])
    decode_walls = [wall for wall, *_ in runs["decode-only OpenCV"]]
    lines = []
    for variant, rs in runs.items():
        walls = [wall for wall, *_ in rs]
        fps = frames / statistics.median(walls)
        # each round against its own decode-only run
        paired = sorted(d / w for d, w in zip(decode_walls, walls))
        speed = (
            f"{'':49s}"
            if variant.startswith("start-up")
            else f"{fps:6.1f} fps  {fps / reference:5.2f}x decode-only  "
            f"{statistics.median(paired):4.2f}x [{paired[0]:4.2f}-{paired[-1]:4.2f}]  "
        )
        cpu = statistics.median(c for _, c, *_ in rs)
        per_video_s = (
            "" if variant.startswith("start-up") else f" ({cpu / duration:4.2f} per video s)"
        )
        lines.append(
            f"  {variant:44s} {speed}CPU {cpu:6.1f} s{per_video_s}  peak RSS "
            f"{statistics.median(m for *_, m, _ in rs):5.0f} MB  (wall {', '.join(f'{x:.1f}' for x in walls)} s)"
        )
        data[variant] = {
            "fps": frames / statistics.median(walls),
            "ratio_paired": statistics.median(paired)
            if not variant.startswith("start-up")
            else None,
            "walls_s": walls,
            "cpu_s": [c for _, c, *_ in rs],
            "peak_rss_mb": [m for *_, m, _ in rs],
            "offset": [o for *_, o in rs],
        }
    return lines


def bench_uuvs(
    name: str, repeats: int, trees: dict[str, Path], work: Path, data: dict
) -> list[str]:
    """The three-UUV session of ``bench/uuvs.py`` (its ``ensure_session``) at ``name`` (:data:`UUVS_SIZES`),
    interleaved rounds: OpenCV decode-only of its video, then per source tree ``skyfix process --uuv all`` (the three
    in one pass over the video) and ``--uuv uuv1`` alone, and this tree's ``--beside`` of both and ``--uuv all
    --track-workers`` (each UUV tracked in a worker process); whether their positions files are identical."""
    from uuvs import ensure_session as uuvs_session

    (w, h), duration = UUVS_SIZES[name]
    session = uuvs_session(duration, (w, h))
    video = str(next(session.glob("video.*")))
    frames = len((session / "video_frames.csv").read_text().splitlines()) - 1
    me = [sys.executable, str(Path(__file__).resolve())]
    process = [sys.executable, "-m", "groundstation.cli", "process", str(session), "--quiet"]
    variants = {"decode-only OpenCV": (me + ["--decode-only", "opencv", video], ROOT)}
    outs = {}  # (tree label, what) -> the output folder of its last run
    for label, tree in trees.items():
        for what, args in (("--uuv all", ["--uuv", "all"]), ("--uuv uuv1", ["--uuv", "uuv1"])):
            outs[label, what] = work / f"{what[6:]}{len(outs)}"
            variants[f"process{label} {what} ({'3 UUVs' if what.endswith('all') else '1 UUV'})"] = (
                process + args + ["--out", str(outs[label, what])],
                tree,
            )
            if tree != ROOT:
                continue
            for flag in ("--beside", "--track-workers")[: 2 if what.endswith("all") else 1]:
                outs[label, f"{what} {flag}"] = work / f"{what[6:]}{flag}"
                variants[f"process {what} {flag}"] = (
                    process + args + [flag, "--out", str(outs[label, f"{what} {flag}"])],
                    tree,
                )
    runs: dict[str, list[tuple[float, float, float, str]]] = {}
    loads = []
    for r in range(repeats):
        for variant, (cmd, tree) in variants.items():
            runs.setdefault(variant, []).append(child(cmd, tree))
            loads.append(os.getloadavg()[0])
            print(
                f"  {name} 3 UUVs round {r + 1}: {variant}: {runs[variant][-1][0]:.2f} s (load {loads[-1]:.1f})",
                flush=True,
            )
    heading = (
        f"{name}, 3 UUVs ({session.name}): {w}x{h}, {duration:g} s, {frames} frames; median of {repeats} "
        f"interleaved rounds, {os.cpu_count()} cores, load average (1 min) {min(loads):.1f}-{max(loads):.1f}"
    )
    data["load_1min"] = loads
    return [heading, *table(runs, frames, duration, data), *identical(outs, data)]


def identical(outs: dict, data: dict) -> list[str]:
    """Whether each run's positions files (``outs``: (tree label, what) -> its output folder) are byte-identical
    to this tree's (``--beside``, ``--track-workers``: to this tree's without them): a line each, into ``data``
    too."""
    lines = []
    for (label, what), folder in outs.items():
        mine = outs["", " ".join(what.split()[:2])]
        if folder == mine:
            continue
        files = sorted(p.relative_to(mine) for p in mine.rglob("positions*.csv"))
        same = [
            f
            for f in files
            if (folder / f).is_file() and (folder / f).read_bytes() == (mine / f).read_bytes()
        ]
        data[f"identical{label} {what}"] = [str(f) for f in same]
        lines.append(
            f"  process{label} {what}: {len(same)} of {len(files)} positions files byte-identical to this tree's"
            + (
                ""
                if len(same) == len(files)
                else f" (differ: {', '.join(str(f) for f in files if f not in same)})"
            )
        )
    return lines


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument(
        "--sizes", default="1080p,4k", help='comma-separated: 1080p, 4k (default both; "": none)'
    )
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument(
        "--mil", action="store_true", help="also the MIL tracker's pipeline (once per size)"
    )
    p.add_argument(
        "--tree",
        action="append",
        default=[],
        metavar="LABEL=DIR",
        help="also time skyfix process from this source tree",
    )
    p.add_argument(
        "--lean",
        action="store_true",
        help="OpenCV decode-only and skyfix process (per tree) only: a round in a third of the time",
    )
    p.add_argument(
        "--uuvs",
        nargs="?",
        const="1080p,4k",
        default="",
        help="also the three-UUV session at these sizes (default 1080p,4k): process --uuv all and --uuv uuv1 "
        "against decode-only",
    )
    p.add_argument("--out", type=Path, help="also write the results here")
    p.add_argument("--decode-only", nargs=2, metavar=("KIND", "VIDEO"), help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.decode_only:
        decode_only(*args.decode_only)
        return 0
    trees = {"": ROOT} | {
        f" [{label}]": Path(d).resolve() for label, d in (t.split("=", 1) for t in args.tree)
    }
    # as installed: pip byte-compiles a package's modules (see the module doc)
    for tree in trees.values():
        subprocess.run(
            [sys.executable, "-m", "compileall", "-q", "localizer", "groundstation"],
            cwd=tree,
            check=True,
        )
    lines, data = [], {}
    with tempfile.TemporaryDirectory() as work:
        for name in filter(None, args.sizes.split(",")):
            lines += bench_size(
                name,
                args.repeats,
                args.mil,
                trees,
                Path(work),
                data.setdefault(name, {}),
                args.lean,
            )
        for name in filter(None, args.uuvs.split(",")):
            lines += bench_uuvs(
                name, args.repeats, trees, Path(work), data.setdefault(f"{name}_3uuvs", {})
            )
    emit(lines, args.out, data)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""What PyAV's log callback costs a file's decoding beside a busy interpreter (issue 30).

    .venv/bin/python bench/ffmpeg_log_cost.py --video /tmp/skyfix-bench/uuvs3_1080p_20s/video.ts [--rounds 5]
                                              [--work-us 1500] [--out bench/results/ffmpeg_log_cost.txt]

skyfix routes FFmpeg's warnings and errors to its log (:mod:`groundstation.video.ffmpeg_log`), through PyAV's log
callback. That callback takes the interpreter's lock for every message FFmpeg emits, its debug lines too (the H.264
parser logs each NAL unit), before it looks at the level: every decoding thread waits for the lock once or more per
frame, while the main thread holds it to track. Each round, in a child process per setting (interleaved), the video
is read as ``skyfix process`` reads it (:func:`~groundstation.video.file.open_video`, grey, prefetched) while the main
thread spends ``--work-us`` of pure Python per frame (what tracking does with the lock held), once with the callback
at WARNING (as skyfix sets it) and once with PyAV's logging off (its callback returns at once, no lock). Printed: the
medians of wall and CPU seconds, and the ratio per round. The decoded frames are the same either way.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
from pathlib import Path

from emit import emit

ROOT = Path(__file__).resolve().parents[1]
CHILD = """
import sys, time
import av.logging
import groundstation.video.file as file
file.route_ffmpeg_log = lambda: None  # the setting below instead of skyfix's
av.logging.set_level(None if sys.argv[2] == "off" else av.logging.WARNING)
work_s = float(sys.argv[3]) * 1e-6
t0, c0, n = time.perf_counter(), time.process_time(), 0
with file.open_video(sys.argv[1], grey=True) as video:
    for frame in video.prefetch(8):
        n += 1
        end = time.thread_time() + work_s
        while time.thread_time() < end:
            pass
print(time.perf_counter() - t0, time.process_time() - c0, n)
"""
SETTINGS = {"on": "PyAV's callback at WARNING (skyfix's)", "off": "PyAV's logging off"}


def run(video: Path, setting: str, work_us: float) -> tuple[float, float, int]:
    """One child's wall seconds, CPU seconds and frames read."""
    out = subprocess.run(
        [sys.executable, "-c", CHILD, str(video), setting, str(work_us)],
        cwd=ROOT,
        env=dict(os.environ, PYTHONPATH=str(ROOT)),
        capture_output=True,
        text=True,
        check=True,
    )
    wall, cpu, n = out.stdout.split()
    return float(wall), float(cpu), int(n)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--video", type=Path, required=True)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument(
        "--work-us", type=float, default=1500.0, help="main thread's Python work per frame"
    )
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()
    runs: dict[str, list[tuple[float, float, int]]] = {s: [] for s in SETTINGS}
    loads = []
    for _ in range(args.rounds):
        for setting in SETTINGS:
            runs[setting].append(run(args.video, setting, args.work_us))
            loads.append(os.getloadavg()[0])
    frames = {n for rs in runs.values() for _, _, n in rs}
    ratios = [on[0] / off[0] for on, off in zip(runs["on"], runs["off"], strict=True)]
    head = (
        f"{args.video.name}: read grey and prefetched, {args.work_us:.0f} us of Python per frame in the main thread; "
        f"{args.rounds} interleaved rounds, {os.cpu_count()} cores, load average (1 min) "
        f"{min(loads):.1f}-{max(loads):.1f}; frames read {sorted(frames)}"
    )
    lines = [head]
    for setting, label in SETTINGS.items():
        walls, cpus = [r[0] for r in runs[setting]], [r[1] for r in runs[setting]]
        lines.append(
            f"  {label:40s} wall {statistics.median(walls):.2f} s [{min(walls):.2f}-{max(walls):.2f}]"
            f"  CPU {statistics.median(cpus):.2f} s"
        )
    lines.append(
        f"  wall with the callback / without, per round: median {statistics.median(ratios):.3f} "
        f"[{min(ratios):.3f}-{max(ratios):.3f}]"
    )
    emit(lines, args.out, {"runs": runs, "ratios": ratios, "load_1min": loads})


if __name__ == "__main__":
    main()

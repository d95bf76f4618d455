"""The CPU ``skyfix process``'s imports cost its main thread before the first frame is tracked (issue 30).

    .venv/bin/python bench/process_imports.py [--base DIR] [--repeats 5] [--out bench/results/process_imports.txt]

Each repeat is a child process (run from the tree, the tree first on its path) that imports what the command runs
on: :mod:`groundstation.offline.process` (the command's module, imported to parse its arguments) and
:mod:`groundstation.offline.track` (imported by the pass), and prints the CPU seconds (``time.process_time``) that
took and the modules it loaded that the default run does not use (``scipy.ndimage``: only a session in waves
measures the vehicle's silhouette). ``--base DIR`` measures another tree (e.g. an export of ``main``'s HEAD) in the
same run, interleaved. CPU seconds are what count on a shared machine: the wall time of the imports is the load's.
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
t0 = time.process_time()
import groundstation.offline.process, groundstation.offline.track
cpu = time.process_time() - t0
assert groundstation.offline.track.__file__.startswith(sys.argv[1]), groundstation.offline.track.__file__
print(cpu, int("scipy.ndimage" in sys.modules))
"""


def measure(tree: Path) -> tuple[float, bool]:
    """One child's import CPU seconds and whether scipy.ndimage was loaded."""
    out = subprocess.run(
        [sys.executable, "-c", CHILD, str(tree)],
        cwd=tree,
        env=dict(os.environ, PYTHONPATH=str(tree)),
        check=True,
        capture_output=True,
        text=True,
    ).stdout.split()
    return float(out[0]), out[1] == "1"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--base", type=Path, help="another source tree, measured interleaved")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--out", type=Path)
    args = p.parse_args(argv)
    trees = {"this tree": ROOT} | ({"base": args.base.resolve()} if args.base else {})
    runs: dict[str, list[tuple[float, bool]]] = {label: [] for label in trees}
    loads = []
    for _ in range(args.repeats):
        for label, tree in trees.items():
            runs[label].append(measure(tree))
            loads.append(os.getloadavg()[0])
    lines = [
        (
            f"skyfix process's imports (groundstation.offline.process + .track), CPU s per child process, "
            f"{args.repeats} interleaved repeats, load average (1 min) {min(loads):.1f}-{max(loads):.1f}"
        )
    ]
    for label, rs in runs.items():
        cpus = [c for c, _ in rs]
        lines.append(
            f"  {label:10s} median {statistics.median(cpus):.3f} s [{min(cpus):.3f}-{max(cpus):.3f}]"
            f"  scipy.ndimage loaded: {'yes' if any(n for _, n in rs) else 'no'}"
        )
    emit(lines, args.out, {label: rs for label, rs in runs.items()} | {"load_1min": loads})
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""CPU of reading a session with several UUVs (``skyfix process --uuv all``'s
:func:`groundstation.session.read.load_sessions`: the UAV's tlog parsed, ingested, each UUV's depth read) in this
tree against a base revision's, on one session.

    .venv/bin/python bench/load_sessions.py SESSION [--base REV] [--rounds 5] [--out bench/results/load_sessions.txt]

The base revision (default ``HEAD``) is extracted with ``git archive``. Each round runs one child process per tree
(the order alternating), which times ``load_sessions`` with ``time.process_time`` (the best of 5). The table gives
the median over the rounds and the machine's 1-minute load average.
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
REPEATS = 5


def child(session: str) -> float:
    """In the tree on ``sys.path``: the best CPU seconds of :data:`REPEATS` ``load_sessions`` of every UUV."""
    from groundstation.session.read import load_sessions, uuv_ids

    uuvs, spent = uuv_ids(session), []
    for _ in range(REPEATS):
        t0 = time.process_time()
        load_sessions(session, uuvs)
        spent.append(time.process_time() - t0)
    return min(spent)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("session", type=Path)
    p.add_argument("--base", default="HEAD")
    p.add_argument("--rounds", type=int, default=5)
    p.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "load_sessions.txt")
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.child:
        print(child(str(args.session)))
        return 0
    with tempfile.TemporaryDirectory() as base:
        archive = subprocess.run(
            ["git", "archive", args.base], cwd=ROOT, check=True, capture_output=True
        ).stdout
        subprocess.run(["tar", "-x", "-C", base], input=archive, check=True)
        trees = {f"base {args.base}": Path(base), "this tree": ROOT}
        runs: dict[str, list[float]] = {label: [] for label in trees}
        loads = []
        for r in range(args.rounds):
            for label in list(trees)[:: 1 if r % 2 == 0 else -1]:
                out = subprocess.run(
                    [
                        sys.executable,
                        str(ROOT / "bench" / "load_sessions.py"),
                        str(args.session.resolve()),
                        "--child",
                    ],
                    cwd=trees[label],
                    env={**os.environ, "PYTHONPATH": str(trees[label])},
                    check=True,
                    capture_output=True,
                    text=True,
                ).stdout
                runs[label].append(float(out.split()[-1]))
            loads.append(os.getloadavg()[0])
    from groundstation.session.read import uuv_ids

    lines = [
        f"# bench/load_sessions.py {args.session} --base {args.base} --rounds {args.rounds}",
        f"# {len(uuv_ids(args.session))} UUVs; CPU ms of load_sessions (time.process_time), median over rounds",
        f"# of the best of {REPEATS}; load average (1 min) after each round: {min(loads):.2f}..{max(loads):.2f}",
    ]
    lines += [f"{label:<16}{1e3 * statistics.median(rs):10.1f}" for label, rs in runs.items()]
    b, t = runs.values()
    lines.append(f"{'this / base':<16}{statistics.median(y / x for x, y in zip(b, t)):10.2f}")
    text = "\n".join(lines) + "\n"
    print(text, end="")
    with args.out.open("a") as f:
        f.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The per-UUV output stage of ``skyfix process`` (issue 30): the safety gates over the recording
(:func:`localizer.fix_gate.gate_offline`) and the smoothed track (:func:`localizer.smooth.smooth_fixes`), the CPU of
this tree against a base revision's on the same fixes, and whether their results are identical.

    .venv/bin/python bench/output_stage.py [--base REV] [--session DIR] [--rounds 7]
                                           [--out bench/results/offline_output_stage.txt]

The fixes are those ``skyfix process --uuv all`` hands to the smoothed track
(:func:`groundstation.offline.smoothed.offline_track`), captured from one run of the command in this tree on the
session (default: ``bench/offline_speed.py``'s three-UUV 1080p one, ``/tmp/skyfix-bench/uuvs3_1080p_20s``; a bundled
session of ``sim_fixtures/bundled`` works too). The base revision (default ``HEAD``) is extracted with ``git archive``.
Each round runs one child process per tree (the order alternating from round to round), which times with
``time.process_time`` ``offline_track`` over every UUV's fixes, ``gate_offline`` and ``smooth_fixes`` inside it
(the best of three repeats). The children's results (the status per frame, every array of the smoothed track)
are compared byte for byte. The table gives the median over the rounds, and the machine's 1-minute load average.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import io
import json
import os
import pickle
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SESSION = Path("/tmp/skyfix-bench/uuvs3_1080p_20s")
REPEATS = 3
PARTS = ("offline_track", "gate_offline", "smooth_fixes")


def capture(session: Path, inputs: Path) -> int:
    """Runs ``skyfix process --uuv all`` on ``session`` and pickles each UUV's ``offline_track`` arguments."""
    from groundstation.cli import main
    from groundstation.offline import process

    taken, offline_track = [], process.offline_track

    def keep(*args):
        taken.append(args)
        return offline_track(*args)

    process.offline_track = keep
    with tempfile.TemporaryDirectory() as out, contextlib.redirect_stdout(io.StringIO()):
        main(["process", str(session), "--out", out, "--quiet", "--uuv", "all"])
    inputs.write_bytes(pickle.dumps(taken))
    return len(taken)


def child(inputs: Path) -> dict:
    """In the tree on ``sys.path``: CPU seconds per part (best of :data:`REPEATS`) and a digest of the results."""
    from groundstation.offline import smoothed

    spent = dict.fromkeys(PARTS, 0.0)

    def timed(name, f):
        def run(*args, **kwargs):
            t0 = time.process_time()
            try:
                return f(*args, **kwargs)
            finally:
                spent[name] += time.process_time() - t0

        return run

    smoothed.gate_offline = timed("gate_offline", smoothed.gate_offline)
    smoothed.smooth_fixes = timed("smooth_fixes", smoothed.smooth_fixes)
    offline_track = timed("offline_track", smoothed.offline_track)
    taken = pickle.loads(inputs.read_bytes())
    best = None
    for _ in range(REPEATS):
        spent.update(dict.fromkeys(PARTS, 0.0))
        results = [offline_track(*args) for args in taken]
        if best is None or spent["offline_track"] < best["offline_track"]:
            best = dict(spent)
    digest = hashlib.sha256(
        pickle.dumps([(vars(track), list(status)) for track, status in results])
    )
    return {**best, "digest": digest.hexdigest(), "fixes": sum(len(a[0]) for a in taken)}


def run_child(tree: Path, inputs: Path) -> dict:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    out = subprocess.run(
        [sys.executable, str(ROOT / "bench" / "output_stage.py"), "--child", str(inputs)],
        cwd=tree,
        env=env,
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    return json.loads(out.splitlines()[-1])


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--base", default="HEAD", help="the revision to compare with (default: HEAD)")
    p.add_argument("--session", type=Path, default=SESSION)
    p.add_argument("--rounds", type=int, default=7)
    p.add_argument(
        "--out", type=Path, default=ROOT / "bench" / "results" / "offline_output_stage.txt"
    )
    p.add_argument("--child", type=Path, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.child:
        print(json.dumps(child(args.child)))
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        base = tmp / "base"
        base.mkdir()
        archive = subprocess.run(
            ["git", "archive", args.base], cwd=ROOT, check=True, capture_output=True
        ).stdout
        subprocess.run(["tar", "-x", "-C", str(base)], input=archive, check=True)
        inputs = tmp / "inputs.pkl"
        uuvs = capture(args.session, inputs)
        trees = {f"base {args.base}": base, "this tree": ROOT}
        runs = {label: [] for label in trees}
        loads = []
        for r in range(args.rounds):
            for label in list(trees)[:: 1 if r % 2 == 0 else -1]:
                runs[label].append(run_child(trees[label], inputs))
            loads.append(os.getloadavg()[0])
    digests = {label: {run["digest"] for run in rs} for label, rs in runs.items()}
    same = len(set().union(*digests.values())) == 1
    fixes = next(iter(runs.values()))[0]["fixes"]
    lines = [
        f"# bench/output_stage.py --base {args.base} --session {args.session} --rounds {args.rounds}",
        f"# {uuvs} UUVs, {fixes} frames; CPU ms (time.process_time), median over rounds of the best of {REPEATS}",
        f"# load average (1 min) after each round: {min(loads):.2f}..{max(loads):.2f}",
        f"{'tree':<16}" + "".join(f"{part:>16}" for part in PARTS),
    ]
    for label, rs in runs.items():
        lines.append(
            f"{label:<16}"
            + "".join(f"{1e3 * statistics.median(r[part] for r in rs):16.1f}" for part in PARTS)
        )
    b, t = (runs[label] for label in trees)
    lines.append(
        f"{'this / base':<16}"
        + "".join(
            f"{statistics.median(y[part] / x[part] for x, y in zip(b, t)):16.2f}" for part in PARTS
        )
        + "   (median of the per-round ratios)"
    )
    lines.append(
        f"results identical (status, every smoothed array, byte for byte): {'yes' if same else 'NO'}"
    )
    text = "\n".join(lines) + "\n"
    print(text, end="")
    args.out.write_text(text)
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())

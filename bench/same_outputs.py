"""Every output of ``skyfix process`` byte-identical between this tree and others (issue 30: a change for speed keeps
the results identical, every file of them, not positions.csv alone).

    .venv/bin/python bench/same_outputs.py --tree base=DIR [--tree LABEL=DIR ...] [--session DIR ...]
                                           [--out bench/results/same_outputs.txt]

``skyfix process`` runs as a user runs it (``python -m groundstation.cli process SESSION --quiet --out ...``, a child
process with the tree on its ``PYTHONPATH``) from this tree and each ``--tree`` (e.g. ``git archive REV | tar -x -C
DIR``): on the three-UUV 1080p session (``bench/offline_speed.py --uuvs 1080p`` makes it) with ``--uuv all``, with
``--uuv all --height-from-size auto`` (the heights from size handed to the height's fusion), ``--uuv all
--track-workers``, ``--uuv all --beside`` and ``--uuv uuv2`` alone, and on every bundled session
(``sim_fixtures/bundled``) and each ``--session`` as it is. Per run it compares every file the run wrote and what it
printed on stdout and stderr (its output folder's path taken out) with this tree's, and prints the files that
differ; the exit status is 1 when any does.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from emit import emit

ROOT = Path(__file__).resolve().parents[1]
UUVS = Path("/tmp/skyfix-bench/uuvs3_1080p_20s")
#: (name, arguments) of the runs on the three-UUV session
UUV_RUNS = (
    ("uuvs3_all", ["--uuv", "all"]),
    ("uuvs3_all_auto", ["--uuv", "all", "--height-from-size", "auto"]),
    ("uuvs3_all_workers", ["--uuv", "all", "--track-workers"]),
    ("uuvs3_all_beside", ["--uuv", "all", "--beside"]),
    ("uuvs3_uuv2", ["--uuv", "uuv2"]),
)


def runs(sessions: list[Path]) -> list[tuple[str, Path, list[str]]]:
    """(name, session, arguments) of every run."""
    if not (UUVS / "session.toml").is_file():
        sys.exit(f"{UUVS}: missing (bench/offline_speed.py --uuvs 1080p makes it)")
    bundled = sorted(p for p in (ROOT / "sim_fixtures" / "bundled").iterdir() if p.is_dir())
    return [(name, UUVS, args) for name, args in UUV_RUNS] + [
        (p.name, p, []) for p in bundled + sessions
    ]


def outputs(tree: Path, session: Path, args: list[str], out: Path) -> dict[str, bytes]:
    """The files a run from ``tree`` wrote under ``out`` (by relative path) and what it printed (``stdout``,
    ``stderr``, with ``out`` replaced by ``OUT``)."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    argv = [sys.executable, "-m", "groundstation.cli", "process", str(session), "--quiet"]
    run = subprocess.run(
        [*argv, "--out", str(out), *args], cwd=tree, env=env, capture_output=True, check=False
    )
    found = {
        "stdout": run.stdout.replace(bytes(out), b"OUT"),
        "stderr": run.stderr.replace(bytes(out), b"OUT"),
        "exit status": str(run.returncode).encode(),
    }
    found.update({str(p.relative_to(out)): p.read_bytes() for p in out.rglob("*") if p.is_file()})
    return found


def differences(mine: dict[str, bytes], theirs: dict[str, bytes]) -> list[str]:
    """The outputs of one run that differ between two trees (or that only one wrote)."""
    return sorted(
        name for name in mine.keys() | theirs.keys() if mine.get(name) != theirs.get(name)
    )


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--tree", action="append", default=[], metavar="LABEL=DIR", required=True)
    p.add_argument("--session", action="append", default=[], type=Path, metavar="DIR")
    p.add_argument("--out", type=Path, help="also write the results here")
    a = p.parse_args(argv)
    trees = [(label, Path(d).resolve()) for label, d in (t.split("=", 1) for t in a.tree)]
    lines, data, differ = (
        [f"skyfix process: every output of this tree ({ROOT}) against {a.tree}"],
        {},
        False,
    )
    for name, session, args in runs([s.resolve() for s in a.session]):
        with tempfile.TemporaryDirectory() as tmp:
            mine = outputs(ROOT, session, args, Path(tmp) / "out")
        for label, tree in trees:
            with tempfile.TemporaryDirectory() as tmp:
                found = differences(mine, outputs(tree, session, args, Path(tmp) / "out"))
            differ = differ or bool(found)
            data[f"{name} {label}"] = {"outputs": len(mine), "differ": found}
            lines.append(
                f"  {name} ({' '.join(args) or 'as it is'}) [{label}]: "
                + (
                    f"{len(found)} of {len(mine)} differ: {', '.join(found)}"
                    if found
                    else f"{len(mine)} outputs identical"
                )
            )
            print(lines[-1], flush=True)
    lines.append(f"load average (1 min) {os.getloadavg()[0]:.1f}")
    emit(lines, a.out, data)
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())

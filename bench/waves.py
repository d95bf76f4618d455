"""Wind waves in the simulator: what the waves alone cost the geometry, and how the tracker fares.

    .venv/bin/python bench/waves.py [--work /tmp/skyfix-waves] [--out bench/results/waves.txt] [--regenerate]
                                    [--only NAME ...]

For each waves scenario (``sim_fixtures/scenarios/waves_*.toml``, generated once with video into ``--work``; the
rendering's seconds per frame are printed, wall clock of the session's render and encode over its frames) it
reports: the waves' own error of the scene from ``truth_waves.csv`` (RMS north and east, and its mean horizontal
length, comparable to evaluate's MAE); ``skyfix evaluate --use-track`` (the true pixel through the waves, the
telemetry as the scenario states it): MAE, shape, share within 2·h_acc; and ``skyfix process`` tracking the video:
how many frames it located.
"""

from __future__ import annotations

import argparse
import csv
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

from groundstation.session.positions import read_positions_csv
from groundstation.session.read import read_table
from sim_fixtures.generate import TRUTH_WAVES_CSV, generate
from sim_fixtures.scenario import load_scenario

SCENARIOS = sorted(p.stem for p in (ROOT / "sim_fixtures" / "scenarios").glob("waves_*.toml"))
SKYFIX = [sys.executable, "-m", "groundstation.cli"]


def session(name: str, work: Path, regenerate: bool) -> tuple[Path, str]:
    """The generated session and its rendering's seconds per frame ("-" when it was there already)."""
    out = work / name
    if regenerate or not (out / "video.mp4").is_file():
        path = ROOT / "sim_fixtures" / "scenarios" / f"{name}.toml"
        report = generate(load_scenario(path), out, scenario_text=path.read_text())
        return out, f"{report.render_s / report.frames:.3f}"
    return out, "-"


def wave_error(path: Path) -> tuple[np.ndarray, float]:
    """RMS (north, east) and mean horizontal length (m) of the waves' own error, over the frames with a track."""
    t = read_table(
        path / TRUTH_WAVES_CSV,
        ("t", "wave_dn_m", "wave_de_m"),
        allow_empty=("wave_dn_m", "wave_de_m"),
    )
    e = np.column_stack([t["wave_dn_m"], t["wave_de_m"]])
    e = e[np.isfinite(e).all(axis=1)]
    return np.sqrt(np.mean(e**2, axis=0)), float(np.mean(np.hypot(*e.T)))


def evaluate(path: Path, out: Path) -> dict:
    """evaluate --use-track's refraction row."""
    subprocess.run(
        [*SKYFIX, "evaluate", str(path), "--use-track", "--out", str(out), "--quiet"],
        cwd=ROOT,
        capture_output=True,
        check=False,
    )
    with open(out / "evaluation.csv", newline="") as f:
        return next(r for r in csv.DictReader(f) if r["method"] == "refraction")


def tracked(path: Path, out: Path) -> tuple[int, int, float]:
    """``skyfix process`` tracking the video: (frames located, frames, seconds)."""
    t0 = time.perf_counter()
    subprocess.run(
        [*SKYFIX, "process", str(path), "--out", str(out), "--quiet"],
        cwd=ROOT,
        capture_output=True,
        check=False,
    )
    fixes = read_positions_csv(out / "positions.csv")
    return int(np.sum(fixes.status == "ok")), len(fixes.status), time.perf_counter() - t0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", default="/tmp/skyfix-waves")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "waves.txt"))
    ap.add_argument("--regenerate", action="store_true", help="render the sessions again")
    ap.add_argument("--only", nargs="*")
    args = ap.parse_args()
    work = Path(args.work)
    header = (
        f"{'scenario':20s} {'s/frame':>7s}  {'wave RMS n,e m':>15s} {'wave MAE':>8s}  {'use-track MAE':>13s} "
        f"{'shape':>6s} {'in 2h':>6s}  {'tracked: located':>16s}"
    )
    lines = [header]
    print(header, flush=True)
    for name in args.only or SCENARIOS:
        path, per_frame = session(name, work, args.regenerate)
        rms, mae = wave_error(path)
        row = evaluate(path, work / "evaluate" / name)
        located, frames, _ = tracked(path, work / "process" / name)
        lines.append(
            f"{name:20s} {per_frame:>7s}  {rms[0]:7.4f},{rms[1]:7.4f} {mae:8.4f}  {float(row['mae_m']):13.4f} "
            f"{float(row['shape_m']):6.4f} {float(row['within_2sigma']):6.1%}  {located:>7d} of {frames}"
        )
        print(lines[-1], flush=True)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"-> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""A hovering drone in the weather: what skyfix gets against what the drone's telemetry allows, and the smoothed track.

    .venv/bin/python bench/weather.py [--work /tmp/skyfix-weather] [--out bench/results/weather.txt] [--regenerate]
                                      [--only NAME ...]

For each scenario ``sim_fixtures/scenarios/weather_*.toml`` (wind waves at 2, 5 and 8 m/s, each flown by a drone with
its own sensor errors on RTK and on plain GNSS; generated once with video into ``--work``) it runs ``skyfix evaluate``
twice, tracking the video and with ``--use-track`` (the true pixel), and prints the refraction rows: coverage of the
frames where the UUV can be seen, MAE, shape (MAE after the best constant offset), share within 2·h_acc, the scene's
wave-only MAE, what the telemetry allows (MAE and shape of the true pixel's flat-surface solution with the reported
telemetry) and the tracked run's ratios to it (target: within 1.2×), the share of the frames the smoothed track has a
position at and its shape (target with RTK: ≤ 0.03 m). The ``--use-track`` rows are the geometry alone, so the numbers
mean something where the tracker still loses frames. The last two columns measure the tracked pixel against the true one (``track.csv``: the UUV's top face
seen through the waves) over the frames located: the bias (px, the length of the mean error) and the jitter about it
(px, the mean distance from that mean), the pixel's own part of the tracked row's error.
"""

from __future__ import annotations

import argparse
import csv
import math
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

import numpy as np
from waves import session

from groundstation.session.read import read_table

SCENARIOS = sorted(p.stem for p in (ROOT / "sim_fixtures" / "scenarios").glob("weather_*.toml"))
SKYFIX = [sys.executable, "-m", "groundstation.cli"]
COLUMNS = (
    ("visible_coverage", "visible", "{:.1%}"),
    ("mae_m", "MAE m", "{:.4f}"),
    ("shape_m", "shape m", "{:.4f}"),
    ("within_2sigma", "in 2σ", "{:.1%}"),
    ("wave_mae_m", "waves m", "{:.4f}"),
    ("allowed_mae_m", "allowed", "{:.4f}"),
    ("allowed_shape_m", "shape m", "{:.4f}"),
    ("mae_ratio", "×MAE", "{:.2f}"),
    ("shape_ratio", "×shape", "{:.2f}"),
    ("smoothed_coverage", "smoothed", "{:.1%}"),
    ("smoothed_shape_m", "shape m", "{:.4f}"),
    ("smoothed_within_2sigma", "in 2σ", "{:.1%}"),
)


def evaluate(path: Path, out: Path, use_track: bool) -> dict:
    """``skyfix evaluate``'s refraction row (tracking the video, or ``--use-track``)."""
    extra = ["--use-track"] if use_track else []
    subprocess.run(
        [*SKYFIX, "evaluate", str(path), *extra, "--out", str(out), "--quiet"],
        cwd=ROOT,
        capture_output=True,
        check=False,
    )
    with open(out / "evaluation.csv", newline="") as f:
        return next(r for r in csv.DictReader(f) if r["method"] == "refraction")


def pixel_error(path: Path, out: Path) -> tuple[float, float]:
    """The located pixels' error against the true pixel (px): the bias (the mean error's length) and the jitter
    (the mean distance from the mean error), over the frames of ``out``'s positions.csv reported ``ok``."""
    truth = read_table(path / "track.csv", ("t", "u", "v"), allow_empty=("u", "v"))
    fixes = read_table(
        out / path.name / "refraction" / "positions.csv", ("t", "u", "v"), allow_empty=("u", "v")
    )
    err = np.column_stack(
        [fixes[c] - np.interp(fixes["t"], truth["t"], truth[c]) for c in ("u", "v")]
    )
    err = err[np.all(np.isfinite(err), axis=1)]
    if not len(err):
        return math.nan, math.nan
    mean = err.mean(axis=0)
    return float(np.hypot(*mean)), float(np.mean(np.hypot(*(err - mean).T)))


def row(name: str, pixels: str, r: dict, pixel: tuple[float, float]) -> str:
    cells = []
    for key, head, form in COLUMNS:
        v = float(r[key])
        cells.append(f"{form.format(v) if math.isfinite(v) else '-':>{max(len(head), 7)}}")
    cells += [f"{v:{w}.2f}" if math.isfinite(v) else f"{'-':>{w}}" for v, w in zip(pixel, (7, 9))]
    return f"{name:20s} {pixels:10s} " + " ".join(cells)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", default="/tmp/skyfix-weather")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "weather.txt"))
    ap.add_argument("--regenerate", action="store_true", help="render the sessions again")
    ap.add_argument("--only", nargs="*")
    args = ap.parse_args()
    work = Path(args.work)
    header = (
        f"{'scenario':20s} {'pixels':10s} "
        + " ".join(f"{h:>{max(len(h), 7)}}" for _, h, _ in COLUMNS)
        + f" {'bias px':>7} {'jitter px':>9}"
    )
    lines = [header]
    print(header, flush=True)
    for name in args.only or SCENARIOS:
        path, _ = session(name, work, args.regenerate)
        for pixels, use_track in (("tracked", False), ("true pixel", True)):
            out = work / "evaluate" / pixels.replace(" ", "_") / name
            lines.append(row(name, pixels, evaluate(path, out, use_track), pixel_error(path, out)))
            print(lines[-1], flush=True)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"-> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

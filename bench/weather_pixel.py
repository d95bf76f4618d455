"""The tracked pixel's own part of ``bench/weather.py``'s error, in metres, per tree: each frame's tracked position
less the true pixel's (the same telemetry, the same geometry), over the frames both have, after its mean is taken
out (the *shape*, as ``skyfix evaluate``'s), for ``positions.csv`` and ``positions_smoothed.csv``.

    .venv/bin/python bench/weather_pixel.py LABEL=WORK [LABEL=WORK ...] [--out bench/results/weather_pixel.txt]

Each ``WORK`` is a ``--work`` directory ``bench/weather.py`` has run in (its ``evaluate/tracked`` and
``evaluate/true_pixel`` outputs; run once per tree, each tree in its own ``--work`` of links to the same renders).
The weather rows' shape mixes the pixel's error with the telemetry's (the drone's own sensor errors), and two pixels
of the same scatter can score apart by how their error happens to line up with the telemetry's over a 12-s
recording; this measures the pixel's part alone. Per scenario: ``pixel m`` (the causal fixes' shape), ``smoothed m``
(the smoothed track's, over the frames both smoothed tracks have) and ``both`` (the share of the frames those are).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

from groundstation.session.positions import read_positions_csv
from localizer.geodesy import geodetic_to_ned

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = sorted(p.stem for p in (ROOT / "sim_fixtures" / "scenarios").glob("weather_*.toml"))


def pixel_shape(work: Path, name: str, table: str) -> tuple[float, float]:
    """The shape (m) of the tracked positions less the true pixel's in ``table``, and the share of the frames both
    have a position at."""
    tracked, true = (
        read_positions_csv(work / "evaluate" / pixels / name / name / "refraction" / table)
        for pixels in ("tracked", "true_pixel")
    )
    if not np.array_equal(tracked.t_unix, true.t_unix):
        raise SystemExit(f"{work}: {name}'s {table}: the two runs' frames differ")
    both = np.isfinite(tracked.lat) & np.isfinite(true.lat)
    both &= (tracked.status == "ok") & (true.status == "ok")
    if not both.any():
        return float("nan"), 0.0
    lat0, lon0 = float(true.lat[both][0]), float(true.lon[both][0])
    n, e, _ = geodetic_to_ned(tracked.lat[both], tracked.lon[both], 0.0, lat0, lon0, 0.0)
    n0, e0, _ = geodetic_to_ned(true.lat[both], true.lon[both], 0.0, lat0, lon0, 0.0)
    err = np.column_stack([n - n0, e - e0])
    err -= err.mean(axis=0)
    return float(np.mean(np.hypot(*err.T))), float(both.mean())


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("works", nargs="+", metavar="LABEL=WORK")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "weather_pixel.txt"))
    args = ap.parse_args()
    lines = [f"{'scenario':20s} {'tree':10s} {'pixel m':>8} {'smoothed m':>10} {'both':>6}"]
    print(lines[0], flush=True)
    for name in SCENARIOS:
        for label, work in (w.split("=", 1) for w in args.works):
            shape, _ = pixel_shape(Path(work), name, "positions.csv")
            smoothed, share = pixel_shape(Path(work), name, "positions_smoothed.csv")
            lines.append(f"{name:20s} {label:10s} {shape:8.4f} {smoothed:10.4f} {share:6.1%}")
            print(lines[-1], flush=True)
    lines.append(f"\nload average (1, 5, 15 min): {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"-> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The camera's height above the water: what each height source buys, geometry only.

    .venv/bin/python bench/height.py [--work /tmp/skyfix-height] [--out bench/results/height.txt]
                                     [--skyfix "PYTHON -m groundstation.cli" --skyfix-cwd DIR] [--only NAME ...]
                                     [--weather /tmp/skyfix-weather]

For each scenario (``sim_fixtures/scenarios/<name>.toml``, generated once into ``--work`` without
video, and two variants of the rangefinder scenario: a lidar that gets no return from the water,
one that sees the seafloor) it runs ``skyfix evaluate --use-track`` and reports, for the refraction
method: the MAE against truth and the share of fixes within 2·h_acc (evaluate's own table), and
from ``positions.csv`` the camera's height against its truth (the scenario's motion): mean and
largest error, its standard deviation (what is left once a constant offset is removed), the RMS of its change
from frame to frame, the share within 2·sigma_height_m, the
median sigma and the source words.
``--skyfix``/``--skyfix-cwd`` run another skyfix (an older checkout: before/after) on the same
sessions. ``sim_fixtures/bundled/*`` is evaluated too (geometry only), the sessions that must not
get worse. ``<name>:climb``: the scenario climbing and descending 3 m at up to 0.94 m/s, its EKF heights with 3 cm of
white noise (what the height must follow without lag). ``--weather DIR``: instead, the hovering drones in the weather (``bench/weather.py``'s sessions, cached
in DIR; their barometers wander), with the smoothed track's shape (``evaluate``'s, the true pixel) after the height
columns.
"""

from __future__ import annotations

import argparse
import csv
import shlex
import subprocess
import sys
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

from groundstation.session.positions import read_positions_csv
from sim_fixtures.bundle import BUNDLED, BUNDLED_DIR
from sim_fixtures.generate import generate
from sim_fixtures.motion import Motion
from sim_fixtures.scenario import load_scenario, with_overrides

WEATHER = tuple(
    sorted(p.stem for p in (ROOT / "sim_fixtures" / "scenarios").glob("weather_*.toml"))
)
SCENARIOS = (
    "height_rtk_drift",
    "height_rtk_noise",
    "height_gnss_drift",
    "height_rangefinder",
    "height_rangefinder:nothing",
    "height_rangefinder:floor",
    "height_rtk_noise:climb",
    "weather_5mps_rtk:climb",
)
CLIMB_SWING_M = (
    3.0  # ":climb": the hover's slow height changes' amplitude (a 20-s period: up to 0.94 m/s) ...
)
CLIMB_BARO_NOISE_M = 0.03  # ... and the EKF heights' white noise


def scenario(name: str):
    base, _, variant = name.partition(":")
    sc = load_scenario(ROOT / "sim_fixtures" / "scenarios" / f"{base}.toml")
    if variant == "climb":  # climbing and descending at up to 0.9 m/s, a barometer with white noise
        return with_overrides(
            sc, uav={"height_swing_m": CLIMB_SWING_M}, sensors={"baro_noise_m": CLIMB_BARO_NOISE_M}
        )
    return with_overrides(sc, rangefinder={"sees": variant}) if variant else sc


def session(name: str, work: Path) -> Path:
    out = work / name.replace(":", "_")
    if not (out / "uav.tlog").is_file():
        generate(scenario(name), out, video=False)
    return out


def evaluate(skyfix: list[str], cwd: Path, path: Path, out: Path) -> dict:
    """evaluate's refraction row for ``path`` and its positions.csv."""
    subprocess.run(
        [*skyfix, "evaluate", str(path), "--use-track", "--out", str(out), "--quiet"],
        cwd=cwd,
        capture_output=True,
        check=False,
    )
    with open(out / "evaluation.csv", newline="") as f:
        row = next(r for r in csv.DictReader(f) if r["method"] == "refraction")
    return {
        "mae_m": float(row["mae_m"]),
        "in_2sigma": float(row["within_2sigma"]),
        "smoothed_shape_m": float(row["smoothed_shape_m"]),
        "positions": read_positions_csv(out / path.name / "refraction" / "positions.csv"),
    }


def height_columns(name: str, pos) -> str:
    sc = scenario(name)
    true_h = -Motion(sc).camera_ned(np.arange(len(pos.t_unix)) / sc.fps)[:, 2]  # frame i at i / fps
    err, sigma = pos.height_m - true_h, pos.sigma_height_m
    ok = np.isfinite(err)
    step = np.diff(err)
    words = ", ".join(
        f"{w} {n / ok.sum():.0%}" for w, n in Counter(pos.height_source[ok]).most_common()
    )
    return (
        f"{np.mean(np.abs(err[ok])):7.3f} {np.max(np.abs(err[ok])):7.3f} {np.std(err[ok]):7.4f} "
        f"{np.sqrt(np.nanmean(step**2)):7.4f} "
        f"{np.mean(np.abs(err[ok]) <= 2 * sigma[ok]):6.1%} {np.median(sigma[ok]):6.3f}  {words}"
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", default="/tmp/skyfix-height")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "height.txt"))
    ap.add_argument(
        "--skyfix",
        help="another skyfix to compare, e.g. '/old/.venv/bin/python -m groundstation.cli'",
    )
    ap.add_argument("--skyfix-cwd", default=str(ROOT))
    ap.add_argument("--only", nargs="*")
    ap.add_argument(
        "--weather", type=Path, help="the weather sessions' directory (bench/weather.py --work)"
    )
    args = ap.parse_args()
    work = Path(args.work)
    runs = [("after", [sys.executable, "-m", "groundstation.cli"], ROOT)]
    if args.skyfix:
        runs.insert(0, ("before", shlex.split(args.skyfix), Path(args.skyfix_cwd)))
    names = args.only or (WEATHER if args.weather else SCENARIOS)
    header = (
        f"{'scenario':28s} {'run':6s} {'MAE m':>7s} {'in 2h':>6s}  {'|dh| m':>7s} {'max dh':>7s} {'dh sd':>7s} {'dh step':>7s} "
        f"{'in 2σh':>6s} {'σh med':>6s}  height source"
    )
    lines = [header]
    if args.weather:
        lines[0] += "  smoothed shape m"
    for name in names:
        path = args.weather / name if args.weather else session(name, work)
        for label, skyfix, cwd in runs:
            r = evaluate(skyfix, cwd, path, work / label / path.name)
            lines.append(
                f"{name:28s} {label:6s} {r['mae_m']:7.4f} {r['in_2sigma']:6.1%}  "
                + height_columns(name, r["positions"])
                + (f"  {r['smoothed_shape_m']:.4f}" if args.weather else "")
            )
            print(lines[-1], flush=True)
    for name in BUNDLED if not (args.only or args.weather) else ():
        for label, skyfix, cwd in runs:
            r = evaluate(skyfix, cwd, BUNDLED_DIR / name, work / label / "bundled")
            lines.append(
                f"{'bundled/' + name:28s} {label:6s} {r['mae_m']:7.4f} {r['in_2sigma']:6.1%}"
            )
            print(lines[-1], flush=True)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"-> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

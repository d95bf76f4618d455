"""A reference of known position in view (a surveyed marker on the seafloor, ``[marker]``, or a buoy drifting on the
surface that reports its RTK GNSS over MAVLink, ``[buoy]``): the fixes' absolute error without and with the offset it
gives (:mod:`localizer.reference`, ``skyfix process --reference``).

    .venv/bin/python bench/reference.py [--duration 120] [--fps 5] [--pixel-sigma 0.5] [--rendered-s 8]
                                        [--references marker,buoy]
                                        [--work /tmp/skyfix-reference] [--out bench/results/reference.txt]

The buoy's position at each sighting is where its GNSS reports in uav.tlog put it (interpolated, time-aligned:
:func:`groundstation.offline.reference.buoy_track`), as ``skyfix process`` takes it; the RTK drones' rows without a
reference are what the plain drones' rows with one are to approach.

Geometry only, for each scenario (plain GNSS and RTK drones with the AHRS and compass biases of ``sensors_*``, the
UUV's true pixel from track.csv): the marker's pixel is the simulator's (reference_track.csv) plus a detector's white
error of ``--pixel-sigma`` px per axis: what the offset does once the marker is found. Rendered: the plain-GNSS nadir
drone for ``--rendered-s`` seconds at 30 fps, the marker found in the video as ``skyfix process`` does
(:mod:`groundstation.offline.reference`), with its pixel error against reference_track.csv.

Printed per row: fixes, absolute MAE and the shape's MAE (after the best constant offset) of the UUV's fixes, the
share within 2·h_acc and the median h_acc, without and with the reference.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

import claim_calibration as claim

from groundstation.offline import process
from groundstation.offline.evaluate import error_ne_m, shape_m
from groundstation.offline.reference import Buoy, buoy_track, read_reference, sigma_seen
from groundstation.offline.reference import apply as apply_reference
from groundstation.offline.reference import sightings as marker_sightings
from groundstation.session.read import load_session, read_table
from localizer.pose import camera_pose
from localizer.reference import applied, correct, offsets, sightings
from sim_fixtures.generate import generate
from sim_fixtures.marker import REFERENCE_TRACK_CSV
from sim_fixtures.scenario import load_scenario, with_overrides

SCENARIOS = (
    "sensors_plain_nadir",
    "sensors_plain_oblique",
    "sensors_rtk_nadir",
    "sensors_rtk_oblique",
)


def marker_track(path: Path, rng, pixel_sigma: float):
    """The marker's times and pixels from the session's reference_track.csv (the simulator's), plus a detector's
    white error of ``pixel_sigma`` px per axis."""
    tr = read_table(path / REFERENCE_TRACK_CSV, ("t", "u", "v"), allow_empty=("u", "v"))
    noise = rng.normal(0.0, pixel_sigma, (2, len(tr["t"])))
    return tr["t"], tr["u"] + noise[0], tr["v"] + noise[1]


def reference_offsets(s, path: Path, rng, pixel_sigma: float, t_fix):
    """The offset at the fixes' times ``t_fix`` from the reference's simulator pixel (+ noise, :func:`marker_track`):
    the surveyed marker, or the buoy where its reports put it at each sighting."""
    cal, tel = s.calibration, s.telemetry
    t_m, u_m, v_m = marker_track(path, rng, pixel_sigma)
    ref, _ = read_reference(s)
    at = buoy_track(s, ref)[0](t_m) if isinstance(ref, Buoy) else ref
    off, seen, jac = sightings(cal, camera_pose(cal, tel, t_m), u_m, v_m, at)
    return offsets(t_m[seen], off[seen], jac[seen], t_fix, sigma_seen(at, seen))


def row(err, h_acc) -> tuple:
    ok = np.isfinite(err[:, 0])
    e = np.hypot(*err[ok].T)
    return (
        float(np.mean(e)),
        shape_m(err),
        float(np.mean(e <= 2 * h_acc[ok])),
        float(np.median(h_acc[ok])),
    )


def errors(s, fixes) -> np.ndarray:
    return error_ne_m(fixes.t_unix, fixes.lat, fixes.lon, fixes.status == "ok", s.truth)


def line(name: str, s, fixes, better, note: str) -> str:
    b, a = row(errors(s, fixes), fixes.h_acc_m), row(errors(s, better), better.h_acc_m)
    ok = fixes.status == "ok"
    return (
        f"{name:24s} {int(ok.sum()):6d}  {b[0]:.3f} {b[1]:.3f} {100 * b[2]:5.1f} % {b[3]:.3f}   "
        f"{a[0]:.3f} {a[1]:.3f} {100 * a[2]:5.1f} % {a[3]:.3f}   {note}"
    )


def geometry_only(name: str, args, work: Path, kind: str = "marker") -> str:
    """The reference's pixel the simulator's (+ noise): what the offset does once it is found; ``kind`` the
    scenario's table of it (``marker`` or ``buoy``)."""
    sc = load_scenario(ROOT / "sim_fixtures" / "scenarios" / f"{name}.toml")
    sc = with_overrides(sc, duration_s=args.duration, fps=args.fps, **{kind: {"enabled": True}})
    out = work / kind / name
    generate(sc, out, video=False)
    s = load_session(out)
    fixes = process.process_session(s, use_track=True)
    cal, tel = s.calibration, s.telemetry
    found = reference_offsets(s, out, np.random.default_rng(7), args.pixel_sigma, fixes.t_unix)
    better = correct(cal, camera_pose(cal, tel, fixes.t_unix), fixes, found)
    have = np.isfinite(found.offset_ne_m[:, 0]) & (fixes.status == "ok")
    taken = applied(fixes, better)
    return line(
        name,
        s,
        fixes,
        better,
        f"offset {100 * have.mean():.0f} %, taken (a smaller claim) {100 * taken.mean():.0f} %",
    )


def population(name: str, args, work: Path, kind: str = "marker") -> str:
    """``--seeds`` drones of the platform (biases drawn as bench/claim_calibration.py draws them, its platform's
    sigmas in ``[uncertainty]``, the UUV's true pixel) with the marker's simulator pixel: the pooled share within
    2·h_acc and within h_acc, and RMS error over RMS h_acc, without and with the reference."""
    base = load_scenario(ROOT / "sim_fixtures" / "scenarios" / f"{name}.toml")
    pooled = {"without": ([], []), "with": ([], [])}
    for seed in range(args.seeds):
        sc = with_overrides(
            base,
            name=f"{name}_s{seed}",
            seed=1000 + seed,
            duration_s=args.population_s,
            fps=2.0,
            sensors={**claim.draw_sensors(seed, args.seeds), "gnss_mode": base.sensors.gnss_mode},
            **{kind: {"enabled": True}},
        )
        out = work / kind / "population" / f"{name}_s{seed}"
        generate(sc, out, video=False)
        s = load_session(out)
        s.calibration = claim.platform_claim(s.calibration, 0.0)
        fixes = process.process_session(s, use_track=True)
        cal, tel = s.calibration, s.telemetry
        rng = np.random.default_rng(seed)
        found = reference_offsets(s, out, rng, args.pixel_sigma, fixes.t_unix)
        better = correct(cal, camera_pose(cal, tel, fixes.t_unix), fixes, found)
        for key, f in (("without", fixes), ("with", better)):
            e = errors(s, f)
            ok = np.isfinite(e[:, 0])
            pooled[key][0].append(np.hypot(*e[ok].T))
            pooled[key][1].append(f.h_acc_m[ok])
    cells = []
    for key in ("without", "with"):
        err, acc = (np.concatenate(x) for x in pooled[key])
        ratio = np.sqrt(np.mean(err**2)) / np.sqrt(np.mean(acc**2))
        cells.append(
            f"{100 * np.mean(err <= 2 * acc):5.1f} % {100 * np.mean(err <= acc):5.1f} % {ratio:.2f}"
        )
    return f"{name:24s} {args.seeds:3d} x {args.population_s:g} s   " + "   ".join(cells)


def rendered(
    args, work: Path, kind: str = "marker", scene: str = "sensors_plain_nadir", seconds=None
) -> str:
    """``scene`` rendered with the reference for ``seconds`` (``--rendered-s``) at 30 fps: skyfix process's
    --reference auto finds it in the video."""
    seconds = args.rendered_s if seconds is None else seconds
    sc = load_scenario(ROOT / "sim_fixtures" / "scenarios" / f"{scene}.toml")
    sc = with_overrides(sc, duration_s=seconds, fps=30.0, **{kind: {"enabled": True}})
    label = "rendered_plain_nadir" if scene == "sensors_plain_nadir" else f"rendered_{scene}"
    out = work / kind / label
    generate(sc, out)
    s = load_session(out)
    fixes = process.process_session(s, use_track=True)
    ref, radius_m = read_reference(s)
    t, u, v = marker_sightings(s, buoy_track(s, ref)[0] if isinstance(ref, Buoy) else ref, radius_m)
    better, _ = apply_reference(s, fixes, "auto")
    truth = read_table(out / REFERENCE_TRACK_CSV, ("t", "u", "v"), allow_empty=("u", "v"))
    seen = np.isfinite(u)
    i = np.searchsorted(truth["t"], t[seen])
    miss = np.hypot(u[seen] - truth["u"][i], v[seen] - truth["v"][i])
    note = f"found {seen.sum()}/{len(u)}, pixel error median {np.median(miss):.2f} max {miss.max():.2f} px"
    return line(f"{label} {seconds:g}s", s, fixes, better, note)


TABLES = {
    "marker": "[marker] on the seafloor (its defaults)",
    "buoy": "[buoy] drifting on the surface, RTK GNSS over MAVLink (its defaults)",
}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--duration", type=float, default=120.0)
    p.add_argument("--fps", type=float, default=5.0)
    p.add_argument("--pixel-sigma", type=float, default=0.5)
    p.add_argument("--rendered-s", type=float, default=8.0)
    p.add_argument(
        "--seeds", type=int, default=20, help="drones per scenario in the population rows"
    )
    p.add_argument("--population-s", type=float, default=60.0)
    p.add_argument(
        "--waves-s",
        type=float,
        default=4.0,
        help="the buoy also rendered on WAVES_SCENE (a floating deck is seen through the air): this long; 0: not",
    )
    p.add_argument("--waves-scene", default="weather_5mps_plain")
    p.add_argument(
        "--references",
        default="marker,buoy",
        help="which references, comma-separated: marker, buoy",
    )
    p.add_argument("--work", type=Path, default=Path("/tmp/skyfix-reference"))
    p.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "reference.txt")
    args = p.parse_args()
    lines = []

    def say(text: str) -> None:
        print(text, flush=True)
        lines.append(text)

    for kind in args.references.split(","):
        say(
            f"{TABLES[kind]}; geometry only: its pixel the simulator's + {args.pixel_sigma:g} px "
            f"white, {args.duration:g} s at {args.fps:g} fps; rendered: found in the video; UUV: true pixel\n"
            f"{'scenario':24s} {'fixes':>6s}  without: MAE shape in2sig h_acc   with: MAE shape in2sig h_acc"
        )
        for name in SCENARIOS:
            say(geometry_only(name, args, args.work, kind))
        say(rendered(args, args.work, kind))
        if kind == "buoy" and args.waves_s > 0:
            say(rendered(args, args.work, kind, args.waves_scene, args.waves_s))
        say(
            f"population ({kind}): {args.seeds} drones per scenario, biases drawn as bench/claim_calibration.py's "
            "platform, its sigmas in [uncertainty]\n"
            f"{'scenario':24s} {'drones':>12s}   without: in2sig in1sig rms_ratio   with: in2sig in1sig rms_ratio"
        )
        for name in SCENARIOS:
            say(population(name, args, args.work, kind))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())

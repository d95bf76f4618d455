"""A reference of known position in view (a surveyed marker on the seafloor): the fixes' absolute error without and
with the offset it gives (:mod:`localizer.reference`).

    .venv/bin/python bench/reference.py [--duration 120] [--fps 5] [--pixel-sigma 0.5] [--work /tmp/skyfix-reference]
                                        [--out bench/results/reference.txt]

For each scenario (plain GNSS and RTK drones with the AHRS and compass biases of ``sensors_*``; geometry only, the
UUV's true pixel from track.csv) a marker lies on the seafloor :data:`MARKER_NE_M` from the UUV's path centre; its
pixel in every frame is the simulator's own (the light's surface crossing projected by OpenCV,
:func:`sim_fixtures.generate.reference_pixel`, with the true pose), plus a detector's white error of
``--pixel-sigma`` px per axis; its surveyed position is the simulator's truth. The marker is not found in the
image here (no detector yet): this measures what the offset does once it is.

Printed per scenario: fixes, absolute MAE and the shape's MAE (after the best constant offset) of the UUV's fixes,
the share within 2·h_acc and the median h_acc, without and with the reference; the offset found (median) against
the true one (mean error of the fixes without it).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from groundstation.offline import process
from groundstation.offline.evaluate import error_ne_m, shape_m
from groundstation.session.read import load_session
from localizer.fix import locate
from localizer.pose import camera_pose
from localizer.reference import Reference, corrected, offsets, sightings
from sim_fixtures.generate import camera_of, frame_truth, generate, reference_pixel
from sim_fixtures.geometry import ned_to_geodetic
from sim_fixtures.motion import Motion
from sim_fixtures.scenario import load_scenario, with_overrides

SCENARIOS = (
    "sensors_plain_nadir",
    "sensors_plain_oblique",
    "sensors_rtk_nadir",
    "sensors_rtk_oblique",
)
MARKER_NE_M = (1.5, -1.0)  # from the UUV's path centre, on the seafloor


def marker_pixels(sc, rng, pixel_sigma: float):
    """The marker's world NED point, its WGS84 position and its pixel per frame (NaN outside the image)."""
    camera = camera_of(sc)
    truth = frame_truth(sc, Motion(sc), camera)
    point = np.array(
        [sc.uuv.north_m + MARKER_NE_M[0], sc.uuv.east_m + MARKER_NE_M[1], sc.site.floor_depth_m]
    )
    u, v = reference_pixel(
        camera,
        truth.R_ned_from_cv,
        truth.camera_ned,
        np.broadcast_to(point, truth.camera_ned.shape),
        sc.site.refractive_index,
    )
    u = u + rng.normal(0.0, pixel_sigma, len(u))
    v = v + rng.normal(0.0, pixel_sigma, len(v))
    inside = (u >= 0) & (u <= camera.width - 1) & (v >= 0) & (v <= camera.height - 1)
    lat, lon, _ = ned_to_geodetic(point, sc.site.lat_deg, sc.site.lon_deg, 0.0)
    return truth.t_unix, np.where(inside, u, np.nan), np.where(inside, v, np.nan), lat, lon


def row(err, h_acc) -> tuple:
    ok = np.isfinite(err[:, 0])
    e = np.hypot(*err[ok].T)
    return (
        float(np.mean(e)),
        shape_m(err),
        float(np.mean(e <= 2 * h_acc[ok])),
        float(np.median(h_acc[ok])),
    )


def run(name: str, args, work: Path) -> str:
    sc = load_scenario(ROOT / "sim_fixtures" / "scenarios" / f"{name}.toml")
    sc = with_overrides(sc, duration_s=args.duration, fps=args.fps)
    out = work / name
    generate(sc, out, video=False)
    s = load_session(out)
    fixes = process.process_session(s, use_track=True)
    ok = fixes.status == "ok"
    err = error_ne_m(fixes.t_unix, fixes.lat, fixes.lon, ok, s.truth)
    t_m, u_m, v_m, lat_m, lon_m = marker_pixels(sc, np.random.default_rng(7), args.pixel_sigma)
    cal, tel = s.calibration, s.telemetry
    ref = Reference(float(lat_m), float(lon_m), sc.site.floor_depth_m)
    off, seen = sightings(cal, camera_pose(cal, tel, t_m), u_m, v_m, ref)
    found = offsets(t_m[seen], off[seen], fixes.t_unix)
    pose = camera_pose(cal, tel, fixes.t_unix)
    quiet = dataclasses.replace(pose, sigma_uav_m=np.zeros(len(pose.t_unix)))
    without = locate(cal, quiet, fixes.u, fixes.v)
    better = corrected(fixes, without, found)
    err2 = error_ne_m(better.t_unix, better.lat, better.lon, ok, s.truth)
    have = np.isfinite(found.offset_ne_m[:, 0]) & ok
    true_off = -np.nanmean(err[have], axis=0)
    got = np.median(found.offset_ne_m[have], axis=0)
    b, a = row(err, fixes.h_acc_m), row(err2, better.h_acc_m)
    return (
        f"{name:24s} {int(ok.sum()):6d}  {b[0]:.3f} {b[1]:.3f} {100 * b[2]:5.1f} % {b[3]:.3f}   "
        f"{a[0]:.3f} {a[1]:.3f} {100 * a[2]:5.1f} % {a[3]:.3f}   "
        f"{got[0]:+.3f}/{got[1]:+.3f} vs {true_off[0]:+.3f}/{true_off[1]:+.3f}  {100 * have.mean():.0f} %"
    )


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--duration", type=float, default=120.0)
    p.add_argument("--fps", type=float, default=5.0)
    p.add_argument("--pixel-sigma", type=float, default=0.5)
    p.add_argument("--work", type=Path, default=Path("/tmp/skyfix-reference"))
    p.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "reference.txt")
    args = p.parse_args()
    head = (
        f"marker {MARKER_NE_M} m from the UUV's path centre on the seafloor, its pixel the simulator's "
        f"+ {args.pixel_sigma:g} px white; {args.duration:g} s at {args.fps:g} fps; UUV: true pixel\n"
        f"{'scenario':24s} {'fixes':>6s}  without: MAE shape in2sig h_acc   with: MAE shape in2sig h_acc   "
        "offset found N/E vs true  corrected"
    )
    print(head, flush=True)
    lines = [head]
    for name in SCENARIOS:
        line = run(name, args, args.work)
        print(line, flush=True)
        lines.append(line)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The smoothed offline track's error budget: which of the drone's errors make its shape, with the true pixel.

    .venv/bin/python bench/smoothed_budget.py [--work /tmp/skyfix-weather] [--out bench/results/smoothed_budget.txt]
                                              [--only NAME ...] [--pixels true tracked]

For each weather session (``bench/weather.py``'s, generated into ``--work`` if missing) the true pixel (track.csv) is
located as ``evaluate --use-track`` locates it and smoothed as ``positions_smoothed.csv`` is
(:func:`groundstation.offline.smoothed.offline_track`). Each fix's error is split into the scene's terms, each a
per-frame series of north-east metres: the waves' own error (``truth_waves.csv``); the camera's attitude error
(``truth_errors.csv``'s rotation vector through :func:`localizer.reference.pose_jacobian`), split into its tilt
(gimbal levelling, or the AHRS's tilt: North and East) and its heading (compass: Down), and each into its value at
the first frame (a bias) and its change since (the wander); the camera height's error (skyfix's height against
the simulator's camera) and the depth's, through their own sensitivities; the UAV's reported position against its
truth (the EKF's walk and white noise); and what is left (the video/telemetry time offset, the pose's white noise,
the sensitivities' second order). The smoother is linear in its positions
(:func:`localizer.smooth.through_smoother`), so the smoothed error is the sum of each term through it plus the
smoother's own lag on the UUV's true motion. Per term: the RMS about its mean per frame (``raw``) and smoothed
(``smoothed``), the smoothed term's shape alone (MAE after the best constant offset, evaluate's) and the smoothed
track's shape without it (``without``: what removing that term alone would leave). The last row checks the sum: the smoothed track's shape as evaluate scores it.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

from waves import session as generated

from groundstation.offline.evaluate import error_ne_m, shape_m
from groundstation.offline.process import frame_pixels, locate_frames, located
from groundstation.offline.smoothed import offline_track
from groundstation.session.read import load_session, read_table
from localizer.fix_gate import MAX_ACCEL_MPS2, MAX_SPEED_MPS
from localizer.geodesy import geodetic_to_ned
from localizer.pose import camera_pose
from localizer.ray import pixel_to_offset
from localizer.reference import pose_jacobian
from localizer.smooth import through_smoother
from sim_fixtures.generate import TRUTH_WAVES_CSV
from sim_fixtures.motion import Motion
from sim_fixtures.scenario import load_scenario

SCENARIOS = sorted(p.stem for p in (ROOT / "sim_fixtures" / "scenarios").glob("weather_*.toml"))
ERRORS = ("cam_err_n_deg", "cam_err_e_deg", "cam_err_d_deg", "north_err_m", "east_err_m")
BOUNDS = (MAX_SPEED_MPS["bluerov2"], MAX_ACCEL_MPS2["bluerov2"])
_DEPTH = 1e-3  # m, the depth's finite difference
#: constant acceleration bounds (m/s²) tried in place of the data's (the smoother's window)
CONSTANT_ACCEL_MPS2 = (0.3, 0.5, 0.7, 1.0)


def terms(path: Path) -> tuple[dict[str, np.ndarray], np.ndarray, object, np.ndarray, dict]:
    """The per-frame error terms (name -> N×2 m), the fixes' total error (N×2), the fixes, the truth's north-east
    (N×2, m from the site's origin) and the session's truth."""
    session = load_session(path)
    sc = load_scenario(path / "scenario.toml")
    pixels = frame_pixels(session, True)
    fixes = locate_frames(session, pixels, True)
    t, u, v = pixels[:3]
    pose = camera_pose(session.calibration, session.telemetry, t)
    truth = session.truth
    err = error_ne_m(fixes.t_unix, fixes.lat, fixes.lon, fixes.status == "ok", truth)
    tau = t - truth["t"][0]
    motion = Motion(sc)
    ref = (sc.site.lat_deg, sc.site.lon_deg)

    cols = read_table(path / "truth_errors.csv", ("t", *ERRORS))
    rot = np.radians(np.column_stack([np.interp(t, cols["t"], cols[c]) for c in ERRORS[:3]]))
    J = pose_jacobian(session.calibration, pose, u, v, pose.depth_m)  # N×2×4
    out = {}
    waves = read_table(path / TRUTH_WAVES_CSV, ("t", "wave_dn_m", "wave_de_m"))
    out["waves"] = np.column_stack(
        [np.interp(t, waves["t"], waves[c]) for c in ("wave_dn_m", "wave_de_m")]
    )
    tilt, yaw = rot * [1, 1, 0], rot * [0, 0, 1]
    for name, r in (("tilt", tilt), ("heading", yaw)):
        out[f"{name} bias"] = np.einsum("nij,j->ni", J[:, :, :3], r[0])
        out[f"{name} wander"] = np.einsum("nij,nj->ni", J[:, :, :3], r - r[0])
    true_h = -motion.camera_ned(tau)[:, 2]
    out["height"] = J[:, :, 3] * (pose.height_m - true_h)[:, None]
    true_depth = np.interp(t, truth["t"], truth["depth_m"])
    n_water = session.calibration.water.refractive_index
    base, _ = pixel_to_offset(
        session.calibration.camera, pose.R_ned_from_cv, u, v, pose.height_m, pose.depth_m, n_water
    )
    deeper, _ = pixel_to_offset(
        session.calibration.camera,
        pose.R_ned_from_cv,
        u,
        v,
        pose.height_m,
        pose.depth_m + _DEPTH,
        n_water,
    )
    out["depth"] = (deeper - base) / _DEPTH * (pose.depth_m - true_depth)[:, None]
    n, e, _ = geodetic_to_ned(pose.lat_deg, pose.lon_deg, 0.0, *ref, 0.0)
    out["UAV position"] = np.column_stack([n, e]) - motion.uav_ned(tau)[:, :2]
    out["rest (time, 2nd order)"] = err - sum(out.values())
    lat_t = np.interp(t, truth["t"], truth["lat"])
    lon_t = np.interp(t, truth["t"], truth["lon"])
    tn, te, _ = geodetic_to_ned(lat_t, lon_t, 0.0, *ref, 0.0)
    return out, err, fixes, np.column_stack([tn, te]), truth


def rms_about_mean(x: np.ndarray) -> float:
    x = x[np.all(np.isfinite(x), axis=1)]
    return float(np.sqrt(np.mean(np.sum((x - x.mean(axis=0)) ** 2, axis=1)))) if len(x) else np.nan


def tracked(path: Path, parts: dict, err: np.ndarray, truth: dict) -> tuple[object, np.ndarray]:
    """The tracked video's fixes as ``evaluate`` smooths them (tracked both ways, the frames traced back included)
    and their error (N×2); adds the tracked pixel's own term to ``parts`` (their error less the true pixel's ``err``,
    the same frames and telemetry)."""
    session = load_session(path)
    _, fixes, _ = located(session, frame_pixels(session, False, both_ways=True), True, None, "auto")
    err_tracked = error_ne_m(fixes.t_unix, fixes.lat, fixes.lon, fixes.status == "ok", truth)
    parts["tracked pixel"] = err_tracked - err
    return fixes, err_tracked


def budget(path: Path, pixels: str = "true") -> list[str]:
    parts, err, fixes, truth_ne, truth = terms(path)
    if pixels == "tracked":
        fixes, err = tracked(path, parts, err, truth)
    smoothed, _ = offline_track(fixes, *BOUNDS)
    taken = smoothed.ok & (smoothed.gap_s == 0)
    through = {k: through_smoother(fixes, taken, smoothed, BOUNDS[0], x) for k, x in parts.items()}
    through["smoother's lag"] = (
        through_smoother(fixes, taken, smoothed, BOUNDS[0], truth_ne) - truth_ne
    )
    sm_err = error_ne_m(fixes.t_unix, smoothed.lat, smoothed.lon, smoothed.ok, truth)
    lines = []
    total = sum(through.values())
    for k, x in through.items():
        raw = rms_about_mean(parts[k]) if k in parts else float("nan")
        lines.append(
            f"  {k:24s} {raw:8.4f} {rms_about_mean(x):8.4f} {shape_m(x):8.4f} {shape_m(total - x):8.4f}"
        )
    lines.append(
        f"  {'sum of the terms':24s} {rms_about_mean(err):8.4f} {rms_about_mean(total):8.4f} "
        f"{shape_m(total):8.4f}"
    )
    lines.append(
        f"  {'smoothed track (evaluate)':24s} {'':8s} {rms_about_mean(sm_err):8.4f} "
        f"{shape_m(sm_err):8.4f}   in 2σ {np.mean(np.hypot(*sm_err[smoothed.ok].T) <= 2 * smoothed.h_acc_m[smoothed.ok]):.1%}"
    )
    slow = total - through["waves"] - through["smoother's lag"]
    lines.append(
        f"  floor: the slow terms alone (no waves, no lag) {shape_m(slow):.4f}; "
        f"without the heading bias too {shape_m(slow - through['heading bias']):.4f}"
    )
    lines.append(
        f"  check: the true track turned about the drone's nadir by the scenario's compass bias, shape "
        f"{shape_m(turned_about_nadir(path, fixes.t_unix - truth['t'][0], truth_ne)):.4f} "
        f"(the heading bias term's raw shape {shape_m(parts['heading bias']):.4f})"
    )
    return lines + window(fixes, taken, smoothed, err, parts["waves"], truth_ne)


def turned_about_nadir(path: Path, tau_s: np.ndarray, truth_ne: np.ndarray) -> np.ndarray:
    """The error (N×2, m) a constant compass bias alone makes, computed apart from the Jacobians: the true track
    turned about the drone's true position by the scenario's ``yaw_bias_deg`` (to first order). Not a constant
    offset where the UUV moves: its shape is the bias times the track's extent."""
    sc = load_scenario(path / "scenario.toml")
    d = truth_ne - Motion(sc).uav_ned(tau_s)[:, :2]
    return np.radians(sc.sensors.yaw_bias_deg) * np.column_stack([-d[:, 1], d[:, 0]])


def window(fixes, taken, smoothed, err, waves, truth_ne) -> list[str]:
    """The smoothed shape, and the waves' and the lag's shapes through the smoother, with the data's acceleration
    bound and with each of :data:`CONSTANT_ACCEL_MPS2` in its place (the same noise share, frames and fixes)."""
    cells = []
    bounds = [("data's", smoothed)] + [
        (f"{a:.1f}", dataclasses.replace(smoothed, accel_mps2=np.full(len(fixes), a)))
        for a in CONSTANT_ACCEL_MPS2
    ]
    for label, sm in bounds:

        def through(x, sm=sm):
            return through_smoother(fixes, taken, sm, BOUNDS[0], x)

        lag = through(truth_ne) - truth_ne
        cells.append(
            f"{label} {shape_m(through(err) + lag):.4f} ({shape_m(through(waves)):.4f}/{shape_m(lag):.4f})"
        )
    return [
        f"  window: acceleration bound (m/s², the data's median {np.median(smoothed.accel_mps2):.2f}) "
        "shape (waves/lag): " + ", ".join(cells)
    ]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", default="/tmp/skyfix-weather")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "smoothed_budget.txt"))
    ap.add_argument("--only", nargs="*")
    ap.add_argument("--pixels", nargs="*", choices=("true", "tracked"), default=["true"])
    args = ap.parse_args()
    head = f"  {'term (m)':24s} {'raw':>8s} {'smoothed':>8s} {'shape':>8s} {'without':>8s}"
    lines = [
        f"# load average (1, 5, 15 min) at the start: {' '.join(f'{x:.2f}' for x in os.getloadavg())}"
    ]
    for name in args.only or SCENARIOS:
        path, _ = generated(name, Path(args.work), False)
        for pixels in args.pixels:
            block = [f"{name} ({pixels} pixel)", head, *budget(path, pixels)]
            lines += block
            print("\n".join(block), flush=True)
    lines.append(f"# load average at the end: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"-> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

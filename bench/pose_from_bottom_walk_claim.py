"""The claim (h_acc) of the fixes whose position the pose from the bottom's walk corrected, against the simulator's
truth: the walk's own error against its sigma, and the claim with the walk's sigma in it (this tree) against the
claim with the GNSS's sigma alone (before) and the walk not applied (the fixes' own positions, the GNSS's sigma).

    .venv/bin/python bench/pose_from_bottom_walk_claim.py --work DIR --only NAME [--draw K] [--out FILE]

One session (bench/pose_from_bottom_claim.py's ``NAME_height`` variants and draws, made in ``--work`` when
missing) per process, the pixel tracked in the video. The three claims share the fit and the fixes' attitude: only
the position and its sigma differ (:meth:`groundstation.offline.bottom.PoseCorrection.sigma_position_m`).
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np
from pose_from_bottom import reported_minus_true
from pose_from_bottom_claim import NAMES, finish, rms, session_of

from groundstation.offline import process
from groundstation.offline.evaluate import error_ne_m
from groundstation.session.read import load_session
from localizer.fix import locate
from localizer.pose import camera_pose


def lines_for(name: str, work: Path, draw: int) -> list[str]:
    twin, path = session_of(name, work, draw)
    label = f"{name}_draw{draw}" if draw else name
    s = load_session(path, "uuv1")
    pixels = process.frame_pixels(s, use_track=False)
    correction = process.bottom_correction(s, pixels, "auto")
    if correction is None:
        return [f"{label}: no pose from the bottom: {'; '.join(s.warnings)}"]
    found = pixels.status == "ok"
    t, u, v = (x[found] for x in pixels[:3])
    sigma_px = None if pixels.sigma_px is None else pixels.sigma_px[found]
    reported = camera_pose(s.calibration, s.telemetry, t)
    pose, cal = correction.apply(s, reported)
    claims = {
        "with the walk's sigma (this tree)": pose,
        "the GNSS's sigma alone (before)": dataclasses.replace(
            pose, sigma_uav_m=reported.sigma_uav_m
        ),
        "the walk not applied": dataclasses.replace(
            pose,
            lat_deg=reported.lat_deg,
            lon_deg=reported.lon_deg,
            sigma_uav_m=reported.sigma_uav_m,
        ),
    }
    te = np.genfromtxt(path / "truth_errors.csv", delimiter=",", names=True)
    at = camera_pose(s.calibration, s.telemetry, te["t"])
    off = reported_minus_true(twin, path, s, None)
    good = np.all(np.isfinite(off), axis=1)
    moved = correction.position_ne_m(at)[good] + off[good]
    walk_err = rms(moved - moved.mean(axis=0))
    sigma_walk = rms(correction.estimate.sigma_walk_at(at.t_unix)[good])
    gnss = off[good].mean(axis=0)
    out = [
        (
            f"{label}: walk's error about the GNSS's mean RMS N/E {walk_err[0]:.4f}/{walk_err[1]:.4f} m (uncorrected "
            f"{rms(off[good] - gnss)[0]:.4f}/{rms(off[good] - gnss)[1]:.4f}) against its 1σ {sigma_walk[0]:.4f}/"
            f"{sigma_walk[1]:.4f}: {walk_err[0] / sigma_walk[0]:.2f}/{walk_err[1] / sigma_walk[1]:.2f}; the GNSS's offset "
            f"N/E {gnss[0]:+.3f}/{gnss[1]:+.3f} m"
        )
    ]
    for what, p in claims.items():
        f = locate(cal, p, u, v, sigma_px=sigma_px)
        err = error_ne_m(f.t_unix, f.lat, f.lon, f.status == "ok", s.truth)
        e = np.hypot(*err.T)
        ok = np.isfinite(e)
        got = rms(err[ok])
        said = np.array([rms(f.sigma_n_m[ok]), rms(f.sigma_e_m[ok])])
        out.append(
            f"{label}: {what}: in 2σ {np.mean(e[ok] <= 2 * f.h_acc_m[ok]):.1%} of {ok.sum()}, h_acc "
            f"{np.median(f.h_acc_m[ok]):.4f} m; error RMS N/E {got[0]:.4f}/{got[1]:.4f} m against 1σ "
            f"{said[0]:.4f}/{said[1]:.4f}: {got[0] / said[0]:.2f}/{got[1] / said[1]:.2f}"
        )
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", type=Path, default=Path("/tmp/skyfix-bottom"))
    ap.add_argument("--only", required=True, choices=NAMES)
    ap.add_argument(
        "--draw", type=int, default=0, help="the variant's sensors drawn again ([sensors] draw)"
    )
    ap.add_argument("--out", type=Path, default=None, help="append the lines to this file")
    args = ap.parse_args()
    lines = lines_for(args.only, args.work, args.draw)
    print("\n".join(lines), flush=True)
    finish(lines, f"{args.only} draw {args.draw}", args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

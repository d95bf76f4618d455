"""What the claim (h_acc) of the fixes with the pose from the bottom is made of, and how sure the estimate is against
the simulator's truth (bench/pose_from_bottom.py's sessions, the true pixel).

    .venv/bin/python bench/pose_from_bottom_claim.py [--work /tmp/skyfix-bottom] --only NAME [--out FILE]

One session per process (``--only``; rendered into ``--work`` when missing, as bench/pose_from_bottom.py does).
``NAME_baro`` is the session again with a barometer's errors drawn (:data:`BARO`: the EKF's heights read high by
0.3 m, with a 0.1 m wander; its ``session.toml`` states them), which bench/pose_from_bottom.py's sessions do not: its
telemetry generated again, its twin's rendered video linked (the video does not depend on the barometer). Per
session, with the estimate applied (``--pose-from-bottom auto``):

- ``claim``: the share of fixes within 2·h_acc, the median h_acc, the error's RMS per axis (north, east) against the
  claimed 1-sigma's RMS (``sigma_n_m``, ``sigma_e_m``) and their ratio (1: calibrated; one session is one draw of the
  biases and the GNSS's offset, so a ratio is one sample of a correlated error, not a distribution);
- ``the height's term alone``: the same claim with the height's term as it was before the estimate's tilt and
  heading per metre of height (:attr:`localizer.bottom.BottomEstimate.bias_per_height_rad`) went into it (base's);
- ``made of``: each input's share of h_acc² (the median over fixes of 1 − h_acc² without it / h_acc²): what the
  estimate put in (``tilt``, ``heading``: its sigmas, :meth:`groundstation.offline.bottom.PoseCorrection.claimed_deg`)
  and what it left as without it (the GNSS, the height, the pixel, the time, the depth);
- ``drawn only``: the same claim without the pixel's sigma (the pixel is the true one) and, but for the ``_baro``
  sessions, the height's (``truth_errors.csv``'s ``height_err_m`` is 0 throughout): whether the terms the session
  does draw are claimed honestly;
- ``estimate``: the attitude error left after the correction (truth_errors.csv's ``cam_err_*`` less the correction
  applied, RMS over frames per NED axis, degrees) against the sigmas h_acc took, and the position: the
  correction's error about the GNSS's mean (the reported position less the true one, :func:`reported_minus_true`,
  plus the correction, about its mean; RMS per axis) against the walk's 1-sigma (RMS over frames), the GNSS's offset
  (its mean) against its claimed 1-sigma per axis (``sigma_uav_m`` / √2).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
from pathlib import Path

import numpy as np
from pose_from_bottom import SESSIONS, reported_minus_true, scenario_of, session

from groundstation.offline import process
from groundstation.offline.evaluate import error_ne_m
from groundstation.session.read import load_session
from localizer.fix import locate
from localizer.pose import camera_pose
from sim_fixtures.generate import generate
from sim_fixtures.scenario import with_overrides

ROOT = Path(__file__).resolve().parents[1]
#: the inputs whose share of h_acc² is printed: (name, the calibration's sigmas set to 0, the pose's)
TERMS = (
    ("tilt", {"tilt_deg": 0.0}, ()),
    ("heading", {"yaw_deg": 0.0}, ()),
    ("GNSS", {}, ("sigma_uav_m",)),
    ("height", {"height_m": 0.0}, ("sigma_height_m",)),
    ("pixel", {"pixel_px": 0.0}, ()),
    ("time", {"time_s": 0.0}, ("sigma_time_s",)),
    ("depth", {"depth_m": 0.0}, ("sigma_depth_m",)),
)
#: the barometer's errors of the ``_baro`` sessions (:func:`with_overrides` keys)
BARO = {"uav": {"baro_bias_m": 0.3}, "sensors": {"baro_wander_m": 0.1}}


def not_drawn(name: str) -> tuple[str, ...]:
    """The :data:`TERMS` the session ``name`` does not draw."""
    return ("pixel",) if name.endswith("_baro") else ("height", "pixel")


def session_of(name: str, work: Path) -> tuple[str, Path]:
    """The twin's name (the session without ``_baro``) and the session's folder (made when missing)."""
    twin = name.removesuffix("_baro")
    path = session(twin, work, None)
    if twin == name:
        return twin, path
    out = work / name
    if not (out / "video.mp4").exists():
        generate(with_overrides(scenario_of(twin, None), name=name, **BARO), out, video=False)
        (out / "video.mp4").symlink_to((path / "video.mp4").resolve())
    return twin, out


def without(cal, pose, names):
    """The calibration and the pose with the sigmas of the :data:`TERMS` named ``names`` at 0."""
    sigmas, fields = {}, {}
    for name, cal_sigmas, pose_sigmas in TERMS:
        if name in names:
            sigmas.update(cal_sigmas)
            fields.update({f: np.zeros_like(getattr(pose, f)) for f in pose_sigmas})
    return (
        dataclasses.replace(cal, sigmas=dataclasses.replace(cal.sigmas, **sigmas)),
        dataclasses.replace(pose, **fields),
    )


def rms(x, axis=0):
    return np.sqrt(np.nanmean(np.square(x), axis=axis))


def claim_line(fixes, err) -> tuple[str, np.ndarray]:
    """The claim's cells and the rows it was scored on."""
    e = np.hypot(*err.T)
    ok = np.isfinite(e)
    got = rms(err[ok])
    said = np.array([rms(fixes.sigma_n_m[ok]), rms(fixes.sigma_e_m[ok])])
    ratio = got / said
    return (
        f"in 2σ {np.mean(e[ok] <= 2 * fixes.h_acc_m[ok]):4.0%}, h_acc {np.median(fixes.h_acc_m[ok]):.3f} m; "
        f"error RMS N/E {got[0]:.4f}/{got[1]:.4f} m, claimed 1σ {said[0]:.4f}/{said[1]:.4f} m: "
        f"ratio {ratio[0]:.2f}/{ratio[1]:.2f}"
    ), ok


def lines_for(name: str, work: Path) -> list[str]:
    twin, path = session_of(name, work)
    s = load_session(path, "uuv1")
    pixels = process.frame_pixels(s, use_track=True)
    correction = process.bottom_correction(s, pixels, "auto")
    if correction is None:
        return [f"{name}: no pose from the bottom: {'; '.join(s.warnings)}"]
    t, u, v = pixels[:3]
    pose, cal = correction.apply(s, camera_pose(s.calibration, s.telemetry, t))

    def fixes_of(names=(), p=pose):
        c, p = without(cal, p, names)
        f = locate(c, p, u, v)
        return f, error_ne_m(f.t_unix, f.lat, f.lon, f.status == "ok", s.truth)

    fixes, err = fixes_of()
    said, ok = claim_line(fixes, err)
    alone = dataclasses.replace(
        pose, rotation_per_height_ned=np.zeros_like(pose.rotation_per_height_ned)
    )
    before, _ = claim_line(*fixes_of(p=alone))
    per_m = np.degrees(correction.estimate.bias_per_height_rad)
    shares = []
    for term, _, _ in TERMS:
        other, _ = fixes_of((term,))
        share = 1.0 - (other.h_acc_m[ok] / fixes.h_acc_m[ok]) ** 2
        shares.append(f"{term} {np.median(share):.1%}")
    drawn, _ = claim_line(*fixes_of(not_drawn(name)))

    te = np.genfromtxt(path / "truth_errors.csv", delimiter=",", names=True)
    at = camera_pose(s.calibration, s.telemetry, te["t"])
    err_ned = np.column_stack([te["cam_err_n_deg"], te["cam_err_e_deg"], te["cam_err_d_deg"]])
    left_deg = rms(err_ned - np.degrees(correction.error_rotvec(s, at)))
    claimed = correction.claimed_deg()
    off = reported_minus_true(twin, path, s, None)
    good = np.all(np.isfinite(off), axis=1)
    moved = correction.position_ne_m(at)[good] + off[good]
    sigma_walk = rms(correction.estimate.sigma_walk_at(at.t_unix))
    sigma_uav = float(np.nanmedian(at.sigma_uav_m)) / np.sqrt(2.0)
    gnss = off[good].mean(axis=0)
    return [
        f"{name}: claim: {said}",
        (
            f"{name}: the height's term alone (the claim before the fit's tilt and heading per metre of "
            f"height, {per_m[0]:+.2f}/{per_m[1]:+.2f}/{per_m[2]:+.2f}°, went with it): {before}"
        ),
        f"{name}: made of: " + ", ".join(shares),
        f"{name}: drawn only (no {', no '.join(not_drawn(name))} sigma): {drawn}",
        (
            f"{name}: estimate: attitude left RMS N/E/D {left_deg[0]:.3f}/{left_deg[1]:.3f}/{left_deg[2]:.3f}° "
            f"against tilt ± {claimed['tilt_deg'] or float('nan'):.3f}°, heading ± "
            f"{claimed['yaw_deg'] or float('nan'):.3f}° in h_acc (the estimate's {np.degrees(correction.estimate.sigma_tilt_rad):.3f}°, "
            f"{np.degrees(correction.estimate.sigma_yaw_rad):.3f}°); position about the GNSS's mean RMS N/E "
            f"{rms(moved - moved.mean(axis=0))[0]:.4f}/{rms(moved - moved.mean(axis=0))[1]:.4f} m (uncorrected "
            f"{rms(off[good] - gnss)[0]:.4f}/{rms(off[good] - gnss)[1]:.4f}) against the walk's 1σ "
            f"{sigma_walk[0]:.4f}/{sigma_walk[1]:.4f}; the GNSS's offset N/E {gnss[0]:+.3f}/{gnss[1]:+.3f} m against "
            f"its 1σ {sigma_uav:.3f} per axis"
        ),
    ]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", type=Path, default=Path("/tmp/skyfix-bottom"))
    ap.add_argument("--only", required=True, choices=[*SESSIONS, *(f"{n}_baro" for n in SESSIONS)])
    ap.add_argument("--out", type=Path, default=None, help="append the lines to this file")
    args = ap.parse_args()
    lines = lines_for(args.only, args.work)
    lines.append(f"({args.only}: load average {' '.join(f'{x:.1f}' for x in os.getloadavg())})")
    print("\n".join(lines), flush=True)
    if args.out:
        with open(args.out, "a") as f:
            f.write("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

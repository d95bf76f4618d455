"""What the claim (h_acc) of the fixes with the pose from the bottom is made of, and how sure the estimate is against
the simulator's truth (bench/pose_from_bottom.py's sessions, the true pixel or the tracked one).

    .venv/bin/python bench/pose_from_bottom_claim.py [--work /tmp/skyfix-bottom] --only NAME [--tracked]
                                                     [--draws N] [--out FILE]

One session per process (``--only``; rendered into ``--work`` when missing, as bench/pose_from_bottom.py does).
``NAME_baro``, ``NAME_height``, ``NAME_time`` are the session again with errors drawn that bench/pose_from_bottom.py's
sessions do not draw (:data:`VARIANTS`; their ``session.toml`` states them as the platform would): its telemetry
generated again, its twin's rendered video linked (the video does not depend on them). ``--tracked``: the pixel
tracked in the video (with the tracker's own sigma) instead of track.csv's true one. ``--draws N``: a variant flown
N more times with its sensors' errors drawn again (``[sensors] draw`` 1..N, folders ``NAME_drawK``), and one line
pooling the draws (:func:`pooled`). Per session, with the estimate applied (``--pose-from-bottom auto``):

- ``claim``: the share of fixes within 2·h_acc, the median h_acc, the error's RMS per axis (north, east) against the
  claimed 1-sigma's RMS (``sigma_n_m``, ``sigma_e_m``) and their ratio (1: calibrated; one session is one draw of the
  biases and the GNSS's offset, so a ratio is one sample of a correlated error, not a distribution);
- ``the height's term alone``: the same claim with the height's term as it was before the estimate's tilt and
  heading per metre of height (:attr:`localizer.bottom.BottomEstimate.bias_per_height_rad`) went into it (base's);
- ``made of``: each input's share of h_acc² (the median over fixes of 1 − h_acc² without it / h_acc²): what the
  estimate put in (``tilt``, ``heading``: its sigmas, :meth:`groundstation.offline.bottom.PoseCorrection.claimed_deg`)
  and what it left as without it (the GNSS, the height, the pixel, the time, the depth);
- ``drawn only``: the same claim without the pixel's sigma where the pixel is the true one and, on the sessions
  without a variant's, the height's (``truth_errors.csv``'s ``height_err_m`` is 0 throughout): whether the terms the
  session does draw are claimed honestly; ``without the time term``: the same claim without the frames' time sigma
  (the error a frame time error makes is the camera's motion less the UUV's over it, about none where the drone
  flies with the UUV; the term takes the same, the UUV's velocity from its fixes:
  :func:`groundstation.offline.bottom.locate_on_track`, as ``skyfix process`` does);
- ``per term``: each term's error RMS against its claimed 1-sigma's: the pose's height (less the simulator's), the
  attitude left after the correction against the tilt's sigma with the height's share (the tilt per metre times the
  height's sigma), the walk, the GNSS's offset, the pixel (tracked less true, against the tracker's sigma), the
  frames' time (``video_frames.csv``'s less ``truth.csv``'s, against the claim's ``sigma_time_s``);
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
import re
from pathlib import Path

import numpy as np
from pose_from_bottom import SESSIONS, reported_minus_true, scenario_of, session

from groundstation.offline import process
from groundstation.offline.bottom import locate_on_track
from groundstation.offline.evaluate import error_ne_m
from groundstation.session.read import load_session
from localizer.pose import camera_pose
from sim_fixtures.generate import generate
from sim_fixtures.motion import Motion
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
#: the errors each variant draws (:func:`with_overrides` keys) by the twin's GNSS mode: ``_baro`` the barometer 0.3 m
#: high with a 0.1 m wander; ``_height`` the weather sessions' barometer (``sim_fixtures/scenarios/weather_*``: a
#: 0.15 m wander of 30 s and 0.03 m white) and a GNSS altitude as its receiver gives it (RTK: 2 cm white and a 1 cm
#: slow error, as ``height_rtk_noise.toml``; plain: a 1.5 m slow error and 0.1 m white); ``_time`` those and the frames'
#: stamps off by a constant of 1-sigma :data:`FRAME_TIME_S` (a latency known to that much, stated as ``[uncertainty]
#: time_s``; its default, which the other variants state without drawing it)
HEIGHT = {
    "rtk": {"gnss_alt_noise_m": 0.02, "gnss_alt_error_m": 0.01, "gnss_alt_error_period_s": 120.0},
    "plain": {"gnss_alt_noise_m": 0.1, "gnss_alt_error_m": 1.5},
}
WEATHER_BARO = {"baro_wander_m": 0.15, "baro_noise_m": 0.03}
FRAME_TIME_S = 0.02
VARIANTS = {
    "_baro": lambda gnss: {"uav": {"baro_bias_m": 0.3}, "sensors": {"baro_wander_m": 0.1}},
    "_height": lambda gnss: {"uav": HEIGHT[gnss], "sensors": WEATHER_BARO},
    "_time": lambda gnss: {
        "uav": HEIGHT[gnss],
        "sensors": {**WEATHER_BARO, "video_time_sigma_s": FRAME_TIME_S},
    },
}
NAMES = [*SESSIONS, *(f"{n}{v}" for v in VARIANTS for n in SESSIONS)]


def split(name: str) -> tuple[str, str]:
    """The twin's name (:data:`SESSIONS`) and the variant's suffix ("" for the twin itself)."""
    for suffix in VARIANTS:
        if name.endswith(suffix):
            return name.removesuffix(suffix), suffix
    return name, ""


def not_drawn(name: str, tracked: bool) -> tuple[str, ...]:
    """The :data:`TERMS` the session ``name`` does not draw (the pixel's when it is the true one)."""
    return (() if split(name)[1] else ("height",)) + (() if tracked else ("pixel",))


def session_of(name: str, work: Path, draw: int = 0) -> tuple[str, Path]:
    """The twin's name (the session without its variant's suffix) and the session's folder (made when missing);
    ``draw``: the variant's sensors' errors drawn again (``[sensors] draw``, the folder ``NAME_drawK``)."""
    twin, suffix = split(name)
    path = session(twin, work, None)
    if twin == name:
        return twin, path
    out = work / (f"{name}_draw{draw}" if draw else name)
    if not (out / "video.mp4").exists():
        sc = scenario_of(twin, None)
        errors = VARIANTS[suffix](sc.sensors.gnss_mode)
        errors["sensors"] = {**errors["sensors"], "draw": draw}
        generate(with_overrides(sc, name=out.name, **errors), out, video=False)
        (out / "video.mp4").symlink_to((path / "video.mp4").resolve())
        # the twin's [tracker] box (made with the video, which this one links), at the same frame's stamp here (a
        # variant's frames' time error moves the stamps)
        tracker = (path / "session.toml").read_text().split("[tracker]")[1].split("\n\n")[0]
        init_t = float(tracker.split("init_t = ")[1].split()[0])
        frame = int(np.argmin(np.abs(load_session(path).frames["t"] - init_t)))
        stamped = float(load_session(out).frames["t"][frame])
        tracker = re.sub(r"init_t = \S+", f"init_t = {stamped!r}", tracker)
        toml = (out / "session.toml").read_text()
        (out / "session.toml").write_text(
            toml.replace("[uncertainty]", f"[tracker]{tracker}\n\n[uncertainty]", 1)
        )
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


def lines_for(name: str, work: Path, tracked: bool, draw: int = 0) -> tuple[list[str], dict]:
    """The session's lines and what :func:`pooled` pools over draws."""
    twin, path = session_of(name, work, draw)
    if draw:
        name = f"{name}_draw{draw}"
    s = load_session(path, "uuv1")
    pixels = process.frame_pixels(s, use_track=not tracked)
    correction = process.bottom_correction(s, pixels, "auto")
    if correction is None:
        return [f"{name}: no pose from the bottom: {'; '.join(s.warnings)}"], {}
    found = pixels.status == "ok"
    t, u, v = (x[found] for x in pixels[:3])
    sigma_px = None if pixels.sigma_px is None else pixels.sigma_px[found]
    pose, cal = correction.apply(s, camera_pose(s.calibration, s.telemetry, t))

    def fixes_of(names=(), p=pose):
        c, p = without(cal, p, names)
        f = locate_on_track(c, p, u, v, sigma_px=0.0 if "pixel" in names else sigma_px)
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
    drawn, _ = claim_line(*fixes_of(not_drawn(name, tracked)))
    timeless, _ = claim_line(*fixes_of(("time",)))

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
    sc = scenario_of(twin, None)
    height_err = at.uav_height_m + Motion(sc).uav_ned(np.arange(len(te)) / sc.fps)[:, 2]
    per_m_rad = correction.estimate.bias_per_height_rad
    tilt_said = np.hypot(
        np.radians(claimed["tilt_deg"] or np.nan),
        np.hypot(*per_m_rad[:2]) / np.sqrt(2) * at.sigma_height_m,
    )
    true_px = np.column_stack([np.interp(t, s.track["t"], s.track[k]) for k in "uv"])
    px_err = rms(np.column_stack([u, v]) - true_px)
    px_said = rms(np.broadcast_to(cal.sigmas.pixel_px if sigma_px is None else sigma_px, u.shape))
    walk_err = moved - moved.mean(axis=0)
    frame_time_s = float(np.median(s.frames["t"] - s.truth["t"]))
    sigma_time_s = float(np.median(at.sigma_time_s))
    pool = {
        "err": err[ok],
        "sigma_ne": np.column_stack([fixes.sigma_n_m[ok], fixes.sigma_e_m[ok]]),
        "h_acc": fixes.h_acc_m[ok],
        "height": np.column_stack([height_err, at.sigma_height_m]),
        "tilt": np.column_stack([left_deg[:2][None, :], np.degrees(rms(tilt_said))[None, None]]),
        "walk": np.column_stack([walk_err, correction.estimate.sigma_walk_at(at.t_unix)[good]]),
        "gnss": np.array([[*gnss, sigma_uav]]),
        "time": np.array([[frame_time_s, sigma_time_s]]),
    }
    return [
        f"{name}: claim: {said}",
        (
            f"{name}: the height's term alone (the claim before the fit's tilt and heading per metre of "
            f"height, {per_m[0]:+.2f}/{per_m[1]:+.2f}/{per_m[2]:+.2f}°, went with it): {before}"
        ),
        f"{name}: made of: " + ", ".join(shares),
        f"{name}: drawn only ({'; '.join(f'no {x} sigma' for x in not_drawn(name, tracked)) or 'all drawn'}): {drawn}",
        f"{name}: without the time term (its sigma 0): {timeless}",
        (
            f"{name}: per term, error RMS / claimed 1σ RMS: height {rms(height_err):.3f}/{rms(at.sigma_height_m):.3f} m "
            f"= {rms(height_err) / rms(at.sigma_height_m):.2f} (within 2σ {np.mean(np.abs(height_err) <= 2 * at.sigma_height_m):.0%}); "
            f"tilt left N/E with the height's share {left_deg[0]:.3f}/{left_deg[1]:.3f}° / {np.degrees(rms(tilt_said)):.3f}° "
            f"= {left_deg[0] / np.degrees(rms(tilt_said)):.2f}/{left_deg[1] / np.degrees(rms(tilt_said)):.2f}; "
            f"walk N/E {rms(moved - moved.mean(axis=0))[0] / sigma_walk[0]:.2f}/"
            f"{rms(moved - moved.mean(axis=0))[1] / sigma_walk[1]:.2f}; "
            f"GNSS offset N/E {abs(gnss[0]) / sigma_uav:.2f}/{abs(gnss[1]) / sigma_uav:.2f}; "
            f"pixel u/v {px_err[0]:.2f}/{px_err[1]:.2f} px / {px_said:.2f} px "
            f"({'tracked' if tracked else 'the true pixel'}, {found.sum()} of {len(found)} frames); "
            f"frame time {frame_time_s * 1000:+.1f}/{sigma_time_s * 1000:.1f} ms"
        ),
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
    ], pool


def pooled(name: str, pools: list[dict]) -> str:
    """One line over the draws: the share of fixes within 2·h_acc, the error's RMS against the claim's per axis, and
    per term its error's RMS against its claimed 1-sigma's (the height, the tilt left with the height's share, the
    walk about the GNSS's mean, the GNSS's offset, the frames' time)."""
    pools = [p for p in pools if p]
    cat = {k: np.concatenate([p[k] for p in pools]) for k in pools[0]}
    e = np.hypot(*cat["err"].T)
    got, said = rms(cat["err"]), rms(cat["sigma_ne"])
    h, t, w, g, ft = cat["height"], cat["tilt"], cat["walk"], cat["gnss"], cat["time"]
    return (
        f"{name} over {len(pools)} draws: in 2σ {np.mean(e <= 2 * cat['h_acc']):.1%} of {len(e)} fixes, median "
        f"h_acc {np.median(cat['h_acc']):.3f} m; error RMS / claimed 1σ N/E {got[0]:.4f}/{said[0]:.4f} = "
        f"{got[0] / said[0]:.2f}, {got[1]:.4f}/{said[1]:.4f} = {got[1] / said[1]:.2f}; per term: height "
        f"{rms(h[:, 0]) / rms(h[:, 1]):.2f}, tilt left N/E {rms(t[:, 0]) / rms(t[:, 2]):.2f}/"
        f"{rms(t[:, 1]) / rms(t[:, 2]):.2f}, walk N/E {rms(w[:, 0]) / rms(w[:, 2]):.2f}/"
        f"{rms(w[:, 1]) / rms(w[:, 3]):.2f}, GNSS offset N/E {rms(g[:, 0]) / rms(g[:, 2]):.2f}/"
        f"{rms(g[:, 1]) / rms(g[:, 2]):.2f}, frame time {rms(ft[:, 0]) / rms(ft[:, 1]):.2f}"
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", type=Path, default=Path("/tmp/skyfix-bottom"))
    ap.add_argument("--only", required=True, choices=NAMES)
    ap.add_argument("--out", type=Path, default=None, help="append the lines to this file")
    ap.add_argument(
        "--tracked",
        action="store_true",
        help="the pixel tracked in the video (default: track.csv's true one)",
    )
    ap.add_argument(
        "--draws",
        type=int,
        default=0,
        help="a variant's sensors drawn this many times again too ([sensors] draw 1..N), pooled in one line",
    )
    ap.add_argument(
        "--from-draw",
        type=int,
        default=0,
        help="start at this draw (its earlier ones made in another run)",
    )
    args = ap.parse_args()
    if args.draws and not split(args.only)[1]:
        ap.error("--draws: a variant's name (NAME_height, NAME_time, NAME_baro)")
    lines, pools = [], []
    for draw in range(args.from_draw, args.draws + 1):
        more, pool = lines_for(args.only, args.work, args.tracked, draw)
        lines += more
        pools.append(pool)
        print("\n".join(more), flush=True)
    if args.draws:
        lines.append(pooled(args.only, pools))
        print(lines[-1], flush=True)
    finish(lines, args.only, args.out)
    return 0


def finish(lines: list[str], label: str, out: Path | None) -> None:
    """The load average as the last line, printed; all ``lines`` appended to ``out`` when given."""
    lines.append(f"({label}: load average {' '.join(f'{x:.1f}' for x in os.getloadavg())})")
    print(lines[-1], flush=True)
    if out:
        with open(out, "a") as f:
            f.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    raise SystemExit(main())

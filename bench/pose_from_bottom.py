"""The drone's pose errors from the static bottom (``skyfix process --pose-from-bottom auto``): what they buy.

    .venv/bin/python bench/pose_from_bottom.py [--work /tmp/skyfix-bottom] [--out bench/results/pose_from_bottom.txt]
                                               [--only NAME ...] [--duration S]

Sessions (rendered once into ``--work``, 640x360): ``sim_fixtures/scenarios/bottom_follow.toml`` (the UAV flies
after a UUV weaving over a textured floor, a stabilised gimbal: its levelling error and the compass's bias) and
``bottom_survey.toml`` (a straight survey line, a servo mount: the AHRS's tilt bias and the compass's), each flown
on RTK and on plain GNSS (``[sensors] gnss_mode``), with the renderer's caustics;
``--only`` also takes ``follow_rtk_waves2``, ``follow_plain_waves2`` (2 m/s wind waves over the same follow). Each is
processed with the true pixel (``track.csv``: the pose's errors alone) without and with the estimate.

The table: per session the GNSS, the camera's attitude error true (median over frames of ``truth_errors.csv``'s
``cam_err_*``, the tilt about the bias frame's forward and right axes) and estimated with its 1-sigma, the position
correction's largest 1-sigma, the MAE and shape (MAE after the best constant offset) against ``truth.csv`` without
and with the estimate, the share of fixes within 2·h_acc and their median h_acc, and the seconds the estimate took;
last, each plain-GNSS session's shape against its RTK twin's and each RTK session's MAE (targets: plain's shape
within 1.5× RTK's; absolute MAE ≤ 0.10 m with RTK). Below the table, the estimate's own line per session.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from groundstation.offline import process
from groundstation.offline.bottom import PoseCorrection, bias_headings
from groundstation.offline.evaluate import error_ne_m, shape_m
from groundstation.session.read import load_session
from localizer.bottom import in_bias_frame
from localizer.geodesy import geodetic_to_ned
from localizer.pose import camera_pose
from sim_fixtures.generate import generate
from sim_fixtures.motion import Motion
from sim_fixtures.scenario import load_scenario, with_overrides
from sim_fixtures.sensors import position_white_ne_m
from sim_fixtures.tlog import Clock, sample_times, stream

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ROOT / "sim_fixtures" / "scenarios"
#: name: (scenario, gnss_mode, wind m/s)
SESSIONS = {
    f"{kind}_{gnss}": (f"bottom_{kind}", gnss, 0.0)
    for kind in ("follow", "survey")
    for gnss in ("rtk", "plain")
}
EXTRA = {f"follow_{gnss}_waves2": ("bottom_follow", gnss, 2.0) for gnss in ("rtk", "plain")}
HEADER = (
    f"{'session':20s} {'GNSS':5s} {'tilt fwd true/est°':>18s} {'tilt right true/est°':>20s} "
    f"{'heading true/est°':>18s} {'σ pos m':>7s} {'MAE off':>8s} {'MAE on':>7s} {'shape off':>9s} "
    f"{'shape on':>8s} {'in 2σ':>6s} {'h_acc m':>7s} {'s':>4s}"
)


def scenario_of(name: str, duration_s: float | None):
    """The session's scenario (:data:`SESSIONS`, :data:`EXTRA`)."""
    scenario, gnss, wind_mps = {**SESSIONS, **EXTRA}[name]
    sc = load_scenario(SCENARIOS / f"{scenario}.toml")
    return with_overrides(
        sc,
        name=name,
        duration_s=duration_s or sc.duration_s,
        sensors={"gnss_mode": gnss},
        **({"waves": {"wind_mps": wind_mps}} if wind_mps else {}),
    )


def session(name: str, work: Path, duration_s: float | None) -> Path:
    """The session's folder, rendered when missing."""
    out = work / name
    if not (out / "video.mp4").is_file():
        generate(scenario_of(name, duration_s), out, video=True)
    return out


def truth_check(name: str, path: Path, s, duration_s: float | None) -> str:
    """One line: the reported UAV position at the frames (GLOBAL_POSITION_INT as the ground station interpolates it)
    less the true one (the scenario's motion) against ``truth_errors.csv``'s ``north_err_m``, ``east_err_m`` (cm RMS
    per axis about the mean, and frame to frame), then less the message's white draws too (the EKF position's
    ``gnss_white_m``, which truth_errors.csv leaves out: the same draws as :func:`sim_fixtures.tlog.write_tlog`'s,
    linearly interpolated to the frames): what is left is the positions' 1e-7 degree steps and the interpolation."""
    sc = scenario_of(name, duration_s)
    te = np.genfromtxt(path / "truth_errors.csv", delimiter=",", names=True)
    tau = np.arange(len(te)) / sc.fps
    site = sc.site
    off = reported_minus_true(name, path, s, duration_s)
    off -= np.column_stack([te["north_err_m"], te["east_err_m"]])
    clock, tel = Clock.of(sc), sc.telemetry
    sent, _ = sample_times(
        clock, tel.position_hz, -tel.lead_s, sc.duration_s + 1.0, stream(sc, "position")
    )
    white = position_white_ne_m(sc, "ekf", len(sent))
    at = np.column_stack([np.interp(tau, clock.tau_of_us(sent), w) for w in white.T])

    def cm(x):
        return "/".join(f"{v:.2f}" for v in 100 * np.std(x, axis=0))

    d = np.diff(off, axis=0)
    # the camera's tilt wander about its mean (the bias taken off), as a ground shift at the UUV's apparent depth below
    # the camera (near nadir: height + depth / n)
    tilt = np.radians(np.column_stack([te["cam_err_n_deg"], te["cam_err_e_deg"]]))
    slant_m = sc.uav.height_m + sc.uuv.depth_m / site.refractive_index
    wander_mm = 1000 * slant_m * np.mean(np.hypot(*(tilt - tilt.mean(axis=0)).T))
    return (
        f"{name}: reported - true - truth_errors: {cm(off)} cm RMS N/E (frame to frame {cm(d)}); "
        f"the white draws interpolated: {cm(at)}; left once they are taken off too: {cm(off - at)} "
        f"(the 1e-7 degree steps alone: {100 * 0.0111 / np.sqrt(12):.2f} cm north); the tilt's wander "
        f"uncorrected would be a shape of {wander_mm:.1f} mm"
    )


def reported_minus_true(name: str, path: Path, s, duration_s: float | None) -> np.ndarray:
    """The reported UAV position (GLOBAL_POSITION_INT as the ground station interpolates it) less the true one (the
    scenario's motion) at ``truth_errors.csv``'s frames: (K, 2) m north, east."""
    sc = scenario_of(name, duration_s)
    te = np.genfromtxt(path / "truth_errors.csv", delimiter=",", names=True)
    pose = camera_pose(s.calibration, s.telemetry, te["t"])
    site = sc.site
    n, e, _ = geodetic_to_ned(
        pose.lat_deg, pose.lon_deg, pose.alt_amsl_m, site.lat_deg, site.lon_deg, site.surface_amsl_m
    )
    return np.column_stack([n, e]) - Motion(sc).uav_ned(np.arange(len(te)) / sc.fps)[:, :2]


def scores(s, pose_from_bottom: str):
    """(MAE, shape, share within 2·h_acc, median h_acc, the correction or None) of the refraction fixes from the true
    pixel."""
    pixels = process.frame_pixels(s, use_track=True)
    correction = process.bottom_correction(s, pixels, pose_from_bottom)
    fixes = process.locate_frames(s, pixels, correction=correction)
    return (*fix_scores(fixes, s.truth), correction)


def fix_scores(fixes, truth) -> tuple[float, float, float, float]:
    """(MAE m, shape m, share within 2·h_acc, median h_acc m) of the ok fixes against the truth."""
    ok = fixes.status == "ok"
    err = error_ne_m(fixes.t_unix, fixes.lat, fixes.lon, ok, truth)
    e = np.hypot(*err.T)
    good = np.isfinite(e)
    return (
        float(np.mean(e[good])),
        shape_m(err),
        float(np.mean(e[good] <= 2 * fixes.h_acc_m[good])),
        float(np.median(fixes.h_acc_m[good])),
    )


def truth_bias(path: Path, s, correction: PoseCorrection | None) -> np.ndarray:
    """The camera's true attitude error (degrees, median over frames): tilt forward and right of the bias frame the
    estimate used (the camera's heading when there is none), heading."""
    te = np.genfromtxt(path / "truth_errors.csv", delimiter=",", names=True)
    pose = camera_pose(s.calibration, s.telemetry, te["t"])
    err_ned = np.column_stack([te["cam_err_n_deg"], te["cam_err_e_deg"], te["cam_err_d_deg"]])
    frame = "camera" if correction is None else correction.tilt_frame
    return np.median(in_bias_frame(err_ned, bias_headings(s, pose, frame)), axis=0)


def cells(true_deg, correction: PoseCorrection | None) -> list[str]:
    """The biases' cells: true and estimated ± 1-sigma (tilt fwd, tilt right, heading), the position's sigma."""
    if correction is None:
        return [f"{t:+.2f}  {'—':>11}" for t in true_deg] + [f"{'—':>6}"]
    e = correction.estimate
    est = [*np.degrees(e.tilt_rad), np.degrees(e.yaw_rad)]
    sig = [np.degrees(e.sigma_tilt_rad)] * 2 + [np.degrees(e.sigma_yaw_rad)]
    return [f"{t:+.2f}  {x:+.2f}±{s:.2f}" for t, x, s in zip(true_deg, est, sig)] + [
        f"{float(np.max(np.hypot(*e.sigma_walk_ne_m.T))):6.3f}"
    ]


def targets(shapes: dict[str, float], maes: dict[str, float], word: str) -> list[str]:
    """Issue 28's targets, printed: a plain-GNSS session's shape (m) against its RTK twin's, an RTK session's
    absolute MAE (m); ``word`` names the target (e.g. "offline target" where the run is not offline's)."""
    lines = []
    for name, shape in shapes.items():
        twin = name.replace("_plain", "_rtk")
        if twin != name and twin in shapes:
            lines.append(
                f"{name}: shape {shape:.4f} m = {shape / shapes[twin]:.2f}x {twin}'s {shapes[twin]:.4f} m "
                f"({word}: within 1.5x)"
            )
        elif "_rtk" in name:
            lines.append(f"{name}: absolute MAE {maes[name]:.3f} m ({word} with RTK: <= 0.10 m)")
    for line in lines:
        print(line)
    return lines


def write(out: Path, lines: list[str], notes: list[str]) -> None:
    """The table and its targets, a blank line, then the notes, into ``out``."""
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join([*lines, "", *notes]) + "\n")
    print(f"-> {out}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", type=Path, default=Path("/tmp/skyfix-bottom"))
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "pose_from_bottom.txt")
    ap.add_argument("--duration", type=float, default=None, help="seconds of each session")
    ap.add_argument("--only", nargs="*", default=None, choices=[*SESSIONS, *EXTRA])
    ap.add_argument(
        "--truth-check",
        type=Path,
        default=None,
        help="only compare each session's reported position with truth_errors.csv (truth_check), into this file",
    )
    args = ap.parse_args()
    if args.truth_check:
        checks = []
        for name in args.only or SESSIONS:
            path = session(name, args.work, args.duration)
            checks.append(truth_check(name, path, load_session(path, "uuv1"), args.duration))
            print(checks[-1], flush=True)
        write(args.truth_check, checks, [])
        return 0
    lines, shapes, maes, notes = [HEADER], {}, {}, []
    print(HEADER, flush=True)
    for name in args.only or SESSIONS:
        path = session(name, args.work, args.duration)
        s = load_session(path, "uuv1")
        mae0, shape0, _, _, _ = scores(s, "off")
        start = time.perf_counter()
        mae1, shape1, in1, h_acc, corr = scores(s, "auto")
        seconds = time.perf_counter() - start
        shapes[name], maes[name] = shape1, mae1
        bias = cells(truth_bias(path, s, corr), corr)
        gnss = {**SESSIONS, **EXTRA}[name][1]
        lines.append(
            f"{name:20s} {gnss:5s} {bias[0]:>18s} {bias[1]:>20s} {bias[2]:>18s} {bias[3]:>7s} "
            f"{mae0:8.3f} {mae1:7.3f} {shape0:9.4f} {shape1:8.4f} {in1:6.0%} {h_acc:7.3f} {seconds:4.0f}"
        )
        notes.append(f"{name}: " + ("none" if corr is None else corr.describe()))
        print(lines[-1], flush=True)
    write(args.out, lines + targets(shapes, maes, "target"), notes)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

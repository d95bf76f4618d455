"""The drone's pose biases from the static bottom (``skyfix process --pose-from-bottom auto``): what they buy.

    .venv/bin/python bench/pose_from_bottom.py [--work /tmp/skyfix-bottom] [--out bench/results/pose_from_bottom.txt]
                                               [--only NAME ...]

Sessions: ``follow_cruise`` (the UAV flies after a cruising UUV, the floor slides through the image) for
``--duration`` s, rendered at 640x360, flown by a drone with ``[sensors]`` errors (the gimbal's levelling error
0.2/-0.2°, AHRS tilt bias 0.18/-0.24°, compass bias 2°, 0.05° wander) on RTK or plain GNSS, each with the
renderer's caustics (the default, 0.5) and without (0), and under 2 m/s wind waves (``[waves] wind_mps = 2``: the
floor seen through a moving surface, the caustics drifting with the waves). Each is processed with the true pixel
(``track.csv``:
the pose's errors alone) without and with the correction; printed per session: MAE and shape (MAE after the
best constant offset) against ``truth.csv``, the share within 2·h_acc, and the camera's attitude error
estimated against ``truth_errors.csv``'s (the median over frames of ``cam_err_*``; the tilt about the camera's
heading's forward and right axes). Last, each plain-GNSS session's shape against its RTK twin's (the target: within
1.5×) and the seconds (wall clock) processing with the estimate took.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from groundstation.offline import process
from groundstation.offline.evaluate import error_ne_m, shape_m
from groundstation.session.read import load_session
from localizer.bottom import camera_heading_rad
from localizer.pose import camera_pose
from sim_fixtures.generate import generate
from sim_fixtures.scenario import load_scenario, with_overrides

SENSORS = {
    "roll_bias_deg": 0.18,
    "pitch_bias_deg": -0.24,
    "yaw_bias_deg": 2.0,
    "wander_deg": 0.05,
    "gimbal_level_deg": (0.2, -0.2),
}
SESSIONS = {
    **{
        f"follow_{g}{'' if c else '_nocaustics'}": (g, c, 0.0)
        for g in ("rtk", "plain")
        for c in (0.5, 0.0)
    },
    **{f"follow_{g}_waves2": (g, 0.5, 2.0) for g in ("rtk", "plain")},
}


def session(name: str, work: Path, duration_s: float) -> Path:
    gnss, caustics, wind_mps = SESSIONS[name]
    out = work / name
    if not (out / "video.mp4").is_file():
        sc = load_scenario(ROOT / "sim_fixtures" / "scenarios" / "follow_cruise.toml")
        sc = with_overrides(
            sc,
            name=name,
            duration_s=duration_s,
            sensors={**SENSORS, "gnss_mode": gnss},
            render={"caustics": caustics},
            **({"waves": {"wind_mps": wind_mps}} if wind_mps else {}),
        )
        generate(sc, out, video=True)
    return out


def scores(path: Path, pose_from_bottom: str):
    """(MAE, shape, share within 2·h_acc, the correction or None) of the refraction fixes from the true pixel."""
    s = load_session(path, "uuv1")
    pixels = process.frame_pixels(s, use_track=True)
    correction = process.bottom_correction(s, pixels, pose_from_bottom)
    fixes = process.locate_frames(s, pixels, correction=correction)
    truth = s.truth
    ok = fixes.status == "ok"
    err = error_ne_m(fixes.t_unix, fixes.lat, fixes.lon, ok, truth)
    e = np.hypot(*err.T)
    good = np.isfinite(e)
    return (
        float(np.mean(e[good])),
        shape_m(err),
        float(np.mean(e[good] <= 2 * fixes.h_acc_m[good])),
        correction,
        s,
    )


def truth_bias(path: Path, s) -> tuple[float, float, float]:
    """The camera's true attitude error (median over frames): tilt forward and right of its heading, yaw (degrees)."""
    te = np.genfromtxt(path / "truth_errors.csv", delimiter=",", names=True)
    pose = camera_pose(s.calibration, s.telemetry, te["t"])
    psi = camera_heading_rad(pose.R_ned_from_cv)
    n, e, d = te["cam_err_n_deg"], te["cam_err_e_deg"], te["cam_err_d_deg"]
    fwd = n * np.cos(psi) + e * np.sin(psi)
    right = -n * np.sin(psi) + e * np.cos(psi)
    return float(np.median(fwd)), float(np.median(right)), float(np.median(d))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", type=Path, default=Path("/tmp/skyfix-bottom"))
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "pose_from_bottom.txt")
    ap.add_argument("--duration", type=float, default=16.0, help="seconds of each session")
    ap.add_argument("--only", nargs="*", default=None)
    args = ap.parse_args()
    lines, shapes = [], {}
    for name in args.only or SESSIONS:
        path = session(name, args.work, args.duration)
        mae0, shape0, in0, _, s = scores(path, "off")
        start = time.perf_counter()
        mae1, shape1, in1, corr, _ = scores(path, "auto")
        seconds = time.perf_counter() - start
        shapes[name] = shape1
        fwd, right, yaw = truth_bias(path, s)
        est = "none" if corr is None else corr.describe()
        lines.append(
            f"{name}: without MAE {mae0:.3f} m shape {shape0:.3f} m in 2σ {in0:.0%}; "
            f"with MAE {mae1:.3f} m shape {shape1:.3f} m in 2σ {in1:.0%}; "
            f"true camera error tilt fwd {fwd:+.2f}° right {right:+.2f}° heading {yaw:+.2f}°; {est}; "
            f"{seconds:.0f} s"
        )
        print(lines[-1], flush=True)
    for name, shape in shapes.items():
        twin = name.replace("_plain", "_rtk")
        if twin != name and twin in shapes:
            lines.append(
                f"{name}: shape {shape:.3f} m = {shape / shapes[twin]:.2f}x {twin}'s {shapes[twin]:.3f} m"
            )
            print(lines[-1])
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines) + "\n")
    print(f"-> {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

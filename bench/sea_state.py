"""The sea state from the image, not yet: the static floor's apparent jitter as the image shows it against the
simulator's truth.

    .venv/bin/python bench/sea_state.py [--duration 4] [--work /tmp/skyfix-sea-state] [--out bench/results/sea_state.txt]
                                        [--only NAME ...]

The waves' slopes move every floor point's image; the part in waves longer than the UUV moves the UUV's image as
a whole, and that is what the claim's wave term needs. For each scenario (the waves scenes, their copies without
caustics, and a flat one; ``--duration`` seconds, rendered once into ``--work``) this prints the floor's jitter in
pixels² (both axes; the mean over 1 s windows of each point's variance about its window mean):

- truth: floor points seen at 30 random pixels of the first frame, their apparent pixel through the waves averaged
  over the UUV's top face (the simulator's :func:`~sim_fixtures.generate.apparent_pixel`, as its track.csv), less
  their flat-surface pixel; and through the unaveraged waves;
- the image: floor corners tracked frame to frame (pyramidal Lucas-Kanade, a window the UUV's image across, kept
  while forward and backward agree within 3 px), the camera's motion taken out by a homography per frame fitted to
  all of them, away from the UUV.

What the image shows does not follow the truth yet (see bench/results/sea_state.txt): under the simulator's waves the
floor's texture breaks up at the shortest waves' scale and the caustics drag the corners, so the tracked jitter is
neither the UUV's share nor the points'. The claim's wave term stays the configured wind's.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]

from groundstation.session.read import load_session
from groundstation.video.file import open_video
from sim_fixtures.generate import (
    apparent_pixel,
    apparent_radius_m,
    camera_of,
    frame_truth,
    generate,
    reference_pixel,
)
from sim_fixtures.geometry import pixel_rays, refract_into_water
from sim_fixtures.motion import Motion
from sim_fixtures.render import floor_div
from sim_fixtures.scenario import load_scenario, with_overrides
from sim_fixtures.waves import wave_field

SCENES = {  # name: (scenario, [render] caustics or None for the scenario's)
    "waves_2mps_nadir": ("waves_2mps_nadir", None),
    "waves_2mps_nadir_no_caustics": ("waves_2mps_nadir", 0.0),
    "waves_5mps_oblique": ("waves_5mps_oblique", None),
    "waves_5mps_oblique_no_caustics": ("waves_5mps_oblique", 0.0),
    "waves_8mps_oblique": ("waves_8mps_oblique", None),
    "nadir_hover": ("nadir_hover", None),
}
WINDOW_S = 1.0
POINTS = 30
BACK_PX = 3.0
UUV_CLEAR_PX = 45


def scenario(name: str, duration_s: float):
    base, caustics = SCENES[name]
    sc = load_scenario(ROOT / "sim_fixtures" / "scenarios" / f"{base}.toml")
    tables = {"name": name, "duration_s": duration_s}
    if caustics is not None:
        tables["render"] = {"caustics": caustics}
    return with_overrides(sc, **tables)


def window_variance(jitter: np.ndarray, per_window: int) -> float:
    """Mean over windows of ``per_window`` frames of each point's variance (both axes) about its window mean:
    ``jitter`` (frames, points, 2), NaN ignored."""
    out = []
    for s in range(0, len(jitter) - per_window + 1, per_window):
        w = jitter[s : s + per_window]
        out.append(np.nanmean(np.sum((w - np.nanmean(w, axis=0)) ** 2, axis=-1)))
    return float(np.mean(out))


def truth_jitter(sc, per_window: int) -> tuple[float, float]:
    """The truth's floor jitter (px²): through the waves averaged over the UUV's top face, and unaveraged."""
    camera = camera_of(sc)
    truth = frame_truth(sc, Motion(sc), camera)
    waves = wave_field(sc, camera.fx / floor_div(camera))
    if waves is None:
        return 0.0, 0.0
    rng = np.random.default_rng(0)
    u = rng.uniform(0.15, 0.85, POINTS) * camera.width
    v = rng.uniform(0.15, 0.85, POINTS) * camera.height
    d = pixel_rays(camera, u, v) @ truth.R_ned_from_cv[0].T
    c0 = truth.camera_ned[0]
    flat = c0[:2] + d[:, :2] * (-c0[2] / d[:, 2])[:, None]
    w = refract_into_water(d, sc.site.refractive_index)
    depth = sc.site.floor_depth_m
    points = np.column_stack([flat + w[:, :2] * (depth / w[:, 2])[:, None], np.full(POINTS, depth)])
    n = sc.site.refractive_index
    result = []
    for field in (waves.averaged(apparent_radius_m(sc.uuv.size_m)), waves):
        jit = []
        for k in range(len(truth.t_unix)):
            R = np.repeat(truth.R_ned_from_cv[k][None], POINTS, 0)
            C = np.repeat(truth.camera_ned[k][None], POINTS, 0)
            au, av = apparent_pixel(camera, R, C, np.full(POINTS, truth.tau_s[k]), points, field, n)
            ru, rv = reference_pixel(camera, R, C, points, n)
            jit.append(np.column_stack([au - ru, av - rv]))
        result.append(window_variance(np.array(jit), per_window))
    return result[0], result[1]


def image_jitter(path: Path, per_window: int, uuv_px: float) -> tuple[float, int]:
    """The tracked floor corners' jitter (px²) and how many corners a window kept on average."""
    s = load_session(path)
    cam = s.calibration.camera
    win = max(9, 2 * round(uuv_px / 2) + 1)
    lk = {
        "winSize": (win, win),
        "maxLevel": 2,
        "criteria": (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 0.01),
    }
    with open_video(
        s.video_path,
        expected_size=(cam.width, cam.height),
        indices=s.frames["frame"].astype(int),
        grey=True,
    ) as video:
        frames = [vf.image for vf in video.prefetch()]
    K, dist = cam.K, np.asarray(cam.distortion)
    variances, kept = [], []
    for s0 in range(0, len(frames) - per_window + 1, per_window):
        mask = np.zeros(frames[s0].shape, np.uint8)
        mask[12:-12, 12:-12] = 255
        i = int(np.argmin(np.abs(s.track["t"] - s.frames["t"][s0])))
        if np.isfinite(s.track["u"][i]):
            centre = (int(s.track["u"][i]), int(s.track["v"][i]))
            cv2.circle(mask, centre, UUV_CLEAR_PX, 0, -1)
        p = cv2.goodFeaturesToTrack(frames[s0], 500, 0.01, 8, mask=mask, blockSize=7)
        track, ok = [p.reshape(-1, 2)], np.ones(len(p), bool)
        for k in range(s0 + 1, s0 + per_window):
            p1, st, _ = cv2.calcOpticalFlowPyrLK(frames[k - 1], frames[k], p, None, **lk)
            back, st2, _ = cv2.calcOpticalFlowPyrLK(frames[k], frames[k - 1], p1, None, **lk)
            agree = np.linalg.norm((back - p).reshape(-1, 2), axis=1) < BACK_PX
            ok &= (st.ravel() == 1) & (st2.ravel() == 1) & agree
            track.append(p1.reshape(-1, 2))
            p = p1
        if ok.sum() < 8:
            continue
        und = np.array(
            [
                cv2.undistortPoints(q[ok].reshape(-1, 1, 2), K, dist, P=K).reshape(-1, 2)
                for q in track
            ]
        )
        res = np.empty_like(und)
        for k in range(per_window):
            H, _ = cv2.findHomography(und[0], und[k], cv2.LMEDS)
            res[k] = und[k] - cv2.perspectiveTransform(und[0].reshape(-1, 1, 2), H).reshape(-1, 2)
        variances.append(window_variance(res, per_window))
        kept.append(int(ok.sum()))
    return float(np.mean(variances)), int(np.mean(kept))


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--duration", type=float, default=4.0)
    p.add_argument("--work", type=Path, default=Path("/tmp/skyfix-sea-state"))
    p.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "sea_state.txt")
    p.add_argument("--only", nargs="*", default=None)
    args = p.parse_args()
    head = (
        f"floor jitter, px² (both axes) in {WINDOW_S:g} s windows, {args.duration:g} s each\n"
        f"{'scene':32s} {'truth UUV-band':>14s} {'truth points':>12s} {'image':>8s} {'corners':>7s}"
    )
    print(head, flush=True)
    lines = [head]
    for name in args.only or SCENES:
        sc = scenario(name, args.duration)
        out = args.work / name
        if not (out / "video.mp4").is_file():
            generate(sc, out)
        per_window = round(WINDOW_S * sc.fps)
        band, points = truth_jitter(sc, per_window)
        camera = camera_of(sc)
        slant_m = sc.uav.height_m / abs(np.sin(np.radians(sc.mount.pitch_deg)))
        uuv_px = 2 * apparent_radius_m(sc.uuv.size_m) * camera.fx / slant_m
        image, kept = image_jitter(out, per_window, uuv_px)
        text = f"{name:32s} {band:14.2f} {points:12.2f} {image:8.2f} {kept:7d}"
        print(text, flush=True)
        lines.append(text)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())

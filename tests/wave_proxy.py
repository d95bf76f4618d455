"""A stand-in for wind waves on a generated session's video: refraction's wobble and break-up, caustic flicker, a
4 Mbit/s-class downlink without B-frames (tests and ``bench/tracker_waves.py``; not the simulator's own waves).

Each frame is resampled through a smooth displacement field, as the image of the seafloor and the UUV is moved
by refraction through a wavy surface: a sum of linear waves with wavelengths from ``shortest_px`` to 300 pixels,
equal slope variance per octave (a saturated wind sea), deep-water dispersion at the image's scale (a 4 px wave
at 65 px/m repeats in 0.2 s, a 300 px one in 1.7 s), scaled to ``shift_px`` RMS per axis. The light is multiplied by a
drifting caustic web (bright lines where a smooth random field crosses zero, ``1 + flicker·(2·web − 0.3)``, as the
simulator's floor caustics), on the vehicle too. Then x264 at ``kbps`` with ``-bf 0`` and a keyframe a second.
Deterministic for a seed.
"""

from __future__ import annotations

import math
import shutil
import subprocess
from pathlib import Path

import cv2
import numpy as np

from groundstation.session.read import load_session
from groundstation.video.file import open_video


class WaveProxy:
    """The displacement and light fields of one realisation over a w × h image (see the module doc)."""

    def __init__(
        self,
        w: int,
        h: int,
        shift_px: float,
        flicker: float,
        seed: int = 1,
        px_per_m: float = 65.0,
        shortest_px: float = 4.0,
        waves: int = 60,
        cell_px: float = 30.0,
    ):
        rng = np.random.default_rng(seed)
        lam = np.exp(
            np.linspace(math.log(shortest_px), math.log(300.0), waves)
            + rng.uniform(-0.05, 0.05, waves)
        )
        k = 2 * np.pi / lam
        heading = rng.normal(0.3, 0.8, waves)  # mostly downwind
        self.kx, self.ky = k * np.cos(heading), k * np.sin(heading)
        self.omega = np.sqrt(9.81 * k * px_per_m)  # rad/s, deep water (k in rad/px)
        self.phase = rng.uniform(0, 2 * np.pi, waves)
        # heights: each wave moves the image by amp·k, all alike
        self.amp = 2.0 * shift_px / math.sqrt(waves) / k
        kc = 2 * np.pi / (cell_px * np.exp(rng.uniform(math.log(0.5), math.log(2.5), 30)))
        tc = rng.uniform(0, 2 * np.pi, 30)
        self.kcx, self.kcy = kc * np.cos(tc), kc * np.sin(tc)
        self.omega_c = 0.3 * np.sqrt(9.81 * kc * px_per_m)
        self.phase_c = rng.uniform(0, 2 * np.pi, 30)
        self.flicker = flicker
        self.xs, self.ys = np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32)

    def _sum(self, kx, ky, coef) -> np.ndarray:
        """Re Σ coef·exp(i(kx·x + ky·y)) over the image (h, w), float32: each wave is separable."""
        return (
            (np.exp(1j * np.outer(self.ys, ky)) * coef) @ np.exp(1j * np.outer(kx, self.xs))
        ).real.astype(np.float32)

    def apply(self, frame_bgr: np.ndarray, t_s: float) -> np.ndarray:
        """The frame seen through the waves at time ``t_s`` (seconds)."""
        c = self.amp * np.exp(1j * (self.phase - self.omega * t_s))
        fx, fy = np.meshgrid(self.xs, self.ys)
        map_x = fx + self._sum(self.kx, self.ky, 1j * self.kx * c)
        map_y = fy + self._sum(self.kx, self.ky, 1j * self.ky * c)
        out = cv2.remap(
            frame_bgr, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT
        ).astype(np.float32)
        if self.flicker > 0:
            n = self._sum(
                self.kcx, self.kcy, np.exp(1j * (self.phase_c - self.omega_c * t_s))
            ) / math.sqrt(15.0)
            out *= (1.0 + self.flicker * (2.0 * np.exp(-np.abs(n) / 0.15) - 0.3))[..., None]
        return np.clip(out, 0, 255).astype(np.uint8)


def through_waves(
    src: str | Path,
    dst: str | Path,
    shift_px: float,
    flicker: float,
    kbps: int = 4000,
    seed: int = 1,
) -> Path:
    """A copy of session ``src`` at ``dst`` whose video is seen through :class:`WaveProxy` waves, re-encoded."""
    src, dst = Path(src), Path(dst)
    shutil.copytree(src, dst)
    session = load_session(src)
    t = session.frames["t"]
    fps = 1.0 / float(np.median(np.diff(t)))
    with open_video(session.video_path) as video:
        frames = [f.image for f in video]
    h, w = frames[0].shape[:2]
    proxy = WaveProxy(w, h, shift_px, flicker, seed)
    video = dst / Path(session.video_path).name
    cmd = [
        "ffmpeg",
        "-v",
        "error",
        "-y",
        "-f",
        "rawvideo",
        "-pix_fmt",
        "bgr24",
        "-s",
        f"{w}x{h}",
        "-r",
        f"{fps:g}",
        "-i",
        "-",
        "-an",
        "-c:v",
        "libx264",
        "-preset",
        "veryfast",
        "-b:v",
        f"{kbps}k",
        "-maxrate",
        f"{kbps}k",
        "-bufsize",
        f"{kbps}k",
        "-bf",
        "0",
        "-g",
        f"{round(fps)}",
        "-pix_fmt",
        "yuv420p",
        str(video),
    ]
    with subprocess.Popen(cmd, stdin=subprocess.PIPE) as encoder:
        for i, frame in enumerate(frames):
            bgr = frame if frame.ndim == 3 else cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR)
            encoder.stdin.write(proxy.apply(bgr, i / fps).tobytes())
        encoder.stdin.close()
    if encoder.returncode:
        raise RuntimeError(f"ffmpeg exited with status {encoder.returncode}")
    return dst

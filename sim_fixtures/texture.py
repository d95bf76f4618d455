"""Procedural, tileable textures fixed in the world: seafloor albedo, caustic and sparkle patterns.

Made by spectral synthesis (white noise shaped in the Fourier domain), so every
texture wraps seamlessly; deterministic for a numpy Generator. Pixel values of
the seafloor are BGR 0-255 (uint8); patterns are float32 in [0, 1].
"""

from __future__ import annotations

import cv2
import numpy as np


def fractal_noise(
    rng, size: int, beta: float, min_period_px: float = 2.0, max_period_px: float | None = None
) -> np.ndarray:
    """Tileable noise (size × size, float32, zero mean, unit std) with a 1/f^beta amplitude spectrum
    between periods ``min_period_px`` and ``max_period_px`` (default: the tile)."""
    f = np.fft.fftfreq(size)
    fr = np.hypot(f[:, None], f[None, :])
    fr[0, 0] = 1.0
    amp = fr ** (-beta) * (fr < 1.0 / min_period_px)
    if max_period_px is not None:
        amp *= fr > 1.0 / max_period_px
    amp[0, 0] = 0.0
    spec = np.fft.fft2(rng.standard_normal((size, size))) * amp
    out = np.fft.ifft2(spec).real
    return ((out - out.mean()) / out.std()).astype(np.float32)


def seafloor(rng, size: int = 2048, m_per_px: float = 0.015) -> np.ndarray:
    """Sand with ripples, darker weed patches and pebbles: (size, size, 3) uint8 BGR."""
    y, x = np.mgrid[0:size, 0:size].astype(np.float32) * m_per_px
    tile_m = size * m_per_px
    waves = tile_m / 0.35  # sand ripples ~0.35 m apart, whole numbers of them across the tile
    kx, ky = (2 * np.pi * round(c * waves) / tile_m for c in (0.8, 0.6))
    ripples = np.sin(kx * x + ky * y + 2.5 * fractal_noise(rng, size, 1.8))
    grain = fractal_noise(rng, size, 1.0)
    lum = 1.0 + 0.10 * ripples + 0.12 * grain + 0.10 * fractal_noise(rng, size, 2.0)
    sand = np.array([118.0, 160.0, 186.0], np.float32)
    weed = np.array([62.0, 104.0, 86.0], np.float32)
    soft = np.clip((fractal_noise(rng, size, 2.4) - 0.6) * 2.0, 0.0, 1.0)[..., None]  # weed patches
    img = (sand * (1 - soft) + weed * soft) * lum[..., None]
    n_pebbles = int(size * size * 4e-4)
    cx, cy = rng.integers(0, size, n_pebbles), rng.integers(0, size, n_pebbles)
    radius = rng.uniform(0.01, 0.05, n_pebbles) / m_per_px
    shade = rng.uniform(0.35, 1.25, n_pebbles)
    for x0, y0, r, s in zip(cx, cy, radius, shade):
        y_lo, y_hi = max(0, int(y0 - r)), min(size, int(y0 + r) + 1)
        x_lo, x_hi = max(0, int(x0 - r)), min(size, int(x0 + r) + 1)
        yy, xx = np.ogrid[y_lo:y_hi, x_lo:x_hi]
        inside = (yy - y0) ** 2 + (xx - x0) ** 2 <= r * r
        img[y_lo:y_hi, x_lo:x_hi][inside] *= s
    return np.clip(img, 0, 255).astype(np.uint8)


def caustics(rng, size: int = 512) -> np.ndarray:
    """Bright thin web where a smooth field crosses zero, like sunlight focused by waves: float32 [0, 1]."""
    n = fractal_noise(rng, size, 1.5, min_period_px=8.0, max_period_px=70.0)
    return np.exp(-np.abs(n) / 0.15).astype(np.float32)


REMAP_COLS = 1024  # cv2.remap's maps are images, at most 32767 a side: points are laid out in rows of this many


def sample(image: np.ndarray, x_px, y_px, interpolation: int, border: int) -> np.ndarray:
    """``image`` (float32, one channel) at the points (``x_px``, ``y_px``) (N,), by cv2.remap: (N,) float32."""
    n = len(x_px)
    rows = -(-n // REMAP_COLS)
    xy = np.zeros((rows * REMAP_COLS, 2), np.float32)
    xy[:n, 0], xy[:n, 1] = x_px, y_px
    return cv2.remap(
        image, xy.reshape(rows, REMAP_COLS, 2), None, interpolation, borderMode=border
    ).ravel()[:n]

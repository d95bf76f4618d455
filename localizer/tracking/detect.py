"""Finding a vehicle-sized object without knowing what it looks like: contrast to the local background.

Before anything has been tracked there is no template, only where the UUV should
be and how large it should look (a :class:`~localizer.tracking.Prediction`, e.g.
the UUV's own position estimate projected into the frame). :func:`detect`
looks there for the place that stands out most from its surroundings at that size:

1. The window (``search_sigmas`` prediction sigmas around it, at least the vehicle's
   size) is block-averaged so the footprint is about ``block_px`` blocks across.
2. Each block's colour deviation from its local background (a box mean
   ``background_sides`` footprints wide), squared and averaged over the footprint, is
   its *saliency* relative to the window's median: a vehicle of mixed dark frame and
   light hull scores in the hundreds on a caustic-lit seafloor, whose own texture
   scores tens.
3. The best place counts if it scores at least ``min_saliency`` and ``distinct``
   times the best place elsewhere (one vehicle, not one bright patch among many).
4. Its outline (:func:`outline`): at full resolution, pixels deviating from a median
   background by more than Otsu's threshold (and ``noise_sigmas`` robust sigmas)
   near it, less the shade (:func:`shade`: the seafloor darkened evenly in every colour,
   in a patch too broad to be the vehicle's dark frame: the UUV's shadow on a shallow
   sunlit bottom, touching it or not); the box around the largest such region and those
   touching it must be vehicle-sized (its longer side ``size_range`` × the footprint's
   diagonal).

The shade is left out of the saliency too: a shadow beside the vehicle is dark and
vehicle-sized, and would otherwise stand out as much as the vehicle.

The box is around the whole visible vehicle, like an operator's; the caller turns
its centre into the top face's (:func:`~localizer.tracking.predict.top_face_pixel`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from . import Prediction


@dataclass(frozen=True)
class DetectParams:
    search_sigmas: float = 3.0  # window half-size in prediction sigmas
    block_px: float = 8.0  # the footprint's side (geometric mean) after block averaging
    background_sides: float = 3.0  # the local background: a box this many footprint sides wide
    min_saliency: float = 25.0  # the object's deviation energy over the window's median
    distinct: float = 2.0  # ... and this many times the best elsewhere in the window
    noise_sigmas: float = 4.0  # outline: pixels deviating more than this many robust sigmas ...
    size_range: tuple[float, float] = (
        0.5,
        2.0,
    )  # ... whose box's longer side is this × the footprint's diagonal
    shade_range: tuple[float, float] = (
        0.15,
        0.85,
    )  # shade: the background darkened to this share of itself ...
    shade_hue: float = 0.12  # ... each colour within this share of the others' darkening ...
    shade_width: float = 0.25  # ... in a patch at least this share of the footprint's side wide


@dataclass(frozen=True)
class Detection:
    """A vehicle-sized object: its box (x, y, w, h, full-resolution pixels), the box's centre, its saliency."""

    box: tuple[int, int, int, int]
    u: float
    v: float
    saliency: float


def _odd(x: float) -> int:
    return max(3, round(x) | 1)


@dataclass(frozen=True)
class Saliency:
    """Each place's saliency in a prediction's window (see the module doc): ``map`` per block (0 outside the window),
    the blocks' centres ``bu`` (columns) and ``bv`` (rows) in full-resolution pixels, the block's side ``f`` and the
    footprint's diagonal ``diag`` (pixels)."""

    map: np.ndarray
    bu: np.ndarray
    bv: np.ndarray
    f: int
    diag: float


def detect(
    frame_bgr: np.ndarray, prediction: Prediction, params: DetectParams | None = None
) -> Detection | None:
    """The most salient vehicle-sized object in the prediction's window, or None (see the module doc)."""
    p = params or DetectParams()
    found = saliency(frame_bgr, prediction, p)
    return None if found is None else standing_out(frame_bgr, found, p)


def saliency(
    frame_bgr: np.ndarray, prediction: Prediction, params: DetectParams | None = None
) -> Saliency | None:
    """Each place's saliency in the prediction's window (steps 1-2 of the module doc); None: no window to read."""
    p = params or DetectParams()
    side = math.sqrt(prediction.width_px * prediction.height_px)
    diag = math.hypot(prediction.width_px, prediction.height_px)
    if not (side > 2 and math.isfinite(prediction.u) and math.isfinite(prediction.v)):
        return None
    H, W = frame_bgr.shape[:2]
    sigma = prediction.sigma_px if math.isfinite(prediction.sigma_px) else float(max(W, H))
    radius = p.search_sigmas * sigma + diag / 2
    pad = p.background_sides * side
    x0, y0 = max(0, int(prediction.u - radius - pad)), max(0, int(prediction.v - radius - pad))
    x1, y1 = (
        min(W, int(prediction.u + radius + pad) + 1),
        min(H, int(prediction.v + radius + pad) + 1),
    )
    f = max(1, round(side / p.block_px))
    w, h = (x1 - x0) // f, (y1 - y0) // f
    if w < 3 or h < 3:
        return None
    small = cv2.resize(
        frame_bgr[y0 : y0 + h * f, x0 : x0 + w * f], (w, h), interpolation=cv2.INTER_AREA
    )
    small = small.astype(np.float32).reshape(h, w, -1)
    s = side / f
    background = cv2.blur(small, (_odd(p.background_sides * s),) * 2).reshape(h, w, -1)
    energy = np.sum((small - background) ** 2, axis=2)
    energy[shade(small, background, s, p)] = 0.0
    ratio = cv2.blur(energy, (_odd(0.8 * s),) * 2) / max(float(np.median(energy)), 1e-6)
    # only places within the window (block centres in full-resolution pixels)
    bu = x0 + np.arange(w) * f + (f - 1) / 2.0
    bv = y0 + np.arange(h) * f + (f - 1) / 2.0
    inside = np.hypot(bu[None, :] - prediction.u, bv[:, None] - prediction.v) <= radius
    return Saliency(np.where(inside, ratio, 0.0).astype(np.float32), bu, bv, f, diag)


def standing_out(
    frame_bgr: np.ndarray, found: Saliency, params: DetectParams | None = None
) -> Detection | None:
    """The best place of ``found`` (the saliencies of ``frame_bgr``'s window) when it stands out, with its outline in
    ``frame_bgr`` (steps 3-4 of the module doc); None otherwise."""
    p = params or DetectParams()
    _, best, _, (j, i) = cv2.minMaxLoc(found.map)
    if best < p.min_saliency:
        return None
    elsewhere = found.map.copy()
    cv2.circle(elsewhere, (j, i), math.ceil(1.5 * found.diag / found.f), 0.0, -1)
    if best < p.distinct * float(elsewhere.max()):
        return None
    box = outline(frame_bgr, float(found.bu[j]), float(found.bv[i]), found.diag, p)
    if box is None:
        return None
    x, y, bw, bh = box
    return Detection(box, x + (bw - 1) / 2.0, y + (bh - 1) / 2.0, float(best))


def shade(
    image: np.ndarray, background: np.ndarray, side_px: float, params: DetectParams | None = None
) -> np.ndarray:
    """Where ``image`` is its ``background`` in shade: boolean mask (a grey image has no colour to tell: none).

    Shade darkens the seafloor evenly in every colour (to ``shade_range`` of itself, each
    colour within ``shade_hue`` of the others); a vehicle's parts change its colour. Only
    patches at least ``shade_width`` × ``side_px`` (the footprint's side, in the images'
    pixels) wide count, so a dark, thin frame around a vehicle's hull is never shade; with
    their soft rim (2 pixels).
    """
    p = params or DetectParams()
    if image.ndim != 3 or image.shape[2] != 3:
        return np.zeros(image.shape[:2], bool)
    ratio = image.astype(np.float32) / np.maximum(background.astype(np.float32), 1.0)
    dark = ratio.mean(axis=2)
    even = np.abs(ratio - dark[..., None]).max(axis=2) <= p.shade_hue * dark
    mask = ((dark >= p.shade_range[0]) & (dark <= p.shade_range[1]) & even).astype(np.uint8)
    k = max(3, round(p.shade_width * side_px) | 1)
    mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, np.ones((k, k), np.uint8))
    return cv2.dilate(mask, np.ones((5, 5), np.uint8)).astype(bool)  # with its soft rim


def outline(
    frame_bgr: np.ndarray, u: float, v: float, diag_px: float, params: DetectParams | None = None
) -> tuple[int, int, int, int] | None:
    """Box (x, y, w, h) around the object near (u, v) whose footprint's diagonal is ``diag_px``, or None."""
    p = params or DetectParams()
    H, W = frame_bgr.shape[:2]
    g = max(1, int(diag_px // 32))  # work with the diagonal at most 32-63 pixels
    r = diag_px / g  # working pixels
    m = math.ceil(2 * diag_px)
    x0, y0 = max(0, int(u) - m), max(0, int(v) - m)
    x1, y1 = min(W, int(u) + m + 1), min(H, int(v) + m + 1)
    w, h = (x1 - x0) // g, (y1 - y0) // g
    if w < 5 or h < 5:
        return None
    win = frame_bgr[y0 : y0 + h * g, x0 : x0 + w * g]
    if g > 1:
        win = cv2.resize(win, (w, h), interpolation=cv2.INTER_AREA)
    win = win.reshape(h, w, -1)
    background = cv2.medianBlur(win, min(_odd(2.5 * r), 255)).reshape(h, w, -1)
    dev = np.sqrt(np.sum((win.astype(np.float32) - background) ** 2, axis=2))
    # the seafloor in shade is no part of the vehicle
    dev[shade(win, background, r / math.sqrt(2.0), p)] = 0.0
    yy, xx = np.mgrid[0:h, 0:w]
    near = np.hypot(xx - ((u - x0) - (g - 1) / 2.0) / g, yy - ((v - y0) - (g - 1) / 2.0) / g) < r
    top = float(dev[near].max()) if near.any() else 0.0
    if top <= 0:
        return None
    otsu, _ = cv2.threshold(
        np.round(dev[near] * (255.0 / top)).astype(np.uint8),
        0,
        255,
        cv2.THRESH_BINARY + cv2.THRESH_OTSU,
    )
    threshold = max(otsu * top / 255.0, p.noise_sigmas * 1.4826 * float(np.median(dev)))
    mask = cv2.morphologyEx(
        ((dev > threshold) & near).astype(np.uint8), cv2.MORPH_CLOSE, np.ones((3, 3), np.uint8)
    )
    found = _region_box(mask)
    if found is None:
        return None
    bx, by, bw, bh = found
    box = (int(x0 + bx * g), int(y0 + by * g), int(bw * g), int(bh * g))
    lo, hi = p.size_range
    if not lo * diag_px <= max(box[2], box[3]) <= hi * diag_px:
        return None
    return box


def _region_box(mask: np.ndarray) -> tuple[int, int, int, int] | None:
    """Box (x, y, w, h) around a mask's largest region and the regions touching its box; None for an empty mask."""
    n, _, stats, _ = cv2.connectedComponentsWithStats(mask)
    if n < 2:
        return None
    main = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    mx, my, mw, mh = stats[main, :4]
    touching = [
        c
        for c in range(1, n)
        if stats[c, 0] <= mx + mw + 2
        and stats[c, 0] + stats[c, 2] >= mx - 2
        and stats[c, 1] <= my + mh + 2
        and stats[c, 1] + stats[c, 3] >= my - 2
    ]
    bx0 = min(stats[c, 0] for c in touching)
    by0 = min(stats[c, 1] for c in touching)
    bx1 = max(stats[c, 0] + stats[c, 2] for c in touching)
    by1 = max(stats[c, 1] + stats[c, 3] for c in touching)
    return int(bx0), int(by0), int(bx1 - bx0), int(by1 - by0)

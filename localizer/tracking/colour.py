"""Whether a tracked place has the UUV's colour: a check of the lock, not a tracker (issue 28).

Through wind waves a deep UUV's grey levels break up, and caustic-lit seafloor matches its grey template and its
contrast as well as the vehicle does: a lock can creep off the vehicle onto the seafloor and be followed there as
if it were the UUV (bench/results/tracker_waves_wrong_s45_s15.txt). The vehicle's colour tells them apart where
its grey levels do not: a BlueROV2's hull stands out of sand or weed in the chroma channels, and a caustic changes
how bright the seafloor is, not its hue.

When tracking starts on a box or a click (:meth:`~localizer.tracking.session.TrackingSession.select`), the
vehicle's colour is learnt on that frame (:func:`learn`): the direction in the two chroma channels (Cb, Cr) in
which the central half of the vehicle's square stands out most from a ring round it (Fisher's discriminant, the two
regions' pooled covariance plus one level² of noise), and the separation along it there. Every frame tracked
after, the same separation is read at the tracked pixel (:func:`separation`): the central half's mean against the
ring's, in units of the ring's spread along the learnt direction. On the vehicle it stays near the learnt one;
on seafloor that only matches the grey template it is near 0 (the place's colour is its surroundings').

:func:`find` reads every place of a window at once (box filters of the learnt channel): where the vehicle's colour
stands out most, for a tracker that lost it through waves to start again there.

A vehicle whose colour does not stand out when it is selected (:data:`LEARN_MIN_SEPARATION`: a grey hull on grey
sand) gets no model, and no check: the check never refuses what it cannot tell.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

#: A vehicle whose chroma separation at its selection is below this gets no colour model (nothing to check with).
LEARN_MIN_SEPARATION = 2.0
#: A tracked place whose separation along the learnt direction is below this (ring spreads) does not have the
#: vehicle's colour.
MIN_SEPARATION = 1.0
#: The ring about the vehicle's square reaches this many half-lengths from its centre.
RING_HALVES = 3


class Chroma:
    """A frame's two chroma channels (Cb, Cr), read where needed: a yuv420p frame's planes as decoded (half
    resolution), or a BGR image's converted window by window (OpenCV's YCrCb)."""

    def __init__(self, cb: np.ndarray | None = None, cr: np.ndarray | None = None, bgr=None):
        self._cb, self._cr, self._bgr = cb, cr, bgr
        if bgr is not None:
            self.shape = bgr.shape[:2]
            self.scale = 1.0
        else:
            self.shape = cb.shape
            self.scale = 0.5  # yuv420p: one chroma sample per 2 x 2 pixels

    def copy(self) -> Chroma:
        """The same colour in arrays of its own (a frame kept beyond the decoder's buffer)."""
        if self._bgr is not None:
            return Chroma(bgr=self._bgr.copy())
        return Chroma(self._cb.copy(), self._cr.copy())

    @classmethod
    def of(cls, image: np.ndarray, planes=None) -> Chroma | None:
        """A frame's chroma: from its yuv420p ``planes`` (Y, U, V) when given, else from ``image`` when it is BGR;
        None for a grey image alone."""
        if planes is not None and len(planes) == 3:
            return cls(planes[1], planes[2])
        if image.ndim == 3 and image.shape[2] == 3:
            return cls(bgr=image)
        return None

    def square(self, u: float, v: float, half_px: float):
        """The chroma channels (Cb, Cr), each (n, m) uint8, of the square of half-side ``half_px`` (image pixels)
        about the image pixel (u, v), clipped to the frame, and (u, v) in its samples; None when (u, v) is off the
        frame."""
        s = self.scale
        cu, cv_ = (u + 0.5) * s - 0.5, (v + 0.5) * s - 0.5
        h = half_px * s
        rows, cols = self.shape
        if not (0 <= cu < cols and 0 <= cv_ < rows):
            return None
        x0, y0 = max(math.floor(cu - h), 0), max(math.floor(cv_ - h), 0)
        x1, y1 = min(math.ceil(cu + h) + 1, cols), min(math.ceil(cv_ + h) + 1, rows)
        if self._bgr is not None:
            ycrcb = cv2.cvtColor(np.ascontiguousarray(self._bgr[y0:y1, x0:x1]), cv2.COLOR_BGR2YCrCb)
            return ycrcb[:, :, 2], ycrcb[:, :, 1], cu - x0, cv_ - y0
        return self._cb[y0:y1, x0:x1], self._cr[y0:y1, x0:x1], cu - x0, cv_ - y0


@dataclass(frozen=True)
class ColourModel:
    """The vehicle's colour as learnt: ``weights`` of (Cb, Cr) and its ``separation`` along them then."""

    weights: np.ndarray
    separation: float

    def matches(self, separation_now: float) -> bool:
        """Whether a place's separation (:func:`separation`) is the vehicle's; NaN (not read): taken as it is."""
        return not separation_now < MIN_SEPARATION


@dataclass(frozen=True)
class _Region:
    """A region's pixels in (Cb, Cr): their count, ``mean`` (2,) and ``scatter`` (2, 2): the sum of the outer
    products of their deviations from the mean."""

    n: int
    mean: np.ndarray
    scatter: np.ndarray

    @classmethod
    def of(cls, sums: list[int]) -> _Region:
        """From the exact sums ``[n, Σb, Σr, Σb², Σbr, Σr²]`` of its pixels' channels b, r (n > 0)."""
        n, sb, sr, sbb, sbr, srr = sums
        # n·Σxxᵀ − ΣxΣxᵀ in Python's integers, exact: the scatter's one rounding is the division
        scatter = (
            np.array(
                [[n * sbb - sb * sb, n * sbr - sb * sr], [n * sbr - sb * sr, n * srr - sr * sr]]
            )
            / n
        )
        return cls(n, np.array([sb, sr]) / n, scatter)


def _within(n: int, centre: float, reach: float) -> slice:
    """The samples 0..n-1 within ``reach`` of ``centre`` (a run: empty when none is)."""
    near = np.flatnonzero(np.abs(np.arange(n) - centre) <= reach)
    return slice(int(near[0]), int(near[-1]) + 1) if len(near) else slice(0, 0)


def _regions(chroma: Chroma, u: float, v: float, half_px: float) -> tuple[_Region, _Region] | None:
    """(central half, ring) of the vehicle's square of half-side ``half_px`` at (u, v): the pixels within half of it
    (Chebyshev distance), and those beyond it up to :data:`RING_HALVES` of it; None when either is too small to read
    (off the frame). Their moments come from exact integer sums over rectangles (the ring: the square less its hole),
    no pixel is gathered."""
    got = chroma.square(u, v, RING_HALVES * half_px)
    if got is None:
        return None
    cb, cr, cu, cv_ = got
    h = half_px * chroma.scale
    b, r = cb.astype(np.uint16), cr.astype(np.uint16)  # a product of two 8-bit levels fits 16 bits
    products = (b, r, b * b, b * r, r * r)

    def sums(rows: slice, cols: slice) -> list[int]:
        return [b[rows, cols].size] + [int(p[rows, cols].sum(dtype=np.int64)) for p in products]

    (rows, cols), reach = b.shape, max(h / 2, 0.5)
    inner = sums(_within(rows, cv_, reach), _within(cols, cu, reach))
    hole = sums(_within(rows, cv_, h), _within(cols, cu, h))
    ring = [whole - held for whole, held in zip(sums(slice(None), slice(None)), hole, strict=True)]
    if inner[0] < 1 or ring[0] < 8:
        return None
    return _Region.of(inner), _Region.of(ring)


def learn(
    chroma: Chroma | None,
    u: float,
    v: float,
    half_px: float,
    min_separation: float = LEARN_MIN_SEPARATION,
) -> ColourModel | None:
    """The vehicle's colour at its pixel (u, v), its square's half-side ``half_px`` (half its apparent length);
    None when it does not stand out in colour (``min_separation``) or cannot be read there."""
    if chroma is None or not half_px >= 1:
        return None
    regions = _regions(chroma, u, v, half_px)
    if regions is None:
        return None
    inner, ring = regions
    pooled = (
        ring.scatter / (ring.n - 1)
        + (inner.scatter / (inner.n - 1) if inner.n > 2 else 0)
        + np.eye(2)
    )
    # the means' difference in float32, as the model has always been learnt: its last bits move find()'s best place
    # between two that stand out equally (bench/same_outputs.py)
    weights = np.linalg.solve(pooled, inner.mean.astype(np.float32) - ring.mean.astype(np.float32))
    d = _separation(weights, inner, ring)
    return ColourModel(weights, d) if d >= min_separation else None


def separation(model: ColourModel, chroma: Chroma, u: float, v: float, half_px: float) -> float:
    """How far the place (u, v) stands out of the ring round it along the learnt colour (ring spreads); NaN where
    it cannot be read."""
    if not half_px >= 1:
        return math.nan
    regions = _regions(chroma, u, v, half_px)
    return math.nan if regions is None else _separation(model.weights, *regions)


def _separation(w: np.ndarray, inner: _Region, ring: _Region) -> float:
    """The inner region's mean against the ring's along ``w``, in units of the ring's spread along it."""
    spread_sq = float(w @ ring.scatter @ w) / ring.n
    return float((inner.mean - ring.mean) @ w / math.sqrt(spread_sq + 1e-6))


def find(
    model: ColourModel, chroma: Chroma, window: tuple[float, float, float, float], half_px: float
) -> tuple[float, float, float, float] | None:
    """The place in ``window`` (x, y, w, h image pixels) that stands out most in the vehicle's colour: ``(u, v,
    separation, second)``, its :func:`separation` and the best separation more than a vehicle's length
    (2 x ``half_px``) from it; None where nothing in it can be read. Every place's separation at once (box filters of
    the learnt channel), the best one's read again as :func:`separation` reads one."""
    if not half_px >= 1:
        return None
    x, y, w, h = window
    reach = RING_HALVES * half_px
    got = chroma.square(x + w / 2, y + h / 2, max(w, h) / 2 + reach)
    if got is None:
        return None
    cb, cr, cu, cv_ = got
    s = chroma.scale
    level = np.dstack((cb, cr)).astype(np.float32) @ model.weights.astype(np.float32)
    inner_r, hole_r, ring_r = max(round(half_px * s / 2), 0), round(half_px * s), round(reach * s)
    if min(level.shape) <= 2 * ring_r + 1:
        return None

    def sums(a: np.ndarray, r: int) -> np.ndarray:
        return cv2.boxFilter(
            a, -1, (2 * r + 1, 2 * r + 1), normalize=False, borderType=cv2.BORDER_CONSTANT
        )

    n_inner, n_hole, n_ring = (2 * inner_r + 1) ** 2, (2 * hole_r + 1) ** 2, (2 * ring_r + 1) ** 2
    squared = level * level
    ring_sum = sums(level, ring_r) - sums(level, hole_r)
    ring_sq = sums(squared, ring_r) - sums(squared, hole_r)
    ring_mean = ring_sum / (n_ring - n_hole)
    ring_var = np.maximum(ring_sq / (n_ring - n_hole) - ring_mean**2, 0.0)
    d = (sums(level, inner_r) / n_inner - ring_mean) / np.sqrt(ring_var + 1e-6)
    # only centres whose ring lies within the region read, and inside the window
    ys, xs = np.mgrid[: level.shape[0], : level.shape[1]]
    u_img, v_img = (
        (xs + (x + w / 2 + 0.5) * s - 0.5 - cu + 0.5) / s - 0.5,
        (ys + (y + h / 2 + 0.5) * s - 0.5 - cv_ + 0.5) / s - 0.5,
    )
    inside = (
        (xs >= ring_r)
        & (xs < level.shape[1] - ring_r)
        & (ys >= ring_r)
        & (ys < level.shape[0] - ring_r)
        & (u_img >= x)
        & (u_img <= x + w)
        & (v_img >= y)
        & (v_img <= y + h)
    )
    if not inside.any():
        return None
    d = np.where(inside, d, -np.inf)
    best = np.unravel_index(np.argmax(d), d.shape)
    u, v = float(u_img[best]), float(v_img[best])
    # the best place more than a vehicle's length from it: a second vehicle of the same colour makes it ambiguous
    away = (np.abs(u_img - u) > 2 * half_px) | (np.abs(v_img - v) > 2 * half_px)
    second = float(np.max(d[away], initial=-np.inf))
    return u, v, separation(model, chroma, u, v, half_px), second

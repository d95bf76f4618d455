"""The UUV's outline in a frame, fitted to the image's edges: the camera's height from the vehicle's size.

Given the tracked pixel of the UUV's top face, its depth, the camera's attitude and the
vehicle's size (``[uuv]``), :func:`measure` finds the camera height (and the vehicle's heading,
and the top face's pixel) at which the projected box's outline (:mod:`localizer.size_range`)
lies on the vehicle's outline in the image.

An *edge* along an outline's outward normal is a peak of the colour's change between samples
``step_px`` apart that stands ``noise_factor`` times above the water's own change there (its
median 1-3 px beyond ``reach_px`` outside the outline: waves, caustics, the seafloor). An
outline is *supported* at a point when there is an edge within ``agree_px`` of it and none
further out within ``clear_px``: the vehicle's outline is the outermost closed edge around it.
Its inner edges (a hull against its frame, thrusters, buoyancy blocks) are often stronger than
its outline against dark water, so the outermost edge is what counts, never the strongest.

1. Heading: a vehicle's structure is aligned with its axes. The gradient orientations of the
   image around the tracked pixel, folded modulo 90° (weighted by the gradient's square), give
   the direction of its axes in the image; the two headings whose forward axis appears along
   either of them are the candidates.
2. Size: for each, outlines of heights from ``scan_from`` to ``scan_to`` times the configured one
   (``scan_step`` apart), centred on the tracked pixel, are scored by the share of their points
   they are supported at; the largest supported nearly as well as the best (``near_best``) is the
   start: the vehicle's inner structure may be as well supported.
3. Fit, in up to ``passes`` passes: the outermost edge within ``fit_reach_px`` of each point of
   the outline, and how each point moves with the height, heading and pixel, give a linear
   least-squares step; again without the points more than 3 robust sigmas off; until a pass moves
   the height less than 0.2 %, the heading less than 0.02 rad and the pixel less than 0.25 px (from
   the third pass on, each step half the one before: an edge point may flip between two peaks from
   pass to pass).
4. Checks: the outline lies inside the frame and is at least ``min_size_px`` large (the square root
   of its area), enough of its points found an edge, it is supported
   at ``min_support`` of its points, the residual is at most ``max_rms_px``, the height within a
   factor of two of the configured one. Otherwise no measurement, and why (:data:`REJECTIONS`).

The height's 1-sigma is the fit's (residuals, and how strongly they constrain the height), the
neighbouring points' errors counted as correlated over :data:`EDGE_CORRELATION_PX` of outline
(the image's blur); what the fit cannot see (the vehicle's true size, its depth) the caller adds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from ..calibration import Uuv
from ..camera import Camera
from ..ray import pixel_to_offset
from ..size_range import box_corners_px, edge_points, outline, point_to_pixel, polygon_area

#: Why a frame gives no measurement: the outline does not reach the water (``no_water``); it comes within
#: ``border_px`` of the frame's edge (``border``); it is smaller than ``min_size_px`` (``too_small``); no outline is
#: supported, or too few of its points found an edge (``few_edges``); the fit did not settle (``no_convergence``),
#: settled more than a factor of two from the configured height (``implausible``), or with a residual above
#: ``max_rms_px`` or a support below ``min_support`` (``poor_fit``).
REJECTIONS = (
    "no_water",
    "border",
    "too_small",
    "few_edges",
    "no_convergence",
    "implausible",
    "poor_fit",
)

#: The outline's length over which edge errors are alike (blur of the optics, the renderer's anti-aliasing,
#: video compression): the number of independent edge measurements is the outline's length over this.
EDGE_CORRELATION_PX = 2.0


@dataclass(frozen=True)
class SilhouetteParams:
    spacing_px: float = 1.0  # points this far apart along the outline
    trim: float = 0.15  # ... leaving out this share of each edge at both ends (blurred corners)
    reach_px: float = 3.0  # edges looked for this far either way along the normal ...
    step_px: float = 0.5  # ... sampled this often
    # an edge: a peak of the colour's change this many times the water's own
    noise_factor: float = 6.0
    # an edge this close to the outline supports it, when there is none further out ...
    agree_px: float = 0.75
    clear_px: float = 6.0  # ... up to this far
    # the vehicle's axes from gradients within this share of its diagonal of the pixel
    axes_radius: float = 0.7
    scan_from: float = 0.7  # outline sizes scanned: heights from this ...
    scan_to: float = 1.45  # ... to this times the configured height ...
    scan_step: float = 0.015  # ... this far apart (relative); the largest supported at least ...
    near_best: float = 0.8  # ... this share of the best's is the start
    fit_reach_px: float = 2.0  # the fit's edges: the outermost this far either way of its outline
    passes: int = 8
    min_found: float = 0.5  # at least this share of the points must find an edge
    min_support: float = 0.6  # the outline found must be supported at this share of its points
    max_rms_px: float = 0.6  # the fitted outline's residual, at most
    # the outline this far inside the frame (its edges are searched beyond it)
    border_px: float = 6.0
    # the outline's size (the square root of its area) at least: smaller, the vehicle's
    min_size_px: float = 16.0
    # inner structure and its outline are a pixel apart, and the water's texture as large as its parts (16-20 px:
    # fewer frames fit, each within its own larger 1-sigma; about 15 px: none)


@dataclass(frozen=True)
class SizeMeasurement:
    """One frame's outline fit."""

    camera_height_m: float  # the camera above the water
    sigma_m: float  # 1-sigma of the fit alone
    heading_rad: float  # the vehicle's heading from North (modulo π: the box is symmetric)
    u: float  # the top face's centre, distorted pixels
    v: float
    points: int  # edge points used
    rms_px: float  # their residual
    support: float  # the share of the outline's points with an edge there and none further out
    size_px: float  # the outline's size: the square root of its area


def measure(
    frame_bgr: np.ndarray,
    camera: Camera,
    R_ned_from_cv,
    u: float,
    v: float,
    uuv: Uuv,
    height_m: float,
    depth_m: float,
    n_water: float,
    params: SilhouetteParams | None = None,
) -> SizeMeasurement | str:
    """The camera height at which the vehicle's outline fits the frame (see the module doc), or why not: a word
    of :data:`REJECTIONS`.

    ``(u, v)``: the tracked pixel of the top face's centre; ``height_m``: the camera's configured
    height above the water; ``depth_m``: the top face's depth.
    """
    p = params or SilhouetteParams()
    R = np.asarray(R_ned_from_cv, dtype=float)
    H, W = frame_bgr.shape[:2]

    def corners(xs):
        """Corners (..., 8, 2) of the outlines of parameters xs (..., 4): height, heading, u, v; None if any is NaN."""
        c = box_corners_px(
            camera, R, xs[..., 2], xs[..., 3], xs[..., 1], uuv, xs[..., 0], depth_m, n_water
        )
        return c if np.all(np.isfinite(c)) else None

    headings = _headings(frame_bgr, camera, R, u, v, uuv, height_m, depth_m, n_water, p)
    if headings is None:
        return "no_water"
    # the largest outline last
    scales = np.exp(np.arange(math.log(p.scan_to), math.log(p.scan_from), -p.scan_step))
    # (2, S, 4)
    xs = np.stack(np.broadcast_arrays(height_m * scales[None, :], headings[:, None], u, v), axis=-1)
    c = corners(xs)
    if c is None:
        return "no_water"
    if not _inside(c[:, -1], W, H, p.border_px):  # the largest outlines
        return "border"
    configured = c[0, np.argmin(np.abs(scales - 1.0))]
    if math.sqrt(polygon_area(configured[outline(configured)])) < p.min_size_px:
        return "too_small"
    # the windows of the scan and of most passes, in float32 once
    floats = _Floats(frame_bgr, c.min(axis=(0, 1, 2)), c.max(axis=(0, 1, 2)), p.clear_px + 1.0)
    texture = _texture(floats, c[0, -1], p)
    support = np.array([_supports(floats, ch, texture, p) for ch in c])  # (2, S)
    if not support.max() > 0:
        return "few_edges"
    good = support >= p.near_best * support.max()
    # the largest outline nearly as well supported as the best
    k = int(np.flatnonzero(good.any(axis=0))[-1])
    x = xs[int(np.argmax(support[:, k])), k]
    # finite differences: height, heading, u, v
    steps = np.array([0.005 * height_m, 0.01, 0.25, 0.25])
    settled = np.array([0.002 * height_m, 0.02, 0.25, 0.25])  # a pass moving less: done
    for n in range(p.passes):
        c = corners(x + np.concatenate([np.zeros((1, 4)), np.diag(steps)]))
        if c is None:
            return "no_water"
        fit = _pass(floats, x, c, steps, texture, p)
        if isinstance(fit, str):
            return fit
        moved = fit.x - x
        if np.all(np.abs(moved) < settled):
            x = fit.x
            break
        # damped more and more: edges flipping from pass to pass would cycle
        x = x + moved * 0.5 ** max(0, n - 1)
    else:
        return "no_convergence"
    if not 0.5 * height_m <= x[0] <= 2.0 * height_m:
        return "implausible"
    if not (fit.rms_px <= p.max_rms_px and fit.support >= p.min_support):
        return "poor_fit"
    return SizeMeasurement(
        float(x[0]),
        fit.sigma_m,
        float(x[1] % math.pi),
        float(x[2]),
        float(x[3]),
        fit.points,
        fit.rms_px,
        fit.support,
        fit.size_px,
    )


def _headings(
    frame_bgr, camera: Camera, R, u, v, uuv: Uuv, height_m, depth_m, n_water, p: SilhouetteParams
):
    """The two candidate headings (2,) (step 1), or None where the pixel does not see the water."""
    d = max(depth_m, 0.0)
    n = n_water if depth_m > 0 else None
    centre, _ = pixel_to_offset(camera, R, u, v, height_m, d, n)
    psi = np.radians(np.arange(0.0, 180.0, 1.0))
    ahead = centre + 0.1 * np.stack([np.cos(psi), np.sin(psi)], axis=-1)
    au, av = point_to_pixel(camera, R, np.vstack([centre, ahead]), height_m, d, n_water)
    if not (np.all(np.isfinite(au)) and np.all(np.isfinite(av))):
        return None
    along = np.arctan2(av[1:] - av[0], au[1:] - au[0])  # the forward axis in the image
    diag = (
        math.hypot(uuv.length_m, uuv.width_m)
        * 10.0
        * float(np.max(np.hypot(au[1:] - au[0], av[1:] - av[0])))
    )
    axes = _axes_angle(frame_bgr, u, v, p.axes_radius * diag)
    off = (along - axes + math.pi / 4) % (
        math.pi / 2
    ) - math.pi / 4  # within ±45°: along either image axis
    first = int(np.argmin(np.abs(off)))
    apart = np.abs((psi - psi[first] + math.pi / 2) % math.pi - math.pi / 2) >= math.pi / 4
    second = int(np.argmin(np.where(apart, np.abs(off), np.inf)))
    return psi[[first, second]]


def _axes_angle(frame_bgr, u: float, v: float, radius_px: float) -> float:
    """The direction (radians, modulo π/2) of the axes of what is around (u, v): the gradients' orientations within
    ``radius_px`` folded modulo 90°, weighted by the gradient's square."""
    H, W = frame_bgr.shape[:2]
    r = max(3, math.ceil(radius_px))
    x0, y0 = max(0, round(u) - r), max(0, round(v) - r)
    win = frame_bgr[y0 : min(H, round(v) + r + 1), x0 : min(W, round(u) + r + 1)]
    grey = (cv2.cvtColor(win, cv2.COLOR_BGR2GRAY) if win.ndim == 3 else win).astype(np.float32)
    gx = cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=3)
    yy, xx = np.ogrid[0 : grey.shape[0], 0 : grey.shape[1]]
    near = np.hypot(xx + x0 - u, yy + y0 - v) <= radius_px
    gx, gy = gx[near], gy[near]
    z = _fourth_power(gx + 1j * gy) / np.maximum(gx**2 + gy**2, 1e-9)  # |g|², angle × 4
    return float(np.angle(z.sum()) / 4.0)


def _fourth_power(z: np.ndarray) -> np.ndarray:
    """``z ** 4`` of complex ``z``, the products numpy's power takes for it (``((z·z)·(z·z))·(1 + 0j)``, each written
    out in ``z``'s own precision), without its per-element loop: the same numbers, signed zeros included, at a
    third of its CPU."""
    r, i = z.real, z.imag
    r2, i2 = r * r - i * i, r * i + i * r
    r4, i4 = r2 * r2 - i2 * i2, r2 * i2 + i2 * r2
    out = np.empty_like(z)
    out.real, out.imag = r4 - 0 * i4, i4 + 0 * r4
    return out


def _inside(corners, W: int, H: int, border_px: float) -> bool:
    """Whether every outline of ``corners`` (..., 8, 2) lies ``border_px`` inside the frame."""
    lo, hi = corners.min(axis=-2), corners.max(axis=-2)
    return bool(
        np.all(lo >= border_px)
        and np.all(hi[..., 0] <= W - 1 - border_px)
        and np.all(hi[..., 1] <= H - 1 - border_px)
    )


@dataclass(frozen=True)
class _Fit:
    x: np.ndarray  # height, heading, u, v after the step
    sigma_m: float
    points: int
    rms_px: float
    support: float  # at the outline the pass started from
    size_px: float  # ... and its size


def _pass(frame_bgr, x, corners, steps, texture: float, p: SilhouetteParams) -> _Fit | str:
    """One pass of step 3 from the parameters ``x`` whose outline's corners (and those of each parameter stepped by
    ``steps``) are ``corners`` (5, 8, 2)."""
    c0 = corners[0]
    if not _inside(c0, frame_bgr.shape[1], frame_bgr.shape[0], p.border_px):
        return "border"
    hull = outline(c0)
    size_px = math.sqrt(polygon_area(c0[hull]))
    if size_px < p.min_size_px:
        return "too_small"
    pts = edge_points(c0, hull, p.spacing_px, p.trim)
    window, origin = _window(frame_bgr, c0.min(axis=0), c0.max(axis=0), p.clear_px + 1.0)
    edges = _edges(window, pts.xy - origin, pts.normal, texture, p)
    offset, seen = _outermost(edges, p.fit_reach_px, p.step_px)
    J = np.einsum("pkc,kc->kp", pts.moved(corners[1:]) - pts.xy, pts.normal) / steps  # (K, 4)
    need = max(8, p.min_found * len(offset))
    use = seen
    for _ in range(2):  # fit, then again without the points it explains worst
        if use.sum() < need:
            return "few_edges"
        step, *_ = np.linalg.lstsq(J[use], offset[use], rcond=None)
        resid = offset - J @ step
        spread = 1.4826 * _median(np.abs(resid[use]))
        use = use & (np.abs(resid) <= max(3.0 * spread, 0.5))
    if use.sum() < need:
        return "few_edges"
    step, *_ = np.linalg.lstsq(J[use], offset[use], rcond=None)
    resid = offset - J @ step
    rms = float(np.sqrt(np.sum(resid[use] ** 2) / (use.sum() - 4)))
    cov = np.linalg.inv(J[use].T @ J[use]) * rms**2 * max(1.0, EDGE_CORRELATION_PX / p.spacing_px)
    limit = np.array([0.2 * x[0], 0.3, p.fit_reach_px, p.fit_reach_px])
    return _Fit(
        x + np.clip(step, -limit, limit),
        float(np.sqrt(cov[0, 0])),
        int(use.sum()),
        rms,
        float(np.mean(_supported(edges, p))),
        size_px,
    )


def _bounds(shape, lo, hi, margin_px: float):
    """The rows and columns ``(y0, y1, x0, x1)`` of the frame (of ``shape``) around pixels ``lo``..``hi`` (and
    ``margin_px`` beyond, plus interpolation's pixel)."""
    H, W = shape[:2]
    x0, y0 = np.maximum(np.floor(np.asarray(lo) - margin_px).astype(int) - 1, 0)
    x1, y1 = np.minimum(np.ceil(np.asarray(hi) + margin_px).astype(int) + 2, (W, H))
    return int(y0), int(y1), int(x0), int(x1)


def _window(frame_bgr, lo, hi, margin_px: float):
    """The frame (or :class:`_Floats`) around pixels ``lo``..``hi`` (and ``margin_px`` beyond, plus interpolation's
    pixel) as float32, and its origin (x, y)."""
    y0, y1, x0, x1 = _bounds(frame_bgr.shape, lo, hi, margin_px)
    return frame_bgr[y0:y1, x0:x1].astype(np.float32, copy=False), np.array([x0, y0])


class _Floats:
    """A frame read as float32: the region around pixels ``lo``..``hi`` (as :func:`_window` reads it) converted once,
    its windows views of it (the same values: ``cv2.remap`` replicates a view's own border); others converted when
    read."""

    def __init__(self, frame_bgr, lo, hi, margin_px: float):
        self.frame, self.shape = frame_bgr, frame_bgr.shape
        self.y0, y1, self.x0, x1 = _bounds(self.shape, lo, hi, margin_px)
        self.region = frame_bgr[self.y0 : y1, self.x0 : x1].astype(np.float32)

    def __getitem__(self, key: tuple[slice, slice]) -> np.ndarray:
        rows, cols = key
        y0, x0 = rows.start - self.y0, cols.start - self.x0
        y1, x1 = rows.stop - self.y0, cols.stop - self.x0
        if y0 >= 0 and x0 >= 0 and y1 <= self.region.shape[0] and x1 <= self.region.shape[1]:
            return self.region[y0:y1, x0:x1]
        return self.frame[rows, cols].astype(np.float32)


#: ``cv2.remap`` takes maps narrower than this (SHRT_MAX): longer lists of points are sampled in parts.
_REMAP_MAX_COLS = 32766


def _changes(window: np.ndarray, xy: np.ndarray, normal: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The colour's change (len(t) - 1, ...) between consecutive samples ``t`` along the normals at points ``xy``
    (..., 2) (window pixels).

    Samples come first: each offset's samples over all points are a row (of as many points), so that NumPy's
    element-wise work runs over long rows (with the points last it was most of a measurement's time). The sample
    positions are computed in float64 and then rounded, as they always were: float32 arithmetic moves them by
    1e-5 px, and that moved 9 of 182 heights of ``bench/offline_speed.py``'s 1080p session by 0.2-35 mm (the fit
    follows edges that flip between peaks at that level)."""
    n = xy.size // 2
    XY = np.multiply.outer(t, normal.reshape(n, 2))  # (T, N, 2): x and y interleaved, one map
    XY += xy.reshape(n, 2)
    XY = XY.astype(np.float32)
    parts = [
        cv2.remap(
            window,
            XY[:, a : a + _REMAP_MAX_COLS],
            None,
            cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_REPLICATE,
        )
        for a in range(0, n, _REMAP_MAX_COLS)
    ]
    profile = (parts[0] if len(parts) == 1 else np.concatenate(parts, axis=1)).reshape(
        len(t), n, -1
    )
    d = np.subtract(profile[1:], profile[:-1])  # (T - 1, N, channels)
    d *= d
    if d.shape[-1] == 3:  # faster than sum() for 3, in place
        sq = np.add(d[..., 0], d[..., 1])
        sq += d[..., 2]
    else:
        sq = d.sum(axis=-1)
    return np.sqrt(sq, out=sq).reshape(len(t) - 1, *xy.shape[:-1])


def _texture(frame_bgr, corners, p: SilhouetteParams) -> float:
    """The water's own change between samples ``step_px`` apart: the median 1-3 px beyond the reach outside the
    outline of ``corners`` (8, 2)."""
    pts = edge_points(corners, outline(corners), p.spacing_px, p.trim)
    far = p.reach_px + 1.0
    window, origin = _window(frame_bgr, corners.min(axis=0), corners.max(axis=0), far + 2.0)
    return _median(
        _changes(window, pts.xy - origin, pts.normal, far + np.arange(0.0, 2.01, p.step_px)).ravel()
    )


def _median(x: np.ndarray) -> float:
    """``np.median`` of the values ``x`` (N,), N > 0: the same number (the middle one, or the two middle ones' mean in
    their own dtype; NaN if any is), without its overhead (most of its CPU on the fit's few hundred residuals)."""
    s = np.sort(x)
    if np.isnan(s[-1]):  # sorted last
        return math.nan
    k = len(s) // 2
    return float(s[k] if len(s) % 2 else (s[k - 1] + s[k]) / 2)


def _edges(window, xy, normal, texture: float, p: SilhouetteParams):
    """The edges along the outward normals at points ``xy`` (..., 2), from ``reach_px`` inside to ``clear_px``
    outside: :func:`_peaks` of the samples ``step_px`` apart."""
    t = np.arange(-round(p.reach_px / p.step_px) - 1, round(p.clear_px / p.step_px) + 2) * p.step_px
    return _peaks(window, xy, normal, t, p.noise_factor * texture)


def _peaks(window, xy, normal, t: np.ndarray, threshold: float):
    """``(is_edge, tm, change)`` along the normals at points ``xy`` (..., 2) sampled at offsets ``t`` (T,): the
    colour's change (M, ...) at the midpoints ``tm`` (M,) of ``t[1:-1]`` (M = T - 3), and whether it is an edge
    there (M, ...): a peak (not below the change before it, above the one after it) above ``threshold``. Each
    row depends on four samples alone: rows r..r' of ``t`` are those of ``t[r : r' + 4]``."""
    g = _changes(window, xy, normal, t)
    inner = g[1:-1]
    tm = (t[1:-2] + t[2:-1]) / 2.0
    return (inner >= g[:-2]) & (inner > g[2:]) & (inner > threshold), tm, inner


def _supported(edges, p: SilhouetteParams):
    """Whether the outline is supported at each point (of :func:`_edges`): an edge within ``agree_px``, none
    further out."""
    is_edge, tm, _ = edges
    near = np.flatnonzero(np.abs(tm) <= p.agree_px)  # tm ascends: rows near..., then further out
    return is_edge[near[0] : near[-1] + 1].any(axis=0) & ~is_edge[near[-1] + 1 :].any(axis=0)


def _outermost(edges, within_px: float, step_px: float):
    """The offset of the outermost edge (of :func:`_edges`, points (K,)) within ``within_px`` of each point
    (sub-pixel: a parabola through the changes around it), and whether there is one."""
    is_edge, tm, g = edges
    edges = is_edge & (np.abs(tm) <= within_px)[:, None]
    j = len(edges) - 1 - np.argmax(edges[::-1], axis=0)
    k = np.arange(edges.shape[1])
    gp = np.concatenate([g[:1], g, g[-1:]])  # the changes beyond the first and last rows: theirs
    a, b, c = gp[j, k], gp[j + 1, k], gp[j + 2, k]
    curv = a - 2.0 * b + c
    sub = np.where(curv < 0, 0.5 * (a - c) / np.where(curv < 0, curv, -1.0), 0.0)
    return tm[j] + np.clip(sub, -0.5, 0.5) * step_px, edges.any(axis=0)


def _supports(frame_bgr, corners, texture: float, p: SilhouetteParams) -> np.ndarray:
    """The share of points each outline of ``corners`` (S, 8, 2) is supported at (S,) (:func:`_supported`).

    The outlines differ in size only: the middle one's edges and points, moved with the corners, serve for all.
    This scan is most of a measurement's time: the colour is sampled from ``agree_px`` inside on, and first only
    up to ``agree_px`` outside; further out only at the points with an edge there (a third of them), the others
    being unsupported whatever is further out (the same supports as sampling all, from 11 instead of 17 samples
    per point)."""
    mid = corners[len(corners) // 2]
    pts = edge_points(mid, outline(mid), p.spacing_px, p.trim)
    if len(pts.xy) < 8:
        return np.zeros(len(corners))
    window, origin = _window(
        frame_bgr, corners.min(axis=(0, 1)), corners.max(axis=(0, 1)), p.clear_px + 1.0
    )
    # flat: long loops
    xy = pts.moved(corners).reshape(-1) - np.tile(origin, len(corners) * len(pts.xy))
    xy = xy.reshape(-1, 2)  # (S · K, 2), window pixels
    _, at, edge = np.unique(pts.first, return_index=True, return_inverse=True)  # the points' edges
    e = corners[:, pts.second[at]] - corners[:, pts.first[at]]  # (S, edges, 2)
    normal = np.stack([e[..., 1], -e[..., 0]], axis=-1) / np.linalg.norm(e, axis=-1, keepdims=True)
    normal = np.take(normal, edge, axis=1).reshape(-1, 2)
    inside = math.ceil(p.agree_px / p.step_px)
    # rows from agree_px inside on
    t = np.arange(-inside - 1, round(p.clear_px / p.step_px) + 2) * p.step_px
    near = np.flatnonzero(np.abs((t[1:-2] + t[2:-1]) / 2.0) <= p.agree_px)
    threshold = p.noise_factor * texture
    end = near[-1] + 1  # rows [0, end): up to agree_px outside; [end, ...): further out
    supported = _peaks(window, xy, normal, t[: end + 3], threshold)[0][near[0] :].any(axis=0)
    further = np.flatnonzero(supported)
    if len(further):
        supported[further] = ~_peaks(
            window,
            np.take(xy, further, axis=0),
            np.take(normal, further, axis=0),
            t[end:],
            threshold,
        )[0].any(axis=0)
    return supported.reshape(len(corners), -1).mean(axis=-1)

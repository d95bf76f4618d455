"""The UUV's outline in the image as a function of the camera's height above the water.

The vehicle is a box (``[uuv]`` length, width, height: :class:`~localizer.calibration.Uuv`)
whose top face's centre is the tracked reference point, at the measured depth, level, at an
unknown heading. Seen from a camera ``height_m`` above the water its eight corners land at
pixels (:func:`box_corners_px`: through the water surface by Snell's law, the corners above
the water along straight rays), and its outline is their convex hull (:func:`outline`). The
outline's size depends on the range: at nadir on ``height_m + depth_m / n`` (the water makes
the vehicle look closer); its shape on the viewing angle and the heading. Fitting it to the
edges found in the image (:mod:`localizer.tracking.silhouette`) measures the camera's height.

Pixels follow OpenCV (the top-left pixel's centre at (0, 0)); an outline runs so that
``(e_v, -e_u)`` of each edge ``e`` points outwards. Batched over leading dimensions.

A frame's fit becomes the height of the UAV's reported position above the water with two
1-sigmas (:func:`size_height`): the fit's own, and the error every frame shares (the vehicle's
size, :data:`SIZE_SIGMA`; the edges' bias, :data:`EDGE_BIAS_PX`; the depth), which no average
reduces. :class:`HeightBias` estimates the configured height's bias over a sliding window and
says when it is sure.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .calibration import Uuv
from .camera import Camera, ray_to_pixel
from .ray import pixel_to_offset
from .refraction import surface_distance

#: Body (forward, right) signs of the top face's corners, in order around it; the bottom face's follow.
_CORNERS = np.array([[1.0, 1.0], [1.0, -1.0], [-1.0, -1.0], [-1.0, 1.0]])


def box_corners_px(
    camera: Camera, R_ned_from_cv, u, v, heading_rad, uuv: Uuv, height_m, depth_m, n_water
):
    """Pixels (..., 8, 2) of the box's corners: the top face's four (at ``depth_m``), then the bottom face's.

    ``(u, v)``: the distorted pixel of the top face's centre; ``heading_rad`` the vehicle's
    heading from North; ``height_m`` the camera above the water; all broadcast over leading
    dimensions (one attitude ``R_ned_from_cv`` (3, 3)). Corners above the water (negative depth)
    are seen along straight rays. NaN where a ray does not reach the water.
    """
    u, v, heading, h = np.broadcast_arrays(
        *(np.asarray(x, dtype=float) for x in (u, v, heading_rad, height_m))
    )
    d = float(depth_m)
    if u.size > 1 and np.all(u == u.flat[0]) and np.all(v == v.flat[0]):
        # one pixel (a scan over heights and headings): its ray once, the same steps (undistort's) as for each
        u, v = u.flat[0], v.flat[0]
    centre, _ = pixel_to_offset(
        camera, R_ned_from_cv, u, v, h, np.full(h.shape, d), n_water if d > 0 else None
    )
    fwd = _CORNERS[:, 0] * (uuv.length_m / 2.0)
    right = _CORNERS[:, 1] * (uuv.width_m / 2.0)
    c, s = np.cos(heading)[..., None], np.sin(heading)[..., None]
    # (..., 4, 2)
    face = centre[..., None, :] + np.stack([c * fwd - s * right, s * fwd + c * right], axis=-1)
    ne = np.concatenate([face, face], axis=-2)
    hh = np.broadcast_to(h[..., None], ne.shape[:-1])
    depth = np.broadcast_to(np.repeat([d, d + uuv.height_m], 4), ne.shape[:-1])
    pu, pv = point_to_pixel(camera, R_ned_from_cv, ne, hh, depth, n_water)
    return np.stack([pu, pv], axis=-1)


def point_to_pixel(camera: Camera, R_ned_from_cv, offset_ne_m, height_m, depth_m, n_water: float):
    """Distorted pixels (u, v) of points at horizontal offsets (..., 2) from the camera and depths (...) below the
    water ``height_m`` (...) below it: :func:`localizer.ray.offset_to_pixel`, the surface crossing found by
    :func:`localizer.refraction.surface_distance` (points above the water, depth ≤ 0, along straight rays)."""
    ne = np.asarray(offset_ne_m, dtype=float)
    h, depth = np.broadcast_arrays(
        np.asarray(height_m, dtype=float), np.asarray(depth_m, dtype=float)
    )
    rho = np.hypot(ne[..., 0], ne[..., 1])
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.where(rho > 0, surface_distance(rho, h, depth, n_water) / rho, 0.0)
    ray_ned = np.concatenate(
        [ne * scale[..., None], np.broadcast_to(h, rho.shape)[..., None]], axis=-1
    )
    # R^T · ray
    return ray_to_pixel(camera, np.einsum("...ji,...j->...i", np.asarray(R_ned_from_cv), ray_ned))


def outline(points) -> list[int]:
    """Indices of the convex hull of ``points`` (N, 2), in the order that makes ``(e_v, -e_u)`` point outwards."""
    # plain floats: the same arithmetic, without numpy's scalars
    pts = np.asarray(points, dtype=float).tolist()
    order = sorted(range(len(pts)), key=lambda i: pts[i])

    def turn(o, a, b):
        (xo, yo), (xa, ya), (xb, yb) = pts[o], pts[a], pts[b]
        return (xa - xo) * (yb - yo) - (ya - yo) * (xb - xo)

    lower: list[int] = []
    upper: list[int] = []
    for chain, seq in ((lower, order), (upper, order[::-1])):
        for i in seq:
            while len(chain) >= 2 and turn(chain[-2], chain[-1], i) <= 0:
                chain.pop()
            chain.append(i)
    return lower[:-1] + upper[:-1]


def polygon_area(polygon) -> float:
    """The area (pixels²) of a simple polygon's vertices (N, 2)."""
    x, y = np.asarray(polygon, dtype=float).T
    x_next, y_next = np.append(x[1:], x[:1]), np.append(y[1:], y[:1])
    return abs(float(np.sum(x * y_next - x_next * y))) / 2.0


@dataclass(frozen=True)
class EdgePoints:
    """Points along an outline's edges: where to look for the image's edge, and how they move with the corners."""

    xy: np.ndarray  # (K, 2) pixels
    normal: np.ndarray  # (K, 2) unit, outwards
    first: np.ndarray  # (K,) index of the corner the point's edge starts at ...
    second: np.ndarray  # (K,) ... and ends at
    along: np.ndarray  # (K,) the point's place between them, 0..1

    def moved(self, corners) -> np.ndarray:
        """The points' positions (..., K, 2) on the same edges of other corner positions (..., 8, 2)."""
        c = np.asarray(corners, dtype=float)
        lead = c.shape[:-2]
        # (2K,): x and y alike, so that NumPy's loops run along the points
        a = np.repeat(self.along, 2)
        first = np.take(c, self.first, axis=-2).reshape(*lead, -1)
        second = np.take(c, self.second, axis=-2).reshape(*lead, -1)
        return ((1.0 - a) * first + a * second).reshape(*lead, len(self.along), 2)


def edge_points(
    corners, hull: list[int], spacing_px: float = 1.0, trim: float = 0.15, min_edge_px: float = 3.0
) -> EdgePoints:
    """Points ``spacing_px`` apart along each edge of the outline ``hull`` of ``corners`` (8, 2), leaving out
    ``trim`` of each edge at both ends (the blurred corners) and edges shorter than ``min_edge_px``.

    All edges at once (each edge's places ``along`` it are ``np.linspace(trim, 1 - trim, count)``'s, computed as
    it computes them): a height measurement takes the points of some ten outlines."""
    c = np.asarray(corners, dtype=float)
    first = np.asarray(hull, dtype=int)
    second = np.asarray(hull[1:] + hull[:1], dtype=int)
    e = c[second] - c[first]  # (E, 2)
    length_px = np.hypot(e[:, 0], e[:, 1])
    keep = length_px >= min_edge_px  # also leaves out NaN
    first, second, e, length_px = first[keep], second[keep], e[keep], length_px[keep]
    # points per edge
    count = np.maximum(2, (length_px * (1.0 - 2.0 * trim) / spacing_px).astype(int) + 1)
    edge = np.repeat(np.arange(len(count)), count)  # each point's edge
    last = np.cumsum(count) - 1  # each edge's last point
    # each point's place on its edge: 0, 1, ...
    index = np.arange(len(edge)) - (last - count + 1)[edge]
    along = index * (((1.0 - trim) - trim) / (count - 1))[edge] + trim
    along[last] = 1.0 - trim
    normal = np.stack([e[:, 1], -e[:, 0]], axis=-1) / length_px[:, None]
    return EdgePoints(
        c[first][edge] + along[:, None] * e[edge], normal[edge], first[edge], second[edge], along
    )


# --- the camera's height, frame by frame and over a window -------------------------------------------------

#: The outline's edges may all lie this far (pixels) outside or inside the vehicle's: blur, anti-aliasing and video
#: compression move the colour's change; 0.03-0.07 px on rendered frames (bench/size_height.py).
EDGE_BIAS_PX = 0.1
#: The vehicle's size (``[uuv]``) relative to the box it is taken for, 1-sigma: a frame tape-measured to 2 mm.
SIZE_SIGMA = 0.005
#: A measurement with the top face at most this deep is one "at the surface" (no refraction between, the most precise).
AT_SURFACE_M = 0.3
WINDOW_S = 30.0  # the estimate's sliding window
BLOCK_S = 1.0  # measurements within a block are alike (the same view, the same background): the spread of the
# blocks' means, not of single measurements, gives the estimate's 1-sigma (grown by the means' own correlation)
# Two a block are enough: the blocks' spread gives the 1-sigma, and the error every measurement shares most of it
# (bench/size_height.py's --schedule, issue 30: 10 gave the estimates and 1-sigmas 20 gave, sure sooner, so the
# measuring slows to one a second sooner); once sure, a window at one a second stays sure while a third of its frames
# give a measurement (20 needed two thirds: with fewer, back to five a second).
MIN_FRAMES, MIN_BLOCKS = 10, 5  # sure: at least this many measurements over this many blocks ...
SURE_SIGMA_M = 0.25  # ... a 1-sigma at most this ...
MAX_OUTLIERS = 0.3  # ... and at most this share of them left out as outliers


@dataclass(frozen=True)
class SizeHeight:
    """One frame's height of the UAV's reported position above the water from the UUV's size in the image."""

    t_unix: float  # the frame's time, station clock
    uav_height_m: float  # measured
    sigma_m: float  # 1-sigma of this frame's own error: the outline's fit
    sigma_common_m: float  # 1-sigma of the error all frames share: the vehicle's size, the edges' bias, the depth
    configured_m: float  # the height as configured (relative_alt + the take-off height, or alt - surface_amsl_m)
    configured_sigma_m: float  # ... and its 1-sigma
    depth_m: float  # the UUV's top face

    @property
    def bias_m(self) -> float:
        """The configured height minus the measured one."""
        return self.configured_m - self.uav_height_m

    @property
    def sigma_total_m(self) -> float:
        return float(np.hypot(self.sigma_m, self.sigma_common_m))


def size_height(
    t_unix: float,
    camera_height_m: float,
    sigma_fit_m: float,
    size_px: float,
    camera_below_m: float,
    configured_m: float,
    configured_sigma_m: float,
    depth_m: float,
    sigma_depth_m: float,
    n_water: float,
) -> SizeHeight:
    """A frame's :class:`SizeHeight` from its outline fit: the camera's height above the water, the fit's 1-sigma and
    the outline's size (pixels); ``camera_below_m`` is how far the camera is below the reported position (the mount's
    offset, NED down).

    The errors every frame shares scale with the range: at nadir the outline's size is that of a
    vehicle ``height + depth / n`` away, so a relative error ε of the size (the vehicle's, or the edges'
    ``2 · EDGE_BIAS_PX / size_px``) is ε times that range in height; a depth error δ is δ / n.
    """
    range_m = camera_height_m + max(depth_m, 0.0) / n_water
    relative = np.hypot(SIZE_SIGMA, 2.0 * EDGE_BIAS_PX / size_px)
    common = float(np.hypot(range_m * relative, sigma_depth_m / n_water))
    return SizeHeight(
        t_unix,
        camera_height_m + camera_below_m,
        sigma_fit_m,
        common,
        configured_m,
        configured_sigma_m,
        depth_m,
    )


@dataclass(frozen=True)
class BiasEstimate:
    """The configured height's bias against the heights from the UUV's size, over the window."""

    bias_m: float  # configured minus measured
    sigma_m: float  # 1-sigma
    sigma_common_m: float  # ... of which the error every measurement shares
    frames: int  # measurements used
    outliers: int  # measurements left out: more than 3 sigmas off the others
    blocks: int  # BLOCK_S blocks with measurements
    at_surface: float  # the share of the measurements with the UUV at the surface (AT_SURFACE_M)
    configured_sigma_m: float  # the configured height's own 1-sigma (the mean over the window)
    sure: bool

    def agrees(self, h: SizeHeight) -> bool:
        """Whether a measurement is within 3 sigmas of the estimate (its own error and the estimate's)."""
        return abs(h.bias_m - self.bias_m) <= 3.0 * float(np.hypot(h.sigma_m, self.sigma_m))


class HeightBias:
    """Measurements over a sliding window (``window_s``) and the bias estimate they give (see the module constants).

    Measurements more than 3 sigmas (their own, and the spread of the others) off the median are outliers
    (an outline locked on the vehicle's inner structure, the water's texture); the estimate is the rest's
    mean weighted by their own 1-sigma; its 1-sigma the larger of the weights' and the spread of the
    blocks' means, combined with the error every measurement shares.
    """

    def __init__(self, window_s: float = WINDOW_S):
        self.window_s = window_s
        self.heights: list[SizeHeight] = []

    def add(self, h: SizeHeight) -> None:
        self.heights.append(h)
        newest = max(x.t_unix for x in self.heights)
        self.heights = [x for x in self.heights if x.t_unix > newest - self.window_s]

    def estimate(self) -> BiasEstimate | None:
        """None without measurements."""
        if not self.heights:
            return None
        b = np.array([h.bias_m for h in self.heights])
        # a perfect fit is not an infinite weight
        s = np.maximum([h.sigma_m for h in self.heights], 1e-3)
        t = np.array([h.t_unix for h in self.heights])
        median = float(np.median(b))
        spread = 1.4826 * float(np.median(np.abs(b - median)))
        keep = np.abs(b - median) <= 3.0 * np.hypot(spread, s)
        b, s, t = b[keep], s[keep], t[keep]
        w = 1.0 / s**2
        bias = float(np.sum(w * b) / np.sum(w))
        block = np.floor((t - t.min()) / BLOCK_S).astype(int)
        blocks = np.unique(block)
        means = np.array([np.sum((w * b)[block == k]) / np.sum(w[block == k]) for k in blocks])
        scatter = _mean_sigma(means)
        kept = [h for h, k in zip(self.heights, keep) if k]
        common = float(np.mean([h.sigma_common_m for h in kept]))
        sigma = float(np.hypot(max(float(np.sqrt(1.0 / np.sum(w))), scatter), common))
        outliers = int(np.sum(~keep))
        sure = (
            len(b) >= MIN_FRAMES
            and len(blocks) >= MIN_BLOCKS
            and sigma <= SURE_SIGMA_M
            and outliers <= MAX_OUTLIERS * len(keep)
        )
        return BiasEstimate(
            bias,
            sigma,
            common,
            len(b),
            outliers,
            len(blocks),
            float(np.mean([h.depth_m <= AT_SURFACE_M for h in kept])),
            float(np.mean([h.configured_sigma_m for h in kept])),
            sure,
        )


def _mean_sigma(x: np.ndarray) -> float:
    """The 1-sigma of the mean of a series whose neighbours may be alike: the standard error, grown by
    ``sqrt((1 + r) / (1 - r))`` for the lag-1 autocorrelation ``r`` (within 0..0.9) as for an AR(1) series."""
    if len(x) < 2:
        return np.inf
    d = x - x.mean()
    r = (
        float(np.clip(np.dot(d[:-1], d[1:]) / max(float(np.dot(d, d)), 1e-300), 0.0, 0.9))
        if len(x) > 2
        else 0.0
    )
    return float(np.std(x, ddof=1) / np.sqrt(len(x)) * np.sqrt((1.0 + r) / (1.0 - r)))

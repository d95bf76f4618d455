"""Pinhole camera with OpenCV's radial-tangential distortion.

Pixels follow OpenCV: ``u`` to the right, ``v`` down, the centre of the top-left
pixel at (0, 0). Camera rays are in OpenCV's camera frame ``cv``: x right, y down,
z along the optical axis. Every function takes scalars or arrays (any matching
shape) and returns arrays of that shape.
"""

from __future__ import annotations

import math
from typing import Annotated

import numpy as np
from annotated_types import Ge, Le
from pydantic import Field, model_validator
from pydantic.dataclasses import dataclass

from .contract import OPEN, Invalid, Number, Positive, Vector5, Whole

Pixels = Annotated[Whole, Ge(16), Le(16384)]


@dataclass(frozen=True, config=OPEN)
class Camera:
    """Intrinsics in pixels and distortion ``(k1, k2, p1, p2, k3)``: the ``[camera]`` table of session.toml."""

    width: Pixels = Field(description="image width, pixels")
    height: Pixels = Field(description="image height, pixels")
    fx: Positive = Field(description="focal length along u, pixels")
    fy: Positive = Field(description="focal length along v, pixels")
    cx: Number = Field(
        description="principal point u, pixels (OpenCV: the top-left pixel's centre is 0)"
    )
    cy: Number = Field(description="principal point v, pixels")
    distortion: Vector5 = Field((0.0, 0.0, 0.0, 0.0, 0.0), description="OpenCV k1, k2, p1, p2, k3")

    @model_validator(mode="after")
    def _principal_point_inside(self):
        for key, value, size in (("cx", self.cx, self.width), ("cy", self.cy, self.height)):
            if not -0.5 <= value <= size - 0.5:
                raise Invalid(key, value, f"must be within [-0.5, {size - 0.5}] (inside the image)")
        return self

    @property
    def K(self) -> np.ndarray:
        """3×3 intrinsic matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def contains(self, u, v, margin_px: float = 0.0):
        """True where the pixel lies inside the image (``margin_px`` away from its border)."""
        u = np.asarray(u, dtype=float)
        v = np.asarray(v, dtype=float)
        return (
            (u >= -0.5 + margin_px)
            & (u <= self.width - 0.5 - margin_px)
            & (v >= -0.5 + margin_px)
            & (v <= self.height - 0.5 - margin_px)
        )


def distort(x, y, distortion):
    """Apply radial-tangential distortion to normalized image coordinates.

    ``x = X/Z``, ``y = Y/Z`` of a point in the ``cv`` frame (unitless). Returns the
    distorted normalized coordinates ``(xd, yd)``, OpenCV's model exactly.
    """
    return _distorted(np.asarray(x, dtype=float), np.asarray(y, dtype=float), distortion)


def _distorted(x, y, distortion):
    """:func:`distort`'s arithmetic, of floats or of arrays alike (the same operations in the same order)."""
    k1, k2, p1, p2, k3 = distortion
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return xd, yd


#: Arrays of up to this many points are undistorted point by point in plain floats (numpy's overhead per operation
#: is most of a small array's time: the height from size undistorts 1-5 pixels at a time), all stepped together until
#: every one has converged, as an array's are: the same steps, the same results.
SCALAR_POINTS = 16


def undistort(xd, yd, distortion, iterations: int = 20, tol: float = 1e-14):
    """Invert :func:`distort` by Newton's method (to ~1e-12, far below a pixel).

    OpenCV's ``undistortPoints`` stops after a few fixed-point steps, which leaves
    errors of 0.01–0.1 px in image corners; this converges quadratically instead.
    Returns NaN where the iteration does not converge (outside the lens model's
    valid region). Up to :data:`SCALAR_POINTS` points are stepped in plain floats.
    """
    xd = np.asarray(xd, dtype=float)
    yd = np.asarray(yd, dtype=float)
    if 0 < xd.size <= SCALAR_POINTS and xd.shape == yd.shape:
        x, y = _undistort_floats(xd, yd, distortion, iterations, tol)
        if x is not None:
            return x, y
    x = xd.copy()
    y = yd.copy()
    for _ in range(iterations):
        dx, dy = _newton_step(x, y, xd, yd, distortion)
        x = x - dx
        y = y - dy
        if np.all(np.abs(dx) + np.abs(dy) < tol):
            break
    xr, yr = distort(x, y, distortion)
    bad = ~(np.abs(xr - xd) + np.abs(yr - yd) < 1e-9)
    if np.any(bad):
        x = np.where(bad, np.nan, x)
        y = np.where(bad, np.nan, y)
    return x, y


def _newton_step(x, y, xd, yd, distortion):
    """:func:`undistort`'s Newton step (dx, dy) from ``(x, y)`` towards the distorted ``(xd, yd)``, of floats or of
    arrays alike (the same operations in the same order)."""
    k1, k2, p1, p2, k3 = distortion
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    dradial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)  # d radial / d r2
    fx = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) - xd
    fy = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y - yd
    # Jacobian of (xd, yd) with respect to (x, y)
    j11 = radial + 2.0 * x * x * dradial + 2.0 * p1 * y + 6.0 * p2 * x
    j12 = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y
    j21 = 2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y
    j22 = radial + 2.0 * y * y * dradial + 6.0 * p1 * y + 2.0 * p2 * x
    det = j11 * j22 - j12 * j21
    return (j22 * fx - j12 * fy) / det, (-j21 * fx + j11 * fy) / det


def _undistort_floats(xd: np.ndarray, yd: np.ndarray, distortion, iterations: int, tol: float):
    """:func:`undistort`'s steps and its check point by point in plain floats, every point stepped until all have
    converged (as an array's); (x, y) arrays of ``xd``'s shape, or (None, None) where a step divides by zero (the
    arrays' steps then give what numpy gives)."""
    k = tuple(float(c) for c in distortion)
    targets = list(zip(xd.ravel().tolist(), yd.ravel().tolist(), strict=True))
    points = targets
    try:
        for _ in range(iterations):
            steps = [
                _newton_step(x, y, a, b, k) for (x, y), (a, b) in zip(points, targets, strict=True)
            ]
            points = [(x - dx, y - dy) for (x, y), (dx, dy) in zip(points, steps, strict=True)]
            if all(abs(dx) + abs(dy) < tol for dx, dy in steps):
                break
    except ZeroDivisionError:
        return None, None
    # the check of undistort's arrays, point by point: NaN where distorting back misses the pixel
    nan = (math.nan, math.nan)
    points = [
        p if abs(xr - a) + abs(yr - b) < 1e-9 else nan
        for p, (a, b), (xr, yr) in zip(
            points, targets, (_distorted(x, y, k) for x, y in points), strict=True
        )
    ]
    x, y = (np.array(c, dtype=float).reshape(xd.shape) for c in zip(*points, strict=True))
    return x, y


def pixel_to_ray(camera: Camera, u, v):
    """Unit ray in the ``cv`` frame through distorted pixel ``(u, v)``; shape ``(..., 3)``."""
    xd = (np.asarray(u, dtype=float) - camera.cx) / camera.fx
    yd = (np.asarray(v, dtype=float) - camera.cy) / camera.fy
    x, y = undistort(xd, yd, camera.distortion)
    ray = np.stack([x, y, np.ones_like(x)], axis=-1)
    return ray / np.linalg.norm(ray, axis=-1, keepdims=True)


def ray_to_pixel(camera: Camera, ray_cv):
    """Distorted pixel ``(u, v)`` where a ``cv``-frame ray ``(..., 3)`` lands.

    Rays pointing behind the camera (z ≤ 0) give NaN.
    """
    ray_cv = np.asarray(ray_cv, dtype=float)
    z = ray_cv[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        x = np.where(z > 0, ray_cv[..., 0] / z, np.nan)
        y = np.where(z > 0, ray_cv[..., 1] / z, np.nan)
    xd, yd = distort(x, y, camera.distortion)
    return camera.fx * xd + camera.cx, camera.fy * yd + camera.cy

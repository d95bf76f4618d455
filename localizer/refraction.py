"""The ray from the camera to the UUV, bent at a flat water surface by Snell's law.

Geometry in a local NED frame centred on the camera: the water surface is the
horizontal plane ``height_m`` below the camera, the UUV is ``depth_m`` below the
surface. Snell: ``sin θ_air = n · sin θ_water`` with θ measured from the vertical.
``n=None`` everywhere means the paper's straight ray (no refraction).
All functions broadcast over scalars and arrays.
"""

from __future__ import annotations

import math

import numpy as np

#: Arrays of up to this many points are solved point by point in plain floats (faster than numpy's steps).
SCALAR_POINTS = 16


def refract_down(dir_ned, n_water):
    """Direction in water of a downward unit ray crossing a flat surface from air.

    ``dir_ned`` (..., 3) unit vectors with a positive down component. Returns unit
    vectors; horizontal components shrink by ``1/n_water``.
    """
    d = np.asarray(dir_ned, dtype=float)
    eta = 1.0 / n_water
    horiz = d[..., :2] * eta
    sin2 = np.sum(horiz * horiz, axis=-1)
    down = np.sqrt(np.clip(1.0 - sin2, 0.0, None))
    return np.concatenate([horiz, down[..., None]], axis=-1)


def offset_from_ray(dir_ned, height_m, depth_m, n_water=1.34):
    """Horizontal offset (north_m, east_m) from the camera to where the ray reaches ``depth_m``.

    ``dir_ned`` (..., 3) unit rays leaving the camera. Returns ``(offset (..., 2), reaches)``;
    ``reaches`` is False (offset NaN) where the ray does not point down at the water.
    """
    d = np.asarray(dir_ned, dtype=float)
    height_m = np.asarray(height_m, dtype=float)
    depth_m = np.asarray(depth_m, dtype=float)
    reaches = (d[..., 2] > 1e-9) & (height_m > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        air = d[..., :2] / d[..., 2:3] * height_m[..., None]
        if n_water is None:
            water_dir = d
        else:
            water_dir = refract_down(d, n_water)
        water = water_dir[..., :2] / water_dir[..., 2:3] * depth_m[..., None]
    offset = np.where(reaches[..., None], air + water, np.nan)
    return offset, reaches


def surface_distance(rho_m, height_m, depth_m, n_water=1.34, tol_m=1e-12, max_steps=60):
    """Horizontal distance from the camera to where the ray to a submerged point crosses the surface.

    The target is ``rho_m`` away horizontally and ``depth_m`` below a surface
    ``height_m`` below the camera. Solves ``x + depth·tan θ_w(x) = rho`` (monotone in
    x) by Newton's method from the straight ray's crossing, safeguarded: the root stays
    bracketed (the straight ray's crossing below it, ``rho`` above it) and a step that
    would leave the bracket bisects it instead, so it cannot fail or diverge; it stops
    when every step is below ``tol_m`` (4-6 steps, up to 8 at grazing angles, where a bisection takes 64). Straight
    ray if ``n_water`` is None, and for points above the water (``depth_m`` ≤ 0).
    Scalars in, a float out; scalars and arrays of up to :data:`SCALAR_POINTS` points (a frame's prediction
    projects 3) are solved in plain floats, the same steps without numpy's overhead per operation.
    """
    if n_water is None:
        return np.asarray(rho_m, dtype=float) * height_m / (np.asarray(height_m, float) + depth_m)
    if all(isinstance(a, (int, float)) for a in (rho_m, height_m, depth_m)):
        return _surface_distance_scalar(
            float(rho_m), float(height_m), float(depth_m), n_water, tol_m, max_steps
        )
    rho, h, d = np.broadcast_arrays(
        np.asarray(rho_m, dtype=float),
        np.asarray(height_m, dtype=float),
        np.asarray(depth_m, dtype=float),
    )
    if rho.size <= SCALAR_POINTS:
        points = zip(rho.flat, h.flat, d.flat)
        one = (_surface_distance_scalar(*p, n_water, tol_m, max_steps) for p in points)
        return np.fromiter(one, float, rho.size).reshape(rho.shape)
    straight = rho * h / (h + d)
    under = d > 0
    lo, hi = straight.copy(), np.where(under, rho, straight)
    x = straight.copy()
    h2 = h * h
    for _ in range(max_steps):
        f, slope = _residual(x, rho, h2, d, n_water, np.sqrt)
        lo = np.where(f < 0, x, lo)
        hi = np.where(f > 0, x, hi)
        new = x - f / slope
        new = np.where((new > lo) & (new < hi), new, 0.5 * (lo + hi))
        new = np.where(under & (f != 0), new, x)
        step = np.abs(new - x)
        x = new
        if not np.any(step > tol_m):
            break
    return x


def _residual(x, rho, h2, d, n_water, sqrt):
    """``(f, df/dx)`` of the crossing's equation ``f(x) = x + d·tan θ_w(x) − rho`` at ``x`` (``h2``: the height
    squared), with ``sqrt`` of floats or of arrays."""
    r2 = x * x + h2
    sin_w = x / (n_water * sqrt(r2))
    cos2_w = 1.0 - sin_w * sin_w
    return x + d * sin_w / sqrt(cos2_w) - rho, 1.0 + d * h2 / (n_water * (r2 * cos2_w) ** 1.5)


def _surface_distance_scalar(rho, h, d, n_water, tol_m, max_steps) -> float:
    """:func:`surface_distance` of one point, in plain floats (the same steps)."""
    x = lo = rho * h / (h + d)
    if not d > 0:
        return x
    hi = rho
    h2 = h * h
    for _ in range(max_steps):
        f, slope = _residual(x, rho, h2, d, n_water, math.sqrt)
        if f == 0:
            break
        if f < 0:
            lo = x
        else:
            hi = x
        new = x - f / slope
        if not lo < new < hi:
            new = 0.5 * (lo + hi)
        step = abs(new - x)
        x = new
        if not step > tol_m:
            break
    return x


def ray_to_target(offset_ne_m, height_m, depth_m, n_water=1.34):
    """Unit ray in NED leaving the camera towards a submerged point (inverse of :func:`offset_from_ray`).

    ``offset_ne_m`` (..., 2): the point's horizontal offset from the camera.
    """
    ne = np.asarray(offset_ne_m, dtype=float)
    rho = np.hypot(ne[..., 0], ne[..., 1])
    x = surface_distance(rho, height_m, depth_m, n_water)
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.where(rho > 0, x / rho, 0.0)
    ray = np.concatenate(
        [ne * scale[..., None], np.broadcast_to(np.asarray(height_m, float), rho.shape)[..., None]],
        axis=-1,
    )
    return ray / np.linalg.norm(ray, axis=-1, keepdims=True)

"""The ray from the camera to the UUV, bent at a flat water surface by Snell's law.

Geometry in a local NED frame centred on the camera: the water surface is the
horizontal plane ``height_m`` below the camera, the UUV is ``depth_m`` below the
surface. Snell: ``sin θ_air = n · sin θ_water`` with θ measured from the vertical.
``n=None`` everywhere means the paper's straight ray (no refraction).
All functions broadcast over scalars and arrays.
"""

from __future__ import annotations

import numpy as np


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


def surface_distance(rho_m, height_m, depth_m, n_water=1.34, iterations=64):
    """Horizontal distance from the camera to where the ray to a submerged point crosses the surface.

    The target is ``rho_m`` away horizontally and ``depth_m`` below a surface
    ``height_m`` below the camera. Solves ``x + depth·tan θ_w(x) = rho`` (monotone in
    x) by bisection, which cannot fail or diverge. Straight ray if ``n_water`` is None.
    """
    rho = np.asarray(rho_m, dtype=float)
    h = np.asarray(height_m, dtype=float)
    d = np.asarray(depth_m, dtype=float)
    if n_water is None:
        return rho * h / (h + d)
    lo = np.broadcast_to(rho * h / (h + d), np.broadcast(rho, h, d).shape).copy()
    hi = np.broadcast_to(rho, lo.shape).copy()
    for _ in range(iterations):
        x = 0.5 * (lo + hi)
        sin_a = x / np.hypot(x, h)
        sin_w = sin_a / n_water
        f = x + d * sin_w / np.sqrt(1.0 - sin_w * sin_w) - rho
        lo = np.where(f < 0, x, lo)
        hi = np.where(f < 0, hi, x)
    return 0.5 * (lo + hi)


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

"""Pixel ↔ submerged point, through the camera model, its attitude and the refracting surface.

``R_ned_from_cv`` is the OpenCV camera frame's attitude in local NED; offsets are
horizontal (north_m, east_m) from the camera's nadir point; ``height_m`` is the
camera's height above the water, ``depth_m`` the point's depth below it.
``n_water=None`` is the paper's straight ray. Batched over leading dimensions.
"""

from __future__ import annotations

import numpy as np

from .camera import Camera, pixel_to_ray, ray_to_pixel
from .refraction import offset_from_ray, ray_to_target


def pixel_to_offset(camera: Camera, R_ned_from_cv, u, v, height_m, depth_m, n_water=1.34):
    """Horizontal offset (..., 2) of the point seen at pixel (u, v), and where the ray reaches water."""
    ray_cv = pixel_to_ray(camera, u, v)
    dir_ned = np.einsum("...ij,...j->...i", np.asarray(R_ned_from_cv), ray_cv)
    return offset_from_ray(dir_ned, height_m, depth_m, n_water)


def offset_to_pixel(camera: Camera, R_ned_from_cv, offset_ne_m, height_m, depth_m, n_water=1.34):
    """Distorted pixel (u, v) where a point at a horizontal offset and depth appears (forward projection)."""
    dir_ned = ray_to_target(offset_ne_m, height_m, depth_m, n_water)
    ray_cv = np.einsum("...ji,...j->...i", np.asarray(R_ned_from_cv), dir_ned)  # R^T · dir
    return ray_to_pixel(camera, ray_cv)

"""1-sigma accuracy of a fix, propagated from its inputs' uncertainties.

First-order propagation: the Jacobian of the horizontal offset with respect to
pixel (u, v), camera tilt about North and East, heading about Down, camera
height and UUV depth is taken by finite differences of the very function that
makes the fix, so the estimate follows refraction and distortion exactly. On top:

- the UAV position's own error (its GNSS receiver's accuracy), isotropic;
- the time alignment: a frame matched to telemetry ``sigmas.time_s`` off sees the
  camera as it was that much earlier or later; the fix then moves by the
  camera's angular velocity through the same Jacobian, plus the UAV's velocity;
- extrapolated or held telemetry: its estimated error adds to tilt and heading.

The result is the covariance of (north, east) per fix; ``h_acc_m`` is its DRMS,
sqrt(σ_N² + σ_E²): about 95–98 % of errors fall within 2·h_acc_m when the input
sigmas are right.
"""

from __future__ import annotations

import numpy as np

from .attitude import rotation_about
from .calibration import Sigmas
from .camera import Camera, pixel_to_ray
from .refraction import offset_from_ray

_AXES = np.eye(3)  # north, east, down


def accuracy(camera: Camera, R_ned_from_cv, u, v, height_m, depth_m, n_water, sigmas: Sigmas, *,
             sigma_tilt_rad=0.0, sigma_yaw_rad=0.0, sigma_uav_m=0.0, omega_ned=None, velocity_ned_mps=None,
             sigma_height_m=None, sigma_depth_m=None, sigma_time_s=None, sigma_pixel_px=None):
    """``(h_acc_m, v_acc_m, cov_ne_m2)`` for fixes made from these inputs (shapes as ``u``; cov ``(..., 2, 2)``).

    ``sigma_tilt_rad``/``sigma_yaw_rad`` add to the calibration's tilt and heading
    sigmas (extrapolated telemetry); ``sigma_uav_m`` is the UAV position's
    horizontal 1-sigma; ``omega_ned`` (rad/s) and ``velocity_ned_mps`` (m/s) (``(..., 3)``)
    turn the time sigma into metres. ``sigma_height_m``, ``sigma_depth_m``, ``sigma_time_s``
    and ``sigma_pixel_px`` (scalars or shaped as ``u``) replace the calibration's ``height_m``,
    ``depth_m``, ``time_s`` and ``pixel_px`` when given: the inputs' own sigmas, per frame
    (the pixel's: the tracker's, for each of u and v).
    """
    u = np.asarray(u, dtype=float)
    v = np.asarray(v, dtype=float)
    R = np.asarray(R_ned_from_cv, dtype=float)
    h = np.broadcast_to(np.asarray(height_m, dtype=float), u.shape)
    d = np.broadcast_to(np.asarray(depth_m, dtype=float), u.shape)
    px, ang, dl = 0.5, 1e-4, 1e-3
    # the undistorted rays of the pixel and of its two pixel-perturbed neighbours, in one call
    rays = pixel_to_ray(camera, np.stack([u, u + px, u]), np.stack([v, v, v + px]))
    dirs = np.einsum("...ij,k...j->k...i", R, rays)
    base = dirs[0]
    rotated = [np.einsum("ij,...j->...i", rotation_about(axis, ang), base) for axis in _AXES]
    all_dirs = np.stack([base, dirs[1], dirs[2], *rotated, base, base])
    all_h = np.stack([h] * 6 + [h + dl, h])
    all_d = np.stack([d] * 7 + [d + dl])
    off, _ = offset_from_ray(all_dirs, all_h, all_d, n_water)
    # columns of the Jacobian: d(offset)/d(u, v, rot N, rot E, rot D, height, depth)
    J = [(off[k] - off[0]) / step for k, step in enumerate((px, px, ang, ang, ang, dl, dl), start=1)]
    sig_h = sigmas.height_m if sigma_height_m is None else sigma_height_m
    sig_d = sigmas.depth_m if sigma_depth_m is None else sigma_depth_m
    sig_t = np.broadcast_to(np.asarray(sigmas.time_s if sigma_time_s is None else sigma_time_s, dtype=float), u.shape)
    tilt = np.hypot(np.radians(sigmas.tilt_deg), sigma_tilt_rad)
    yaw = np.hypot(np.radians(sigmas.yaw_deg), sigma_yaw_rad)
    sig_px = sigmas.pixel_px if sigma_pixel_px is None else sigma_pixel_px
    sig = [sig_px, sig_px, tilt, tilt, yaw, sig_h, sig_d]
    cov = np.zeros(u.shape + (2, 2))
    for j, s in zip(J, sig):
        js = j * np.asarray(s, dtype=float)[..., None]
        cov += js[..., :, None] * js[..., None, :]
    if np.any(sig_t > 0) and (omega_ned is not None or velocity_ned_mps is not None):
        rate = np.zeros(u.shape + (2,))
        if omega_ned is not None:
            w = np.asarray(omega_ned, dtype=float)
            rate += J[2] * w[..., 0:1] + J[3] * w[..., 1:2] + J[4] * w[..., 2:3]
        if velocity_ned_mps is not None:
            vel = np.asarray(velocity_ned_mps, dtype=float)
            rate += vel[..., :2] - J[5] * vel[..., 2:3]  # descending lowers the camera
        js = rate * sig_t[..., None]
        cov += js[..., :, None] * js[..., None, :]
    uav = np.broadcast_to(np.asarray(sigma_uav_m, dtype=float), u.shape)
    cov[..., 0, 0] += uav**2 / 2.0  # isotropic: the DRMS grows by sigma_uav
    cov[..., 1, 1] += uav**2 / 2.0
    h_acc = np.sqrt(cov[..., 0, 0] + cov[..., 1, 1])
    v_acc = np.broadcast_to(np.hypot(sig_d, sigmas.surface_amsl_m), h_acc.shape).copy()
    return h_acc, v_acc, cov

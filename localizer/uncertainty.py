"""1-sigma accuracy of a fix, propagated from its inputs' uncertainties.

First-order propagation: the Jacobian of the horizontal offset with respect to
pixel (u, v), camera tilt about North and East, heading about Down, camera
height and UUV depth is taken by finite differences of the very function that
makes the fix, so the estimate follows refraction and distortion exactly. On top:

- the UAV position's own error (its GNSS receiver's accuracy), isotropic;
- the time alignment: a frame matched to telemetry ``sigmas.time_s`` off sees the
  camera as it was that much earlier or later; the fix then moves by the
  camera's angular velocity through the same Jacobian, plus the UAV's velocity, less the located point's own
  where it is given (``target_velocity_ne_mps``: a frame stamped late also shows the UUV where it was, so the fix
  is off by the camera's motion relative to the UUV's; a drone flying with the UUV makes next to no error);
- extrapolated or held telemetry: its estimated error adds to tilt and heading;
- wind waves (``sigmas.wind_mps``; with refraction): each facet of the surface the ray
  crosses is tilted by the waves' slope, which bends the ray in the water: a point at depth
  d moves by about d·(1 − 1/n)·slope per axis straight down, more off nadir. The slopes' variance is Cox and
  Munk's (:func:`wave_slope_sigma_rad`); the Jacobian is taken by turning the facet by a small
  angle about North and about East (:func:`_facet_run`).

The result is the covariance of (north, east) per fix; ``h_acc_m`` is half the radius of the circle
that holds 95 % of a normal error of that covariance (:func:`h_acc_from_cov_m`), so 2·h_acc holds 95 % of
the fixes whatever the error's shape when the input sigmas are right (a DRMS, sqrt(σ_N² + σ_E²), holds
95.4 % along one axis to 98.2 % circular: loose where the error is round). It is also what ArduPilot's
EKF3 reads GPS_INPUT's ``horiz_accuracy`` as: each axis's 1-sigma (docs/explanation/accuracy.md). The sigmas describe a platform's
population: a tilt or compass bias is constant over one flight (all of its fixes are in or
out together), and the share is over the flights of drones of that kind (bench/claim_calibration.py).
"""

from __future__ import annotations

import numpy as np

from .attitude import rotation_about
from .calibration import Sigmas
from .camera import Camera, pixel_to_ray
from .refraction import offset_from_ray, refract_down

_AXES = np.eye(3)  # north, east, down

#: Cox and Munk (1954), a clean sea surface: mean square slope (both axes) = a + b · wind (m/s, 12.5 m up).
COX_MUNK_MSS = (0.003, 0.00512)
#: The share of that slope variance that moves the UUV's image as a whole: waves several times longer than it.
#: Shorter ones break its image up about where it is, their displacements averaging out over the vehicle (over a
#: disk of radius r a wave of wavenumber k keeps (2·J1(kr)/(kr))² of its variance: 5 % at the vehicle's own
#: length). 40–60 % of the slope variance is in waves longer than a half-metre vehicle at 2–10 m/s; the
#: simulator's wind sea (Elfouhaily's spectrum scaled to Cox and Munk, averaged over the top face) keeps
#: 15–37 % at 2–8 m/s, 1–2 m deep (bench/claim_calibration.py).
SLOPE_SHARE_UUV = 0.35
#: ... from this wind up (m/s); below it the share falls in proportion to the wind: a light wind's sea is short
#: waves (its peak's wavelength grows with the wind squared), so less of its slope is in waves longer than the
#: vehicle (the simulator's keeps about half the share at 2 m/s that it keeps at 5, bench/claim_calibration.py)
FULL_SHARE_WIND_MPS = 4.0


#: Half the radius of the circle holding 95 % of a 2-D normal error, per its larger axis's sigma sqrt(λ1), at the
#: axis ratios sqrt(λ2 / λ1) of :data:`_AXIS_RATIOS` (λ1 ≥ λ2 the covariance's eigenvalues): P(|x| < 2·k·sqrt(λ1))
#: = 0.95 solved by numerical integration; 1.96 / 2 along one axis, sqrt(−2 ln 0.05) / 2 circular. Linear
#: interpolation between them is within 0.03 % (tests/test_uncertainty_h_acc.py checks it against an independent integration).
H_ACC_PER_MAJOR_SIGMA = np.array(
    [0.97998, 0.9803, 0.98126, 0.98289, 0.9852, 0.98825, 0.9921, 0.99683, 1.00257, 1.00951, 1.01793]
    + [1.02819, 1.04065, 1.05556, 1.07299, 1.0929, 1.11514, 1.13954, 1.1659, 1.19406, 1.22387]
)
_AXIS_RATIOS = np.linspace(0.0, 1.0, len(H_ACC_PER_MAJOR_SIGMA))
#: ``h_acc`` of a circular error per its sigma on each axis: an isotropic covariance from an ``h_acc`` (m) has
#: ``h_acc / H_ACC_PER_SIGMA_ISOTROPIC`` (m) on each axis.
H_ACC_PER_SIGMA_ISOTROPIC = float(H_ACC_PER_MAJOR_SIGMA[-1])


def h_acc_from_cov_m(cov_ne_m2) -> np.ndarray:
    """A fix's horizontal accuracy ``h_acc`` (m) from its (north, east) covariance ``cov_ne_m2`` (m², ``(..., 2, 2)``):
    half the radius of the circle about the fix that holds 95 % of a normal error of that covariance, so a
    calibrated claim has 95 % of its fixes within 2·h_acc whatever the error's shape. 1.2239 σ for a circular error
    of σ per axis, 0.98 σ for one along a single axis (:data:`H_ACC_PER_MAJOR_SIGMA`). NaN in, NaN out."""
    C = np.asarray(cov_ne_m2, dtype=float)
    mean = (C[..., 0, 0] + C[..., 1, 1]) / 2.0
    half_gap = np.hypot((C[..., 0, 0] - C[..., 1, 1]) / 2.0, C[..., 0, 1])
    major, minor = mean + half_gap, np.clip(mean - half_gap, 0.0, None)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(major > 0, np.sqrt(minor / major), 1.0)
    return np.sqrt(major) * np.interp(ratio, _AXIS_RATIOS, H_ACC_PER_MAJOR_SIGMA)


def isotropic_sigma_m(h_acc_m) -> np.ndarray:
    """Each axis's 1-sigma (m) of the circular error whose ``h_acc`` is ``h_acc_m`` (m): for a claim that states no
    covariance of its own."""
    return np.asarray(h_acc_m, dtype=float) / H_ACC_PER_SIGMA_ISOTROPIC


def wave_slope_sigma_rad(wind_mps) -> np.ndarray:
    """The waves' slope (radians, 1-sigma per axis, North and East alike) that moves the UUV's image in wind
    ``wind_mps``: half of Cox and Munk's mean square slope per axis, :data:`SLOPE_SHARE_UUV` of it (less below
    :data:`FULL_SHARE_WIND_MPS`, in proportion to the wind). 0 for no wind (a still surface)."""
    w = np.asarray(wind_mps, dtype=float)
    a, b = COX_MUNK_MSS
    share = SLOPE_SHARE_UUV * np.clip(w / FULL_SHARE_WIND_MPS, 0.0, 1.0)
    return np.where(w > 0, np.sqrt(share * (a + b * w) / 2.0), 0.0)


def _facet_run(dir_ned, depth_m, n_water, R_facet=None):
    """Horizontal run (north, east; m) under the surface to ``depth_m`` of rays ``dir_ned`` (..., 3) refracted at a
    facet turned by ``R_facet`` from level (None: level): Snell in the facet's own frame."""
    if R_facet is None:
        w = refract_down(dir_ned, n_water)
    else:
        w = np.einsum(
            "ij,...j->...i",
            R_facet,
            refract_down(np.einsum("ji,...j->...i", R_facet, dir_ned), n_water),
        )
    return w[..., :2] / w[..., 2:3] * np.asarray(depth_m, dtype=float)[..., None]


def accuracy(
    camera: Camera,
    R_ned_from_cv,
    u,
    v,
    height_m,
    depth_m,
    n_water,
    sigmas: Sigmas,
    *,
    sigma_tilt_rad=0.0,
    sigma_yaw_rad=0.0,
    sigma_uav_m=0.0,
    omega_ned=None,
    velocity_ned_mps=None,
    sigma_height_m=None,
    sigma_depth_m=None,
    sigma_time_s=None,
    sigma_pixel_px=None,
    rotation_per_height_ned=None,
    target_velocity_ne_mps=None,
):
    """``(h_acc_m, v_acc_m, cov_ne_m2)`` for fixes made from these inputs (shapes as ``u``; cov ``(..., 2, 2)``).

    ``sigma_tilt_rad``/``sigma_yaw_rad`` add to the calibration's tilt and heading
    sigmas (extrapolated telemetry); ``sigma_uav_m`` is the UAV position's
    horizontal 1-sigma; ``omega_ned`` (rad/s) and ``velocity_ned_mps`` (m/s) (``(..., 3)``)
    turn the time sigma into metres. ``sigma_height_m``, ``sigma_depth_m``, ``sigma_time_s``
    and ``sigma_pixel_px`` (scalars or shaped as ``u``) replace the calibration's ``height_m``,
    ``depth_m``, ``time_s`` and ``pixel_px`` when given: the inputs' own sigmas, per frame
    (the pixel's: the tracker's, for each of u and v). ``rotation_per_height_ned`` (rad per metre, ``(..., 3)``): the
    attitude's error that comes with the height's (reported − true, a NED rotation vector per metre the height reads
    high: a pose from the bottom's, whose tilt takes up part of a height error), so the height's term is the two
    together. ``target_velocity_ne_mps`` (m/s, ``(..., 2)``): the located point's horizontal velocity (the UUV's, from
    its track); the time term is then the camera's motion relative to it (None: the point taken as still).
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
    J = [
        (off[k] - off[0]) / step for k, step in enumerate((px, px, ang, ang, ang, dl, dl), start=1)
    ]
    if (
        rotation_per_height_ned is not None
    ):  # the corrected ray is the true one turned back by that error
        turn = np.asarray(rotation_per_height_ned, dtype=float)
        J[5] = J[5] - sum(J[2 + i] * turn[..., i : i + 1] for i in range(3))
    sig_h = sigmas.height_m if sigma_height_m is None else sigma_height_m
    sig_d = sigmas.depth_m if sigma_depth_m is None else sigma_depth_m
    sig_t = np.broadcast_to(
        np.asarray(sigmas.time_s if sigma_time_s is None else sigma_time_s, dtype=float), u.shape
    )
    tilt = np.hypot(np.radians(sigmas.tilt_deg), sigma_tilt_rad)
    yaw = np.hypot(np.radians(sigmas.yaw_deg), sigma_yaw_rad)
    sig_px = sigmas.pixel_px if sigma_pixel_px is None else sigma_pixel_px
    sig = [sig_px, sig_px, tilt, tilt, yaw, sig_h, sig_d]
    cov = np.zeros(u.shape + (2, 2))
    for j, s in zip(J, sig):
        js = j * np.asarray(s, dtype=float)[..., None]
        cov += js[..., :, None] * js[..., None, :]
    moving = (omega_ned, velocity_ned_mps, target_velocity_ne_mps)
    if np.any(sig_t > 0) and any(x is not None for x in moving):
        rate = np.zeros(u.shape + (2,))
        if omega_ned is not None:
            w = np.asarray(omega_ned, dtype=float)
            rate += J[2] * w[..., 0:1] + J[3] * w[..., 1:2] + J[4] * w[..., 2:3]
        if velocity_ned_mps is not None:
            vel = np.asarray(velocity_ned_mps, dtype=float)
            rate += vel[..., :2] - J[5] * vel[..., 2:3]  # descending lowers the camera
        if (
            target_velocity_ne_mps is not None
        ):  # the fix is scored where the point is at the frame's stamp
            rate -= np.asarray(target_velocity_ne_mps, dtype=float)
        js = rate * sig_t[..., None]
        cov += js[..., :, None] * js[..., None, :]
    slope = float(wave_slope_sigma_rad(sigmas.wind_mps))
    if slope > 0 and n_water is not None:
        level = _facet_run(base, d, n_water)
        for axis in _AXES[:2]:
            js = (_facet_run(base, d, n_water, rotation_about(axis, ang)) - level) * (slope / ang)
            cov += js[..., :, None] * js[..., None, :]
    uav = np.broadcast_to(np.asarray(sigma_uav_m, dtype=float), u.shape)
    cov[..., 0, 0] += uav**2 / 2.0  # isotropic: sigma_uav is a DRMS (a receiver's)
    cov[..., 1, 1] += uav**2 / 2.0
    h_acc = h_acc_from_cov_m(cov)
    v_acc = np.broadcast_to(np.hypot(sig_d, sigmas.surface_amsl_m), h_acc.shape).copy()
    return h_acc, v_acc, cov

"""The simulator's own geometry: rotations, the lens, refraction and geodesy.

Written without the localizer, from other tools and other derivations, so that a
session the simulator writes checks the localizer instead of echoing it
(``tests/test_sim_independent.py`` compares the two):

- rotations: :class:`scipy.spatial.transform.Rotation` (MAVLink's Z-Y-X Euler
  angles are scipy's intrinsic ``"ZYX"`` sequence of yaw, pitch, roll; scipy's
  quaternions are (x, y, z, w), MAVLink's (w, x, y, z));
- the lens: OpenCV itself, :func:`cv2.projectPoints` forward and
  :func:`cv2.undistortPoints` with tight termination criteria backward;
- refraction: Snell's law in vector form for rays going down, Fermat's principle
  (least optical path, solved by :func:`scipy.optimize.brentq`) for the path from
  the camera to a submerged point;
- geodesy: :func:`pymap3d.enu2geodetic` (East-North-Up, not the localizer's NED call).

Frames: ``ned`` the world (North-East-Down, origin on the water surface, which is
the plane down = 0); ``body`` the UAV's FRD; ``gimbal`` the camera's FRD (x is the
optical axis); ``cv`` OpenCV's camera frame (x image right, y image down, z optical
axis). ``R_a_from_b`` maps vectors from b to a. Radians and metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import pymap3d
from scipy.optimize import brentq
from scipy.spatial.transform import Rotation

#: The OpenCV camera frame in the gimbal's FRD frame, column by column: image right
#: (cv x) is the gimbal's right (y), image down (cv y) its down (z), the optical
#: axis (cv z) its forward (x). Session format v1, "Telemetry".
R_GIMBAL_FROM_CV = np.column_stack([(0.0, 1.0, 0.0), (0.0, 0.0, 1.0), (1.0, 0.0, 0.0)])

#: cv2.undistortPoints stops when the re-projection error is below this many pixels
UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-11)
#: rays whose pixel does not re-project within this many pixels are refused (NaN)
UNDISTORT_CHECK_PX = 1e-6


# --- rotations ---------------------------------------------------------------------------------


def rotation_zyx(roll, pitch, yaw) -> Rotation:
    """FRD → NED rotation of MAVLink Euler angles: yaw about z, then pitch about the new y, then roll.

    Scalars give one rotation, arrays (broadcast together) a flat stack of them.
    """
    r, p, y = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (roll, pitch, yaw)))
    if r.ndim == 0:
        return Rotation.from_euler("ZYX", [float(y), float(p), float(r)])
    return Rotation.from_euler("ZYX", np.stack([y.ravel(), p.ravel(), r.ravel()], axis=-1))


def matrix_zyx(roll, pitch, yaw) -> np.ndarray:
    """``R_ned_from_frd`` (..., 3, 3) of Z-Y-X Euler angles (see :func:`rotation_zyx`)."""
    shape = np.broadcast_shapes(np.shape(roll), np.shape(pitch), np.shape(yaw))
    return rotation_zyx(roll, pitch, yaw).as_matrix().reshape(shape + (3, 3))


def quat_wxyz(rot: Rotation) -> np.ndarray:
    """MAVLink's quaternion order (w, x, y, z) of a rotation, w ≥ 0."""
    q = rot.as_quat(canonical=True)  # scipy: x, y, z, w
    return np.concatenate([q[..., 3:], q[..., :3]], axis=-1)


def body_rates(rotation_at, tau_s, h_s: float = 1e-4) -> np.ndarray:
    """Angular velocity (p, q, r) in rad/s of a frame, expressed in that frame, at times ``tau_s``.

    ``rotation_at(tau)`` gives the frame's rotation into NED. With R(t + dt) = R(t)·exp([ω] dt)
    for a body-frame ω, R(t − h)⁻¹·R(t + h) is a rotation by 2h·ω (to second order in h).
    """
    tau = np.atleast_1d(np.asarray(tau_s, dtype=float))
    before, after = rotation_at(tau - h_s), rotation_at(tau + h_s)
    w = (before.inv() * after).as_rotvec() / (2 * h_s)
    return w.reshape(np.shape(tau_s) + (3,))


# --- the camera --------------------------------------------------------------------------------


@dataclass(frozen=True)
class SimCamera:
    """Pinhole intrinsics (pixels) and OpenCV distortion ``(k1, k2, p1, p2, k3)``."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion: tuple = (0.0, 0.0, 0.0, 0.0, 0.0)

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def dist(self) -> np.ndarray:
        return np.asarray(self.distortion, dtype=float)

    def contains(self, u, v, margin_px: float = 0.0):
        """True where pixel (u, v) lies in the image (pixel centres at integers, edges at ±0.5)."""
        u, v = np.asarray(u, dtype=float), np.asarray(v, dtype=float)
        return (
            (u >= -0.5 + margin_px)
            & (u <= self.width - 0.5 - margin_px)
            & (v >= -0.5 + margin_px)
            & (v <= self.height - 0.5 - margin_px)
        )

    def max_radius(self) -> float:
        """Largest normalized radius (tan of the off-axis angle) up to which the radial distortion
        still increases with the radius: beyond it the lens model folds back and means nothing."""
        k1, k2, _, _, k3 = self.distortion
        r = np.linspace(0.0, 5.0, 50001)
        slope = 1 + 3 * k1 * r**2 + 5 * k2 * r**4 + 7 * k3 * r**6  # d(r·radial(r))/dr
        bad = np.flatnonzero(slope <= 0)
        return float(r[bad[0] - 1]) if len(bad) else float(r[-1])


def project(
    camera: SimCamera, R_ned_from_cv, camera_ned, points_ned
) -> tuple[np.ndarray, np.ndarray]:
    """Distorted pixels (u, v) of world points (..., 3) seen from one camera pose, by cv2.projectPoints.

    NaN for points behind the camera or outside the lens model's valid cone.
    """
    pts = np.asarray(points_ned, dtype=float)
    shape = pts.shape[:-1]
    pts = pts.reshape(-1, 3)
    R_cv_from_ned = np.asarray(R_ned_from_cv, dtype=float).T
    rvec, _ = cv2.Rodrigues(R_cv_from_ned)
    tvec = -R_cv_from_ned @ np.asarray(camera_ned, dtype=float)
    uv, _ = cv2.projectPoints(pts.reshape(-1, 1, 3), rvec, tvec, camera.K, camera.dist)
    uv = uv.reshape(-1, 2)
    p_cv = pts @ R_cv_from_ned.T + tvec
    with np.errstate(divide="ignore", invalid="ignore"):
        radius = np.hypot(p_cv[:, 0], p_cv[:, 1]) / p_cv[:, 2]
    bad = ~((p_cv[:, 2] > 0) & (radius <= camera.max_radius()))
    uv[bad] = np.nan
    return uv[:, 0].reshape(shape), uv[:, 1].reshape(shape)


def pixel_rays(camera: SimCamera, u, v) -> np.ndarray:
    """Unit rays (..., 3) in the cv frame through distorted pixels (u, v), by cv2.undistortPoints.

    OpenCV iterates a fixed point until the re-projection error is below
    ``UNDISTORT_CRITERIA``'s epsilon; each ray is then projected back and refused (NaN)
    unless it lands within ``UNDISTORT_CHECK_PX`` of its pixel.
    """
    u, v = np.broadcast_arrays(np.asarray(u, dtype=float), np.asarray(v, dtype=float))
    shape = u.shape
    pts = np.stack([u.ravel(), v.ravel()], axis=-1).reshape(-1, 1, 2)
    if len(pts) == 0:
        return np.zeros(shape + (3,))
    if hasattr(cv2, "undistortPointsIter"):  # OpenCV 4
        xy = cv2.undistortPointsIter(pts, camera.K, camera.dist, None, None, UNDISTORT_CRITERIA)
    else:  # OpenCV 5 folded it into undistortPoints
        xy = cv2.undistortPoints(pts, camera.K, camera.dist, None, None, None, UNDISTORT_CRITERIA)
    xy = xy.reshape(-1, 2)
    ray = np.column_stack([xy, np.ones(len(xy))])
    back, _ = cv2.projectPoints(
        ray.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), camera.K, camera.dist
    )
    off = np.abs(back.reshape(-1, 2) - pts.reshape(-1, 2)).max(axis=1)
    ray[~(off < UNDISTORT_CHECK_PX)] = np.nan
    ray /= np.linalg.norm(ray, axis=-1, keepdims=True)
    return ray.reshape(shape + (3,))


# --- refraction at the flat water surface ----------------------------------------------------------

SURFACE_NORMAL_UP = np.array([0.0, 0.0, -1.0])  # NED: the surface's normal on the air side


def refract_into_water(d_ned, n_water: float, normal_up=None) -> np.ndarray:
    """Direction in the water of unit rays (..., 3) going down through the surface.

    Snell's law in vector form: with the unit normal n on the incident side and
    cos θi = −n·i, the refracted ray is t = η·i + (η·cos θi − cos θt)·n, η = 1/n_water,
    cos θt = √(1 − η²·(1 − cos²θi)). ``normal_up``: the surface's unit normals on the air
    side (..., 3) where it is tilted (a wave's facet); unset: the flat surface's,
    :data:`SURFACE_NORMAL_UP`. Rays that do not go into the water through it give NaN.
    Float32 rays stay float32 (the floor's many rays under waves).
    """
    d = np.asarray(d_ned)
    d = d.astype(np.result_type(d.dtype, np.float32), copy=False)
    eta = 1.0 / n_water
    if normal_up is None:
        normal = SURFACE_NORMAL_UP
        cos_i = -(d @ SURFACE_NORMAL_UP)
    else:
        normal = np.asarray(normal_up, dtype=float)
        cos_i = -np.sum(d * normal, axis=-1)
    with np.errstate(invalid="ignore"):
        cos_t = np.sqrt(1.0 - eta**2 * (1.0 - cos_i**2))
        t = eta * d + (eta * cos_i - cos_t)[..., None] * normal
    return np.where((cos_i > 0)[..., None], t, np.nan)


def facet_normal_up(slope_ne) -> np.ndarray:
    """Unit normals (..., 3) on the air side of a surface down = −η(north, east) with slopes (∂η/∂north, ∂η/∂east)
    (..., 2): ∇(down + η) = (η_n, η_e, 1) points into the water; the air side is its opposite."""
    s = np.asarray(slope_ne)
    scale = -1.0 / np.sqrt(1.0 + s[..., 0] ** 2 + s[..., 1] ** 2)
    return np.stack([s[..., 0] * scale, s[..., 1] * scale, scale], axis=-1)


def reach_offset(d_ned, height_m, depth_m, n_water: float) -> np.ndarray:
    """Horizontal offset (north, east) from the camera's nadir at which a ray (..., 3) leaving a camera
    ``height_m`` above the water reaches ``depth_m`` below it (NaN if it does not go down)."""
    d = np.asarray(d_ned, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        air = d[..., :2] * (np.asarray(height_m, dtype=float) / d[..., 2])[..., None]
        t = refract_into_water(d, n_water)
        water = t[..., :2] * (np.asarray(depth_m, dtype=float) / t[..., 2])[..., None]
    return np.where((d[..., 2] > 0)[..., None], air + water, np.nan)


def surface_crossing(camera_ned, point_ned, n_water: float) -> np.ndarray:
    """Where light from submerged points (..., 3) to a camera in the air crosses the surface (NED, down 0).

    Fermat's principle: the crossing lies on the straight line between the two nadir
    points, at the distance s from the camera's that makes the optical path
    L(s) = √(s² + h²) + n·√((ρ − s)² + d²) stationary: dL/ds = s/√(s² + h²) − n·(ρ − s)/√((ρ − s)² + d²)
    rises from −n·ρ/√(ρ² + d²) at s = 0 to ρ/√(ρ² + h²) at s = ρ, so its root is bracketed.
    """
    cam = np.broadcast_to(np.asarray(camera_ned, dtype=float), np.shape(point_ned))
    pt = np.asarray(point_ned, dtype=float)
    flat_c, flat_p = cam.reshape(-1, 3), pt.reshape(-1, 3)
    out = np.empty_like(flat_p)
    for i, (c, p) in enumerate(zip(flat_c, flat_p)):
        h, d = -c[2], p[2]
        if not (h > 0 and d >= 0):
            out[i] = np.nan
            continue
        horizontal = p[:2] - c[:2]
        rho = float(np.hypot(*horizontal))
        if rho == 0.0:
            out[i] = (c[0], c[1], 0.0)
            continue
        if d == 0.0:  # a point on the surface is its own crossing
            out[i] = (p[0], p[1], 0.0)
            continue

        def slope(s, h=h, d=d, rho=rho):
            return s / np.hypot(s, h) - n_water * (rho - s) / np.hypot(rho - s, d)

        s = brentq(slope, 0.0, rho, xtol=1e-13, maxiter=200)
        out[i, :2] = c[:2] + horizontal * (s / rho)
        out[i, 2] = 0.0
    return out.reshape(pt.shape)


# --- geodesy -------------------------------------------------------------------------------------


def ned_to_geodetic(ned, lat0_deg: float, lon0_deg: float, alt0_m: float):
    """Latitude, longitude (degrees) and altitude (m) of world NED points (..., 3) from the origin,
    through pymap3d's East-North-Up conversion."""
    ned = np.asarray(ned, dtype=float)
    lat, lon, alt = pymap3d.enu2geodetic(
        ned[..., 1], ned[..., 0], -ned[..., 2], lat0_deg, lon0_deg, alt0_m
    )
    return np.asarray(lat), np.asarray(lon), np.asarray(alt)

"""The true state of the UAV, its camera and the UUV at any time of a scenario.

Times ``tau_s`` are seconds since the scenario's first frame (arrays). Positions
are in the scenario's world frame (local NED, origin on the water surface, metres);
attitudes are Z-Y-X Euler angles in radians. Every motion is a sum of slow
sinusoids, so telemetry sampled at its usual rates and interpolated linearly
reproduces the state to far below a millimetre. Random phases come from the seed.
"""

from __future__ import annotations

import numpy as np

from localizer.attitude import euler_to_R
from localizer.refraction import offset_from_ray

from .scenario import Scenario

TAU = 2 * np.pi


def _wave(tau, amplitude, freq_hz, phase):
    return amplitude * np.sin(TAU * freq_hz * np.asarray(tau, dtype=float) + phase)


def _eased(tau, keyframes):
    """Values through ``keyframes`` ((tau, value), ...) at ``tau``: cosine-eased between consecutive ones
    (the rate is zero at each keyframe, so the motion stays smooth), held before the first and after the last."""
    k = np.asarray(keyframes, dtype=float)
    tau = np.asarray(tau, dtype=float)
    if len(k) == 1:
        return np.full(tau.shape, k[0, 1])
    i = np.clip(np.searchsorted(k[:, 0], tau, side="right") - 1, 0, len(k) - 2)
    s = np.clip((tau - k[i, 0]) / (k[i + 1, 0] - k[i, 0]), 0.0, 1.0)
    return k[i, 1] + (k[i + 1, 1] - k[i, 1]) * (1.0 - np.cos(np.pi * s)) / 2.0


class Motion:
    """Trajectories of one scenario; deterministic for its seed."""

    def __init__(self, sc: Scenario):
        self.sc = sc
        rng = np.random.default_rng([sc.seed, 101])
        self._ph = rng.uniform(0, TAU, 16)
        self.uav_centre_ne_m = self._uav_centre()

    # --- UAV -----------------------------------------------------------------------------------
    def uav_rpy(self, tau_s):
        """UAV body (FRD) attitude in NED: array (..., 3) of roll, pitch, yaw (radians)."""
        u, ph = self.sc.uav, self._ph
        yaw = np.radians(u.yaw_deg) + _wave(tau_s, np.radians(u.yaw_swing_deg), 1.0 / u.yaw_period_s, ph[0])
        tilt = np.radians(u.tilt_deg) + _wave(tau_s, np.radians(u.gust_deg), 0.27, ph[1])
        lean = np.radians(u.wind_from_deg) - yaw  # the airframe leans towards where the wind comes from
        return np.stack([tilt * np.sin(lean), -tilt * np.cos(lean), yaw], axis=-1)

    def uav_ned(self, tau_s):
        """Position the autopilot reports (GLOBAL_POSITION_INT's point), world NED (..., 3)."""
        u, ph = self.sc.uav, self._ph
        n = self.uav_centre_ne_m[0] + _wave(tau_s, 0.7 * u.drift_m, 0.031, ph[2]) + _wave(tau_s, 0.3 * u.drift_m, 0.083, ph[3])
        e = self.uav_centre_ne_m[1] + _wave(tau_s, 0.7 * u.drift_m, 0.037, ph[4]) + _wave(tau_s, 0.3 * u.drift_m, 0.071, ph[5])
        d = -(u.height_m + _wave(tau_s, u.height_swing_m, 0.05, ph[6]))
        return np.stack([n, e, d], axis=-1)

    # --- camera --------------------------------------------------------------------------------
    def gimbal_rpy(self, tau_s):
        """Stabilised gimbal's FRD attitude in NED (roll, pitch relative to the horizon, yaw from North)."""
        m, ph = self.sc.mount, self._ph
        j = np.radians(m.jitter_deg)
        roll = _wave(tau_s, j, 0.4, ph[7])
        pitch = np.radians(m.pitch_deg) + _wave(tau_s, j, 0.7, ph[8])
        yaw = np.radians(m.yaw_deg) + _wave(tau_s, j, 0.5, ph[9])
        return np.stack([roll, pitch, yaw], axis=-1)

    def R_ned_from_gimbal(self, tau_s):
        """The camera's gimbal FRD frame (x = optical axis) in NED, (..., 3, 3)."""
        if self.sc.mount.attitude_source == "fixed":
            body = self.uav_rpy(tau_s)
            fixed = np.radians(self.sc.mount.fixed_rpy_deg)
            return euler_to_R(body[..., 0], body[..., 1], body[..., 2]) @ euler_to_R(*fixed)
        g = self.gimbal_rpy(tau_s)
        return euler_to_R(g[..., 0], g[..., 1], g[..., 2])

    def camera_ned(self, tau_s):
        """Camera position, world NED (..., 3): the reported point plus the body-frame offset."""
        rpy = self.uav_rpy(tau_s)
        R_body = euler_to_R(rpy[..., 0], rpy[..., 1], rpy[..., 2])
        return self.uav_ned(tau_s) + R_body @ np.asarray(self.sc.mount.camera_offset_m)

    # --- UUV -----------------------------------------------------------------------------------
    def uuv_ne(self, tau_s):
        """Horizontal position of the UUV (world north, east), (..., 2): a figure eight."""
        v, ph = self.sc.uuv, self._ph
        f = 1.0 / v.period_s
        n = v.north_m + _wave(tau_s, v.path_n_m, f, ph[10])
        e = v.east_m + _wave(tau_s, v.path_e_m, 2 * f, 2 * ph[10] + ph[11])
        return np.stack([n, e], axis=-1)

    def uuv_heading(self, tau_s):
        """UUV heading (radians from North): along its velocity."""
        dt = 1e-3
        d = self.uuv_ne(np.asarray(tau_s, dtype=float) + dt) - self.uuv_ne(np.asarray(tau_s, dtype=float) - dt)
        return np.arctan2(d[..., 1], d[..., 0])

    def uuv_depth_m(self, tau_s):
        """Depth of the UUV's reference point (centre of its top face) below the surface.

        ``depth_m`` ± a slow swing, or the ``depth_profile`` keyframes when given (see :func:`_eased`).
        """
        v = self.sc.uuv
        if v.depth_profile:
            return _eased(tau_s, v.depth_profile)
        return v.depth_m + _wave(tau_s, v.depth_swing_m, 1.0 / v.depth_period_s, self._ph[12])

    def uuv_ned(self, tau_s):
        """The UUV's reference point (centre of the top face), world NED (..., 3)."""
        return np.concatenate([self.uuv_ne(tau_s), self.uuv_depth_m(tau_s)[..., None]], axis=-1)

    # --- placement -----------------------------------------------------------------------------
    def _uav_centre(self):
        """Mean UAV position: given, or where the mean optical axis meets the UUV's path centre."""
        u, v = self.sc.uav, self.sc.uuv
        if u.standoff == "given":
            return np.array([u.north_m, u.east_m])
        if self.sc.mount.attitude_source == "fixed":
            r, p, y = np.radians(self.sc.mount.fixed_rpy_deg)
            axis = (euler_to_R(0.0, 0.0, np.radians(u.yaw_deg)) @ euler_to_R(r, p, y))[:, 0]
        else:
            axis = euler_to_R(0.0, np.radians(self.sc.mount.pitch_deg), np.radians(self.sc.mount.yaw_deg))[:, 0]
        off, reaches = offset_from_ray(axis, u.height_m, v.depth_m, self.sc.site.refractive_index)
        if not reaches:
            raise ValueError(f"scenario {self.sc.name}: the camera's optical axis does not reach the water")
        return np.array([v.north_m, v.east_m]) - off

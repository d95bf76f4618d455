"""The true state of the UAV, its camera and the UUV at any time of a scenario.

Times ``tau_s`` are seconds since the scenario's first frame (arrays). Positions
are in the scenario's world frame (local NED, origin on the water surface, metres);
attitudes are Z-Y-X Euler angles in radians, turned into rotations by scipy
(:mod:`sim_fixtures.geometry`). Every motion is a sum of slow sinusoids (plus an
optional faster airframe wobble), so telemetry sampled at its usual rates and
interpolated reproduces the state closely. Random phases come from the seed.

The camera's true attitude depends on the mount (``[mount]``):

- ``attitude_source = "fixed"``: rigid on the airframe, ``R_body · R(fixed_rpy_deg)``;
- ``kind = "stabilised"``: the gimbal holds roll 0 and ``pitch_deg`` relative to the
  horizon (plus a small jitter) and ``yaw_deg`` from North (``yaw_mode = "earth"``) or
  from the vehicle's heading (``"vehicle"``, follow mode);
- ``kind = "servo"`` (ArduPilot ``MNT1_TYPE 1``): the autopilot stabilises the camera by
  servo angles = target − the vehicle's lean (roll_servo = −roll, pitch_servo =
  pitch_deg − pitch, yaw relative to the vehicle), so the camera truly points at
  ``R_body · R(roll_servo, pitch_servo, yaw_rel)``, which is not exactly the target.

The UUV follows a slow figure eight or cruises (``[uuv] path``); the UAV hovers over a
fixed point or follows the UUV (``[uav] standoff = "follow"``). A second vehicle
(``[second_uuv]``) runs a straight line past the UUV; a rock (``[rock]``) lies by its path.
"""

from __future__ import annotations

import numpy as np

from .geometry import body_rates, matrix_zyx, reach_offset, rotation_zyx
from .scenario import Scenario

TAU = 2 * np.pi


def _wave(tau, amplitude, freq_hz, phase):
    return amplitude * np.sin(TAU * freq_hz * np.asarray(tau, dtype=float) + phase)


def wrap_pi(angle):
    """Angles in radians wrapped to [-pi, pi)."""
    return (np.asarray(angle, dtype=float) + np.pi) % TAU - np.pi


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
        self._ph_wobble = rng.uniform(0, TAU, 2)  # drawn after the others: they keep their values
        u, v = sc.uav, sc.uuv
        if u.standoff == "given":
            self._centre_ne_m = np.array([u.north_m, u.east_m])
        else:
            self._axis_offset_ne_m = self._axis_offset()
            self._centre_ne_m = np.array([v.north_m, v.east_m]) - self._axis_offset_ne_m
        self._lines = {key: self._line(getattr(sc, key)) for key in ("second_uuv", "third_uuv")}
        self.second_heading = self._lines["second_uuv"][0]
        self.third_heading = self._lines["third_uuv"][0]
        r = sc.rock
        self.rock_ned = np.append(
            self.uuv_ne(r.at_s) + np.asarray(r.offset_m), sc.site.floor_depth_m - r.size_m[2]
        )
        self.rock_heading = float(np.radians(r.heading_deg))

    # --- UAV -----------------------------------------------------------------------------------
    def uav_rpy(self, tau_s):
        """UAV body (FRD) attitude in NED: array (..., 3) of roll, pitch, yaw (radians)."""
        u, ph = self.sc.uav, self._ph
        yaw = np.radians(u.yaw_deg) + _wave(
            tau_s, np.radians(u.yaw_swing_deg), 1.0 / u.yaw_period_s, ph[0]
        )
        tilt = np.radians(u.tilt_deg) + _wave(tau_s, np.radians(u.gust_deg), 0.27, ph[1])
        # the airframe leans towards where the wind comes from
        lean = np.radians(u.wind_from_deg) - yaw
        roll, pitch = tilt * np.sin(lean), -tilt * np.cos(lean)
        if u.wobble_deg:
            w = np.radians(u.wobble_deg)
            roll = roll + _wave(tau_s, w, u.wobble_hz, self._ph_wobble[0])
            pitch = pitch + _wave(tau_s, w, u.wobble_hz, self._ph_wobble[1])
        return np.stack([roll, pitch, yaw], axis=-1)

    def body_rotation(self, tau_s):
        """The UAV body's rotation into NED (a scipy Rotation, one per time)."""
        rpy = self.uav_rpy(tau_s)
        return rotation_zyx(rpy[..., 0], rpy[..., 1], rpy[..., 2])

    def R_ned_from_body(self, tau_s):
        rpy = self.uav_rpy(tau_s)
        return matrix_zyx(rpy[..., 0], rpy[..., 1], rpy[..., 2])

    def body_rates(self, tau_s):
        """The body's angular velocity (p, q, r) in rad/s, in the body frame (FRD), (..., 3)."""
        return body_rates(self.body_rotation, tau_s)

    def uav_ned(self, tau_s):
        """Position the autopilot reports (GLOBAL_POSITION_INT's point), world NED (..., 3)."""
        u, ph = self.sc.uav, self._ph
        c = self.uav_centre_ne(tau_s)
        n = (
            c[..., 0]
            + _wave(tau_s, 0.7 * u.drift_m, 0.031, ph[2])
            + _wave(tau_s, 0.3 * u.drift_m, 0.083, ph[3])
        )
        e = (
            c[..., 1]
            + _wave(tau_s, 0.7 * u.drift_m, 0.037, ph[4])
            + _wave(tau_s, 0.3 * u.drift_m, 0.071, ph[5])
        )
        d = -(u.height_m + _wave(tau_s, u.height_swing_m, 0.05, ph[6]))
        return np.stack([n, e, d], axis=-1)

    def uav_centre_ne(self, tau_s):
        """The point the UAV's drift wanders about, world (north, east) (..., 2): fixed, or for ``standoff =
        "follow"`` where the optical axis meets the UUV's depth when the UUV was there ``follow_lag_s`` ago."""
        tau = np.asarray(tau_s, dtype=float)
        if self.sc.uav.standoff == "follow":
            return self.uuv_ne(tau - self.sc.uav.follow_lag_s) - self._axis_offset_ne_m
        return np.broadcast_to(self._centre_ne_m, tau.shape + (2,))

    def uav_velocity_ned(self, tau_s, h_s: float = 1e-3):
        """Velocity of the reported point, NED m/s (..., 3) (central difference; the motion is slow)."""
        tau = np.asarray(tau_s, dtype=float)
        return (self.uav_ned(tau + h_s) - self.uav_ned(tau - h_s)) / (2 * h_s)

    # --- camera --------------------------------------------------------------------------------
    def gimbal_target(self, tau_s):
        """The mount's target attitude: (..., 4) roll, pitch (relative to the horizon), yaw relative
        to the vehicle's heading, yaw from North (radians). Includes the gimbal's small jitter."""
        m, ph = self.sc.mount, self._ph
        j = np.radians(m.jitter_deg)
        roll = _wave(tau_s, j, 0.4, ph[7])
        pitch = np.radians(m.pitch_deg) + _wave(tau_s, j, 0.7, ph[8])
        vehicle_yaw = self.uav_rpy(tau_s)[..., 2]
        if m.yaw_mode == "vehicle":
            yaw_rel = np.radians(m.yaw_deg) + _wave(tau_s, j, 0.5, ph[9])
            yaw = vehicle_yaw + yaw_rel
        else:
            yaw = np.radians(m.yaw_deg) + _wave(tau_s, j, 0.5, ph[9])
            yaw_rel = wrap_pi(yaw - vehicle_yaw)
        return np.stack([roll, pitch, yaw_rel, yaw], axis=-1)

    def gimbal_rpy(self, tau_s):
        """A stabilised gimbal's FRD attitude in NED: roll, pitch relative to the horizon, yaw from North."""
        return self.gimbal_target(tau_s)[..., [0, 1, 3]]

    def servo_angles(self, tau_s):
        """A servo mount's demands (..., 3): roll, pitch = target − the vehicle's lean, yaw relative to
        the vehicle; the camera's attitude relative to the body as Z-Y-X Euler angles."""
        g = self.gimbal_target(tau_s)
        body = self.uav_rpy(tau_s)
        return np.stack([g[..., 0] - body[..., 0], g[..., 1] - body[..., 1], g[..., 2]], axis=-1)

    def reported_gimbal(self, tau_s):
        """What the autopilot reports of the camera: (..., 3) roll, pitch, yaw relative to the vehicle.

        A stabilised gimbal reports its horizon-relative attitude; a servo mount its servo
        demands, which ArduPilot flags as horizon-relative all the same.
        """
        if self.sc.mount.kind == "servo":
            return self.servo_angles(tau_s)
        return self.gimbal_target(tau_s)[..., :3]

    def R_ned_from_gimbal(self, tau_s):
        """The camera's gimbal FRD frame (x = optical axis) in NED, (..., 3, 3): the true attitude."""
        m = self.sc.mount
        if m.attitude_source == "fixed":
            return self.R_ned_from_body(tau_s) @ matrix_zyx(*np.radians(m.fixed_rpy_deg))
        if m.kind == "servo":
            s = self.servo_angles(tau_s)
            return self.R_ned_from_body(tau_s) @ matrix_zyx(s[..., 0], s[..., 1], s[..., 2])
        g = self.gimbal_rpy(tau_s)
        return matrix_zyx(g[..., 0], g[..., 1], g[..., 2])

    def camera_ned(self, tau_s):
        """Camera position, world NED (..., 3): the reported point plus the body-frame offset."""
        return self.uav_ned(tau_s) + self.R_ned_from_body(tau_s) @ np.asarray(
            self.sc.mount.camera_offset_m
        )

    # --- UUV -----------------------------------------------------------------------------------
    def uuv_ne(self, tau_s):
        """Horizontal position of the UUV (world north, east), (..., 2): a figure eight, or a cruise from
        (north_m, east_m) along course_deg at speed_mps, weaving sideways (positive: to the course's right)."""
        v, ph = self.sc.uuv, self._ph
        if v.path == "cruise":
            tau = np.asarray(tau_s, dtype=float)
            course = np.radians(v.course_deg)
            along = v.speed_mps * tau
            side = v.weave_m * np.sin(TAU * tau / v.weave_period_s)
            n = v.north_m + along * np.cos(course) - side * np.sin(course)
            e = v.east_m + along * np.sin(course) + side * np.cos(course)
            return np.stack([n, e], axis=-1)
        f = 1.0 / v.period_s
        n = v.north_m + _wave(tau_s, v.path_n_m, f, ph[10])
        e = v.east_m + _wave(tau_s, v.path_e_m, 2 * f, 2 * ph[10] + ph[11])
        return np.stack([n, e], axis=-1)

    def uuv_heading(self, tau_s):
        """UUV heading (radians from North): along its velocity."""
        dt = 1e-3
        d = self.uuv_ne(np.asarray(tau_s, dtype=float) + dt) - self.uuv_ne(
            np.asarray(tau_s, dtype=float) - dt
        )
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

    # --- the look-alikes ----------------------------------------------------------------------------
    def _line(self, s):
        """A passing vehicle's line (``[second_uuv]``'s or ``[third_uuv]``'s table ``s``): its heading (radians), its
        direction (north, east) and its place at ``pass_at_s`` (north, east, m)."""
        course = self.uuv_heading(s.pass_at_s) + np.radians(s.course_rel_deg)
        at_pass = self.uuv_ne(s.pass_at_s) + s.miss_m * np.array([-np.sin(course), np.cos(course)])
        return float(wrap_pi(course)), np.array([np.cos(course), np.sin(course)]), at_pass

    def second_ned(self, tau_s, key: str = "second_uuv"):
        """The second vehicle's reference point (centre of its top face), world NED (..., 3): a straight line at
        ``speed_mps`` through its place at ``pass_at_s``; its heading is :attr:`second_heading` (radians).
        ``key`` "third_uuv": the third vehicle's (:attr:`third_heading`)."""
        s = getattr(self.sc, key)
        _, direction_ne, at_pass_ne_m = self._lines[key]
        tau = np.asarray(tau_s, dtype=float)
        ne = at_pass_ne_m + (s.speed_mps * (tau - s.pass_at_s))[..., None] * direction_ne
        return np.concatenate([ne, np.full(tau.shape + (1,), s.depth_m)], axis=-1)

    # --- placement -----------------------------------------------------------------------------
    def _axis_offset(self):
        """Horizontal offset (north, east) from the mean UAV position to where its mean optical axis meets the
        UUV's mean depth."""
        u, v, m = self.sc.uav, self.sc.uuv, self.sc.mount
        yaw = np.radians(u.yaw_deg)
        if m.attitude_source == "fixed":
            R = matrix_zyx(0.0, 0.0, yaw) @ matrix_zyx(*np.radians(m.fixed_rpy_deg))
        elif m.kind == "servo":  # the mean lean matters: the servos do not quite cancel it
            lean, tilt = np.radians(u.wind_from_deg) - yaw, np.radians(u.tilt_deg)
            roll, pitch = tilt * np.sin(lean), -tilt * np.cos(lean)
            yaw_rel = (
                np.radians(m.yaw_deg) if m.yaw_mode == "vehicle" else np.radians(m.yaw_deg) - yaw
            )
            R = matrix_zyx(roll, pitch, yaw) @ matrix_zyx(
                -roll, np.radians(m.pitch_deg) - pitch, yaw_rel
            )
        else:
            gimbal_yaw = np.radians(m.yaw_deg) + (yaw if m.yaw_mode == "vehicle" else 0.0)
            R = matrix_zyx(0.0, np.radians(m.pitch_deg), gimbal_yaw)
        off = reach_offset(R[:, 0], u.height_m, v.depth_m, self.sc.site.refractive_index)
        if not np.all(np.isfinite(off)):
            raise ValueError(
                f"scenario {self.sc.name}: the camera's optical axis does not reach the water"
            )
        return off


def first_contact(sc: Scenario, motion: Motion, other: str, step_s: float = 0.02):
    """The first scenario time (telemetry lead included) at which the UUV and ``other`` ("the second vehicle", "the
    third vehicle" or "the rock", when enabled) might touch, or None: their depth spans overlap while their centres are closer than
    the sum of their half diagonals (a conservative test: boxes that pass it never touch)."""
    v = sc.uuv
    key = {"the second vehicle": "second_uuv", "the third vehicle": "third_uuv"}.get(other)
    if key is not None and getattr(sc, key).enabled:
        size, top = v.size_m, None
    elif other == "the rock" and sc.rock.enabled:
        size, top = sc.rock.size_m, motion.rock_ned
    else:
        return None
    tau = np.arange(-sc.telemetry.lead_s, sc.duration_s + step_s, step_s)
    uuv = motion.uuv_ned(tau)
    there = motion.second_ned(tau, key) if top is None else np.broadcast_to(top, uuv.shape)
    reach = 0.5 * (np.hypot(v.size_m[0], v.size_m[1]) + np.hypot(size[0], size[1]))
    close = np.hypot(*(uuv[:, :2] - there[:, :2]).T) < reach
    overlap = (uuv[:, 2] < there[:, 2] + size[2]) & (there[:, 2] < uuv[:, 2] + v.size_m[2])
    hit = np.flatnonzero(close & overlap)
    return float(tau[hit[0]]) if len(hit) else None

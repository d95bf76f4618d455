"""The UAV's telemetry as a standard tlog: real MAVLink 2 frames with link delay and jitter.

Each message's values are the true state at its ``time_boot_ms`` (plus the
scenario's optional noise), so geometry from this telemetry alone can reach the
truth. Record times are the ground station's receive times: send time + the
link's delay + an exponential jitter, kept in order as a real link delivers them.
Integer microseconds of UNIX time throughout.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from groundstation.mavlink_io import mavutil
from localizer.attitude import (
    GIMBAL_DEVICE_FLAGS_YAW_IN_EARTH_FRAME,
    GIMBAL_DEVICE_FLAGS_YAW_IN_VEHICLE_FRAME,
    euler_to_quat,
)
from localizer.geodesy import ned_to_geodetic

from .motion import Motion
from .scenario import Scenario

GIMBAL_DEVICE_FLAGS_ROLL_LOCK = 4  # roll and pitch relative to the horizon
GIMBAL_DEVICE_FLAGS_PITCH_LOCK = 8


@dataclass(frozen=True)
class Clock:
    """The autopilot's boot clock: UNIX microseconds at ``time_boot_ms = 0``."""

    boot_epoch_us: int
    start_us: int  # UNIX microseconds of the scenario's first frame

    @classmethod
    def of(cls, sc: Scenario) -> Clock:
        start_us = round(sc.start_unix * 1e6)
        return cls(start_us - round(sc.link.boot_s_at_start * 1e6), start_us)

    def tau_s(self, boot_ms):
        """Scenario time (s since the first frame) of boot-clock milliseconds."""
        return (np.asarray(boot_ms, dtype=np.int64) * 1000 + self.boot_epoch_us - self.start_us) / 1e6


def sample_times_ms(clock: Clock, rate_hz: float, tau0_s: float, tau1_s: float, rng) -> np.ndarray:
    """Boot-clock milliseconds of a stream at ``rate_hz`` over [tau0, tau1], with ±10 % scheduling jitter."""
    period = 1.0 / rate_hz
    tau = np.arange(tau0_s, tau1_s, period)
    tau = tau + rng.uniform(-0.1, 0.1, len(tau)) * period
    ms = np.round((clock.start_us - clock.boot_epoch_us) / 1000 + tau * 1000).astype(np.int64)
    return np.unique(ms)  # strictly increasing


def _messages(sc: Scenario, motion: Motion, clock: Clock, rng):
    """Every message as ``(sample_us, encode_name, args)`` in no particular order."""
    mav = mavutil().mavlink
    tel = sc.telemetry
    tau0, tau1 = -tel.lead_s, sc.duration_s + 1.0
    att_noise = np.radians(tel.attitude_noise_deg)
    out = []

    def add(ms, name, rows):
        us = ms * 1000 + clock.boot_epoch_us
        out.extend((int(u), name, args) for u, args in zip(us, rows))

    ms = sample_times_ms(clock, 1.0, tau0, tau1, rng)
    armed = mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | mav.MAV_MODE_FLAG_SAFETY_ARMED
    loiter = 5  # ArduCopter's LOITER flight mode
    add(ms, "heartbeat", [(mav.MAV_TYPE_QUADROTOR, mav.MAV_AUTOPILOT_ARDUPILOTMEGA, armed, loiter, mav.MAV_STATE_ACTIVE)] * len(ms))
    ms = sample_times_ms(clock, 1.0, tau0, tau1, rng)
    add(ms, "system_time", [(int(m * 1000 + clock.boot_epoch_us), int(m)) for m in ms])

    ms = sample_times_ms(clock, tel.attitude_hz, tau0, tau1, rng)
    tau = clock.tau_s(ms)
    rpy = motion.uav_rpy(tau) + rng.normal(0.0, 1.0, (len(ms), 3)) * att_noise
    rates = (motion.uav_rpy(tau + 0.005) - motion.uav_rpy(tau - 0.005)) / 0.01
    rpy[:, 2] = (rpy[:, 2] + np.pi) % (2 * np.pi) - np.pi
    add(ms, "attitude", [(int(m), *map(float, a), *map(float, r)) for m, a, r in zip(ms, rpy, rates)])

    ms = sample_times_ms(clock, tel.position_hz, tau0, tau1, rng)
    tau = clock.tau_s(ms)
    ned = motion.uav_ned(tau)
    vel = (motion.uav_ned(tau + 0.05) - motion.uav_ned(tau - 0.05)) / 0.1
    s = sc.site
    lat, lon, alt = ned_to_geodetic(ned[:, 0], ned[:, 1], ned[:, 2], s.lat_deg, s.lon_deg, s.surface_amsl_m)
    alt = alt + rng.normal(0.0, 1.0, len(ms)) * tel.height_noise_m
    rel = -ned[:, 2] - s.takeoff_height_above_surface_m + rng.normal(0.0, 1.0, len(ms)) * tel.height_noise_m
    hdg = np.round(np.degrees(motion.uav_rpy(tau)[:, 2]) % 360 * 100).astype(int) % 36000
    add(ms, "global_position_int", [
        (int(m), round(la * 1e7), round(lo * 1e7), round(a * 1000), round(r * 1000),
         round(v[0] * 100), round(v[1] * 100), round(v[2] * 100), int(h))
        for m, la, lo, a, r, v, h in zip(ms, lat, lon, alt, rel, vel, hdg)
    ])

    if sc.mount.attitude_source != "fixed":
        ms = sample_times_ms(clock, tel.gimbal_hz, tau0, tau1, rng)
        tau = clock.tau_s(ms)
        g = motion.gimbal_rpy(tau) + rng.normal(0.0, 1.0, (len(ms), 3)) * att_noise
        yaw_rel = g[:, 2] - motion.uav_rpy(tau)[:, 2]
        if sc.mount.attitude_source == "mount_orientation":
            add(ms, "mount_orientation", [
                (int(m), *np.degrees([r, p, (yr + np.pi) % (2 * np.pi) - np.pi]), float(np.degrees(y) % 360))
                for m, r, p, yr, y in zip(ms, g[:, 0], g[:, 1], yaw_rel, g[:, 2])
            ])
        else:
            earth = sc.mount.gimbal_frame == "earth"
            flags = GIMBAL_DEVICE_FLAGS_ROLL_LOCK | GIMBAL_DEVICE_FLAGS_PITCH_LOCK | (
                GIMBAL_DEVICE_FLAGS_YAW_IN_EARTH_FRAME if earth else GIMBAL_DEVICE_FLAGS_YAW_IN_VEHICLE_FRAME)
            q = euler_to_quat(g[:, 0], g[:, 1], g[:, 2] if earth else yaw_rel)
            nan = float("nan")
            add(ms, "gimbal_device_attitude_status", [
                (0, 0, int(m), flags, [float(x) for x in qq], nan, nan, nan, 0) for m, qq in zip(ms, q)
            ])
    return out


def write_tlog(path: Path, sc: Scenario, motion: Motion, clock: Clock, rng) -> dict[str, int]:
    """Write ``uav.tlog``; returns the number of messages of each type."""
    mav = mavutil().mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    msgs = sorted(_messages(sc, motion, clock, rng), key=lambda m: m[0])
    send_us = np.array([m[0] for m in msgs], dtype=np.int64) + 800  # the autopilot sends ~1 ms after sampling
    extra = rng.exponential(sc.link.jitter_s, len(msgs)) if sc.link.jitter_s > 0 else np.zeros(len(msgs))
    recv_us = np.maximum.accumulate(send_us + np.round((sc.link.delay_s + extra) * 1e6).astype(np.int64))
    counts: dict[str, int] = {}
    with open(path, "wb") as f:
        for (_, name, args), t_us in zip(msgs, recv_us):
            msg = getattr(mav, name + "_encode")(*args)
            f.write(struct.pack(">Q", int(t_us)) + msg.pack(mav))
            counts[msg.get_type()] = counts.get(msg.get_type(), 0) + 1
    return counts

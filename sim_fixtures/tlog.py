"""The UAV's telemetry as a standard tlog: real MAVLink 2 frames with link delay and jitter.

Clocks (all integer microseconds):

- *true* time: GNSS/UNIX time; the scenario's ``start_unix`` is the first frame's;
- the *station* clock (the ground station's laptop): true + ``[clock] station_offset_s``.
  It stamps every record of the tlog (the receive time), the frames and depth arrivals;
- the autopilot's *boot* clock (``time_boot_ms``): zero ``link.boot_s_at_start`` before the
  first frame, and again at ``link.reboot_at_s`` when the autopilot reboots; it then sends
  nothing for ``link.reboot_down_s``.

Each message's values are the true state at its ``time_boot_ms`` (plus the
scenario's optional noise and the drone's sensor errors, ``[sensors]``: :mod:`sim_fixtures.sensors`),
so without them geometry from this telemetry alone can reach the truth. Messages (system 1,
component 1, as ArduPilot's):

- HEARTBEAT (1 Hz): armed (``base_mode`` SAFETY_ARMED) from ``uav.armed_at_s`` on, or throughout;
  SYSTEM_TIME (``system_time_hz``): ``time_unix_usec`` is true time;
- ATTITUDE (``attitude_hz``): roll, pitch, yaw (with the AHRS's errors) and the true body rates (p, q, r in
  rad/s, FRD);
- GLOBAL_POSITION_INT (``position_hz``) with its true NED velocity (cm/s); ``lat``, ``lon`` the EKF's position
  (with the GNSS's walk), ``hdg`` the autopilot's heading; its heights ``alt`` and ``relative_alt`` carry the
  barometer's error (:func:`baro_error_m` and the sensors' white noise), as ArduPilot's EKF's do when the
  barometer is its height source (EK3_SRC1_POSZ = 1);
- GPS_RAW_INT (``gps_raw_hz``): see :func:`_gps_raw`;
- DISTANCE_SENSOR and ArduPilot's RANGEFINDER (``[rangefinder]``): see :func:`_rangefinder`;
- GIMBAL_DEVICE_ATTITUDE_STATUS or MOUNT_ORIENTATION (``gimbal_hz``) unless the camera is fixed;
- TIMESYNC replies: the ground station sends requests (``tc1`` 0, ``ts1`` its station-clock
  send time in ns) at ``timesync_hz``; the autopilot answers like ArduPilot with
  ``tc1`` = its boot time in ns when the request arrived and ``ts1`` echoed. The uplink
  takes ``link.delay_s`` plus the same exponential jitter as the downlink;
- PARAM_VALUE ``MNT1_TYPE`` = 1 for a servo mount, as if the ground station had asked for it.

Record times are the ground station's receive times: send time (sample + 0.8 ms) +
the link's delay + an exponential jitter, kept in order as a real link delivers them.
Every random draw comes from its own stream, independent of the clock offsets, so a
scenario and its twin with other offsets have the same samples, values and delays.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from groundstation.mavlink.ingest import mavutil
from groundstation.session.tlog import tlog_record

from .geometry import ned_to_geodetic, quat_wxyz, rotation_zyx
from .motion import Motion, wrap_pi
from .scenario import Scenario
from .sensors import (
    ahrs_error_rpy,
    baro_noise_m,
    baro_wander_m,
    drawn,
    gnss_claim,
    levelled,
    ned_with_error,
    position_error_ne_m,
    position_white_ne_m,
)

# MAVLink GIMBAL_DEVICE_FLAGS (common.xml)
GIMBAL_DEVICE_FLAGS_ROLL_LOCK = 4  # roll relative to the horizon
GIMBAL_DEVICE_FLAGS_PITCH_LOCK = 8  # pitch relative to the horizon
GIMBAL_DEVICE_FLAGS_YAW_IN_VEHICLE_FRAME = 32
GIMBAL_DEVICE_FLAGS_YAW_IN_EARTH_FRAME = 64
SEND_LATENCY_US = 800  # the autopilot sends a message this long after sampling it
# PARAM_VALUE param_count: the autopilot's number of parameters (illustrative)
GCS_PARAM_COUNT = 1200

# independent random streams: np.random.default_rng([seed, 404, STREAM[name]])
STREAM = {
    "heartbeat": 1,
    "system_time": 2,
    "attitude": 3,
    "position": 4,
    "gimbal": 5,
    "gps_raw": 6,
    "timesync": 7,
    "downlink": 8,
    "depth": 9,
    "depth_link": 10,
    "gnss_alt": 11,
    "rangefinder": 12,
    "second_depth": 13,
    "second_link": 14,  # a second UUV's depth sensor and link
    "gnss_alt_noise": 15,
    "third_depth": 16,
    "third_link": 17,  # a third UUV's depth sensor and link
}
MAV_SENSOR_ROTATION_PITCH_270 = 25  # a rangefinder looking down the body's z axis
# ArduPilot's lidar drivers report max + 1 m when nothing returns (e.g. Benewake)
OUT_OF_RANGE_ADD_M = 1.0


def stream(sc: Scenario, name: str, sensor: bool = False):
    """The random stream ``name``; ``sensor``: a sensor's error, drawn again with ``[sensors] draw``
    (:func:`sim_fixtures.sensors.drawn`)."""
    return np.random.default_rng([sc.seed, 404, STREAM[name], *(drawn(sc) if sensor else [])])


def exponential(rng, mean_s: float, n: int) -> np.ndarray:
    return rng.exponential(mean_s, n) if mean_s > 0 else np.zeros(n)


@dataclass(frozen=True)
class Clock:
    """The clocks of a scenario, in integer UNIX microseconds (see the module's docstring)."""

    boot_epoch_us: int  # true time at time_boot_ms = 0 (the first boot)
    start_us: int  # true time of the scenario's first frame
    station_offset_us: int = 0  # station clock minus true time
    uuv_offset_us: int = 0  # UUV clock minus true time
    reboot_us: int | None = None  # true time of the reboot: the second boot clock's zero
    back_us: int | None = None  # true time the rebooted autopilot talks again

    @classmethod
    def of(cls, sc: Scenario) -> Clock:
        start_us = round(sc.start_unix * 1e6)
        reboot = back = None
        if sc.link.reboot_at_s is not None:
            reboot = start_us + round(sc.link.reboot_at_s * 1e6)
            back = reboot + round(sc.link.reboot_down_s * 1e6)
        return cls(
            start_us - round(sc.link.boot_s_at_start * 1e6),
            start_us,
            round(sc.clock.station_offset_s * 1e6),
            round(sc.clock.uuv_offset_s * 1e6),
            reboot,
            back,
        )

    def true_us(self, tau_s) -> np.ndarray:
        """True time of scenario times (seconds since the first frame)."""
        return self.start_us + np.round(np.asarray(tau_s, dtype=float) * 1e6).astype(np.int64)

    def tau_of_us(self, true_us) -> np.ndarray:
        return (np.asarray(true_us, dtype=np.int64) - self.start_us) / 1e6

    def up(self, true_us) -> np.ndarray:
        """Whether the autopilot is running (not in its reboot) at these true times."""
        t = np.asarray(true_us, dtype=np.int64)
        if self.reboot_us is None:
            return np.ones(t.shape, bool)
        return (t < self.reboot_us) | (t >= self.back_us)

    def epoch_us(self, true_us) -> np.ndarray:
        """The boot clock's zero in force at these true times."""
        t = np.asarray(true_us, dtype=np.int64)
        if self.reboot_us is None:
            return np.full(t.shape, self.boot_epoch_us, np.int64)
        return np.where(t >= self.reboot_us, self.reboot_us, self.boot_epoch_us).astype(np.int64)

    def tau_s(self, boot_ms, rebooted=False):
        """Scenario time (s since the first frame) of boot-clock milliseconds (of the second boot if ``rebooted``)."""
        epoch = np.where(
            rebooted, self.reboot_us if self.reboot_us is not None else 0, self.boot_epoch_us
        )
        return (np.asarray(boot_ms, dtype=np.int64) * 1000 + epoch - self.start_us) / 1e6

    def station_us(self, true_us) -> np.ndarray:
        return np.asarray(true_us, dtype=np.int64) + self.station_offset_us


def sample_times(clock: Clock, rate_hz: float, tau0_s: float, tau1_s: float, rng):
    """A stream at ``rate_hz`` over [tau0, tau1] with ±10 % scheduling jitter, on whole boot milliseconds.

    Returns ``(true_us, boot_ms)``, strictly increasing true times; none while the autopilot reboots.
    """
    period = 1.0 / rate_hz
    tau = np.arange(tau0_s, tau1_s, period)
    tau = tau + rng.uniform(-0.1, 0.1, len(tau)) * period
    t = clock.true_us(tau)
    t = t[clock.up(t)]
    epoch = clock.epoch_us(t)
    ms = (t - epoch) // 1000
    t, first = np.unique(epoch + ms * 1000, return_index=True)
    return t, ms[first]


def baro_error_m(sc: Scenario, tau_s):
    """The EKF heights' slow error (m, positive: they read high) at scenario times: ``uav.baro_bias_m`` at the
    first frame, changing linearly by ``uav.baro_drift_m`` up to the last, plus the barometer's wander
    (``[sensors] baro_wander_m``)."""
    u = sc.uav
    return (
        u.baro_bias_m
        + u.baro_drift_m * np.asarray(tau_s, dtype=float) / sc.duration_s
        + baro_wander_m(sc, tau_s)
    )


def gnss_alt_error_m(sc: Scenario, tau_s):
    """The GNSS altitude's error (m) at scenario times: three sinusoids of ``uav.gnss_alt_error_period_s``,
    0.61 and 0.37 of it, random phases, together of RMS ``uav.gnss_alt_error_m``."""
    u = sc.uav
    tau = np.asarray(tau_s, dtype=float)
    phases = stream(sc, "gnss_alt", sensor=True).uniform(0.0, 2 * np.pi, 3)
    amplitude = u.gnss_alt_error_m / np.sqrt(1.5)  # three sinusoids of amplitude a: RMS a·sqrt(3/2)
    return sum(
        amplitude * np.sin(2 * np.pi * tau / (u.gnss_alt_error_period_s * k) + ph)
        for k, ph in zip((1.0, 0.61, 0.37), phases)
    )


def _gps_raw(sc: Scenario, motion: Motion, clock: Clock, t_us, ms, rng):
    """GPS_RAW_INT arguments: the reported point's position with the receiver's error (the walk GLOBAL_POSITION_INT
    follows, and white noise of its own: :mod:`sim_fixtures.sensors`), its
    altitude with the GNSS's own error (:func:`gnss_alt_error_m`, and ``uav.gnss_alt_noise_m`` of white noise), not
    the barometer's.

    ``time_usec`` true UNIX µs (``gps_raw_time = "unix"``) or boot µs (``"boot"``, ArduPilot's
    ``last_fix_time_ms``·1000); ``fix_type``, ``h_acc`` and ``eph`` (HDOP × 100) the receiver's claims
    (:func:`~sim_fixtures.sensors.gnss_claim`: ``uav.gnss_fix_type``, ``gnss_h_acc_m``, ``gnss_hdop`` or
    ``[sensors] gnss_mode``'s), ``epv`` VDOP × 100 (``uav.gnss_vdop``); ``vel`` ground speed cm/s, ``cog``
    course over ground cdeg; 14 satellites; ``alt_ellipsoid`` = alt + ``site.geoid_separation_m`` (mm);
    ``v_acc`` = ``uav.gnss_v_acc_m`` or twice h_acc (mm), both 0 with
    ``gnss_accuracy = "dop_only"``; ``vel_acc`` 30 mm/s; ``hdg_acc`` and ``yaw`` 0 (no GNSS yaw).
    """
    s, u = sc.site, sc.uav
    tau = clock.tau_of_us(t_us)
    error_ne = position_error_ne_m(sc, tau) + position_white_ne_m(sc, "raw", len(tau))
    lat, lon, alt = ned_to_geodetic(
        ned_with_error(motion.uav_ned(tau), error_ne), s.lat_deg, s.lon_deg, s.surface_amsl_m
    )
    alt = (
        alt
        + rng.normal(0.0, 1.0, len(tau)) * sc.telemetry.height_noise_m
        + gnss_alt_error_m(sc, tau)
    )
    # its own stream: 0 adds 0
    alt = alt + stream(sc, "gnss_alt_noise", sensor=True).normal(0.0, u.gnss_alt_noise_m, len(tau))
    vel = motion.uav_velocity_ned(tau)
    speed = np.hypot(vel[:, 0], vel[:, 1])
    cog = np.round(np.degrees(np.arctan2(vel[:, 1], vel[:, 0])) % 360 * 100).astype(int) % 36000
    time_usec = t_us if sc.telemetry.gps_raw_time == "unix" else ms * 1000
    fix_type, h_acc_m, hdop = gnss_claim(sc)
    h_acc = round(h_acc_m * 1000)
    v_acc = 2 * h_acc if u.gnss_v_acc_m is None else round(u.gnss_v_acc_m * 1000)
    if u.gnss_accuracy == "dop_only":
        h_acc = v_acc = 0
    eph, epv = round(hdop * 100), round(u.gnss_vdop * 100)
    return [
        (
            int(tu),
            fix_type,
            round(la * 1e7),
            round(lo * 1e7),
            round(a * 1000),
            eph,
            epv,
            round(v * 100),
            int(c),
            14,
            round((a + s.geoid_separation_m) * 1000),
            h_acc,
            v_acc,
            30,
            0,
            0,
        )
        for tu, la, lo, a, v, c in zip(time_usec, lat, lon, alt, speed, cog)
    ]


def rangefinder_distance_m(sc: Scenario, motion: Motion, tau_s):
    """What a downward rangefinder at the reported position measures (m, before noise): the distance along
    the body's down axis to what it sees (``[rangefinder] sees``)."""
    tau = np.asarray(tau_s, dtype=float)
    rf, s = sc.rangefinder, sc.site
    if rf.sees == "nothing":
        return np.full(tau.shape, rf.max_m + OUT_OF_RANGE_ADD_M)
    height = -motion.uav_ned(tau)[..., 2]
    if (
        rf.sees == "floor"
    ):  # light travels n times slower in water: the time of flight reads n × the depth
        height = height + s.refractive_index * s.floor_depth_m
    down_axis_down = motion.R_ned_from_body(tau)[
        ..., 2, 2
    ]  # the body's z axis, its NED down component
    return height / down_axis_down


def _rangefinder(sc: Scenario, motion: Motion, clock: Clock, t_us, ms, rng):
    """``(t_us, DISTANCE_SENSOR rows, RANGEFINDER rows)`` as ArduPilot sends them for a downward rangefinder.

    DISTANCE_SENSOR: ``time_boot_ms``, min/max/current distance in cm, type 0 (laser), id 0, orientation 25
    (PITCH_270), covariance 0 (unknown), no FOV or quaternion, signal_quality 0 (unknown); RANGEFINDER:
    the distance in metres and voltage 0. None during ``[rangefinder] dropouts``.
    """
    rf = sc.rangefinder
    tau = clock.tau_of_us(t_us)
    noise = rng.normal(0.0, 1.0, len(tau)) * rf.noise_m
    distance = rangefinder_distance_m(sc, motion, tau) + (noise if rf.sees != "nothing" else 0.0)
    keep = np.ones(len(tau), bool)
    for a, b in rf.dropouts:
        keep &= ~((tau >= a) & (tau < b))
    cm = np.clip(np.round(distance * 100), 0, 65535).astype(int)
    lo, hi = round(rf.min_m * 100), round(rf.max_m * 100)
    ds = [
        (int(m), lo, hi, int(c), 0, 0, MAV_SENSOR_ROTATION_PITCH_270, 0)
        for m, c in zip(ms[keep], cm[keep])
    ]
    rng_rows = [(float(c) / 100.0, 0.0) for c in cm[keep]]
    return t_us[keep], ds, rng_rows


def _gimbal(sc: Scenario, motion: Motion, clock: Clock, t_us, ms, rng):
    """``(encode_name, rows)`` of the camera-attitude message: what the autopilot reports (see
    :meth:`Motion.reported_gimbal`; a stabilised gimbal's levelling error, :func:`~sim_fixtures.sensors.levelled`),
    with yaw relative to the vehicle or to North (the autopilot's heading + the relative yaw) as the flags say."""
    tau = clock.tau_of_us(t_us)
    att_noise = np.radians(sc.telemetry.attitude_noise_deg)
    g = levelled(sc, motion.reported_gimbal(tau)) + rng.normal(0.0, 1.0, (len(tau), 3)) * att_noise
    # the autopilot's heading
    vehicle_yaw = motion.uav_rpy(tau)[:, 2] + ahrs_error_rpy(sc, tau)[:, 2]
    yaw_abs = g[:, 2] + vehicle_yaw
    if sc.mount.attitude_source == "mount_orientation":
        return "mount_orientation", [
            (int(m), *np.degrees([r, p, wrap_pi(yr)]), float(np.degrees(ya) % 360))
            for m, r, p, yr, ya in zip(ms, g[:, 0], g[:, 1], g[:, 2], yaw_abs)
        ]
    earth = sc.mount.gimbal_frame == "earth"
    flags = (
        GIMBAL_DEVICE_FLAGS_ROLL_LOCK
        | GIMBAL_DEVICE_FLAGS_PITCH_LOCK
        | (
            GIMBAL_DEVICE_FLAGS_YAW_IN_EARTH_FRAME
            if earth
            else GIMBAL_DEVICE_FLAGS_YAW_IN_VEHICLE_FRAME
        )
    )
    q = quat_wxyz(rotation_zyx(g[:, 0], g[:, 1], yaw_abs if earth else g[:, 2]))
    nan = float("nan")
    # as ArduPilot: sent by the autopilot for gimbal device 1, angular velocities and delta_yaw unknown
    return "gimbal_device_attitude_status", [
        (0, 0, int(m), flags, [float(x) for x in qq], nan, nan, nan, 0, nan, nan, 1)
        for m, qq in zip(ms, q)
    ]


def _timesync(sc: Scenario, clock: Clock, tau0: float, tau1: float, rng):
    """The autopilot's TIMESYNC replies as ``(true_us, (tc1, ts1))``, stamped when each request arrived."""
    period = 1.0 / sc.telemetry.timesync_hz
    tau = np.arange(tau0 + rng.uniform(0.0, period), tau1, period)
    sent = clock.true_us(tau)
    arrived = sent + np.round(
        (sc.link.delay_s + exponential(rng, sc.link.jitter_s, len(tau))) * 1e6
    ).astype(np.int64)
    up = clock.up(arrived)
    tc1 = (arrived - clock.epoch_us(arrived)) * 1000  # the autopilot's boot time in ns
    ts1 = clock.station_us(sent) * 1000  # the request's station-clock send time in ns, echoed
    return [(int(a), (int(c), int(s))) for a, c, s, ok in zip(arrived, tc1, ts1, up) if ok]


def _messages(sc: Scenario, motion: Motion, clock: Clock):
    """Every message as ``(sample_true_us, encode_name, args)`` in no particular order."""
    mav = mavutil().mavlink
    tel = sc.telemetry
    tau0, tau1 = -tel.lead_s, sc.duration_s + 1.0
    out = []

    def add(t_us, name, rows):
        out.extend((int(t), name, args) for t, args in zip(t_us, rows))

    t, _ = sample_times(clock, 1.0, tau0, tau1, stream(sc, "heartbeat"))
    armed = mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | mav.MAV_MODE_FLAG_SAFETY_ARMED
    disarmed = mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    loiter = 5  # ArduCopter's LOITER flight mode
    arm_at = sc.uav.armed_at_s
    add(
        t,
        "heartbeat",
        [
            (
                mav.MAV_TYPE_QUADROTOR,
                mav.MAV_AUTOPILOT_ARDUPILOTMEGA,
                armed,
                loiter,
                mav.MAV_STATE_ACTIVE,
            )
            if arm_at is None or tau >= arm_at
            else (
                mav.MAV_TYPE_QUADROTOR,
                mav.MAV_AUTOPILOT_ARDUPILOTMEGA,
                disarmed,
                loiter,
                mav.MAV_STATE_STANDBY,
            )
            for tau in clock.tau_of_us(t)
        ],
    )
    if tel.system_time_hz > 0:
        t, ms = sample_times(clock, tel.system_time_hz, tau0, tau1, stream(sc, "system_time"))
        add(t, "system_time", [(int(tu), int(m)) for tu, m in zip(t, ms)])

    rng = stream(sc, "attitude")
    t, ms = sample_times(clock, tel.attitude_hz, tau0, tau1, rng)
    tau = clock.tau_of_us(t)
    rpy = (
        motion.uav_rpy(tau)
        + ahrs_error_rpy(sc, tau)
        + rng.normal(0.0, 1.0, (len(t), 3)) * np.radians(tel.attitude_noise_deg)
    )
    rpy[:, 2] = wrap_pi(rpy[:, 2])
    rates = motion.body_rates(tau)
    add(
        t, "attitude", [(int(m), *map(float, a), *map(float, r)) for m, a, r in zip(ms, rpy, rates)]
    )

    rng = stream(sc, "position")
    t, ms = sample_times(clock, tel.position_hz, tau0, tau1, rng)
    tau = clock.tau_of_us(t)
    ned = motion.uav_ned(tau)
    vel = motion.uav_velocity_ned(tau)
    s = sc.site
    error_ne = position_error_ne_m(sc, tau) + position_white_ne_m(sc, "ekf", len(t))
    lat, lon, alt = ned_to_geodetic(
        ned_with_error(ned, error_ne), s.lat_deg, s.lon_deg, s.surface_amsl_m
    )
    baro = baro_error_m(sc, tau) + baro_noise_m(sc, len(t))
    alt = alt + rng.normal(0.0, 1.0, len(t)) * tel.height_noise_m + baro
    rel = (
        -ned[:, 2]
        - s.takeoff_height_above_surface_m
        + rng.normal(0.0, 1.0, len(t)) * tel.height_noise_m
        + baro
    )
    heading = motion.uav_rpy(tau)[:, 2] + ahrs_error_rpy(sc, tau)[:, 2]
    hdg = np.round(np.degrees(heading) % 360 * 100).astype(int) % 36000
    add(
        t,
        "global_position_int",
        [
            (
                int(m),
                round(la * 1e7),
                round(lo * 1e7),
                round(a * 1000),
                round(r * 1000),
                round(v[0] * 100),
                round(v[1] * 100),
                round(v[2] * 100),
                int(h),
            )
            for m, la, lo, a, r, v, h in zip(ms, lat, lon, alt, rel, vel, hdg)
        ],
    )

    if tel.gps_raw_hz > 0:
        rng = stream(sc, "gps_raw")
        t, ms = sample_times(clock, tel.gps_raw_hz, tau0, tau1, rng)
        add(t, "gps_raw_int", _gps_raw(sc, motion, clock, t, ms, rng))

    if sc.rangefinder.enabled:
        rng = stream(sc, "rangefinder")
        t, ms = sample_times(clock, sc.rangefinder.rate_hz, tau0, tau1, rng)
        t, ds, rf = _rangefinder(sc, motion, clock, t, ms, rng)
        add(t, "distance_sensor", ds)
        add(t, "rangefinder", rf)

    if sc.mount.attitude_source != "fixed":
        rng = stream(sc, "gimbal")
        t, ms = sample_times(clock, tel.gimbal_hz, tau0, tau1, rng)
        name, rows = _gimbal(sc, motion, clock, t, ms, rng)
        add(t, name, rows)

    if tel.timesync_hz > 0:
        replies = _timesync(sc, clock, tau0, tau1, stream(sc, "timesync"))
        add([a for a, _ in replies], "timesync", [args for _, args in replies])

    if sc.mount.kind == "servo":
        t = clock.true_us([tau0 + 0.3])
        if clock.up(t)[
            0
        ]:  # ArduPilot answers PARAM_REQUEST_READ by name: index -1, value cast to float
            add(
                t,
                "param_value",
                [(b"MNT1_TYPE", 1.0, mav.MAV_PARAM_TYPE_INT8, GCS_PARAM_COUNT, 65535)],
            )
    return out


def write_tlog(
    path: Path, sc: Scenario, motion: Motion, clock: Clock, others: list[tuple[int, bytes]] = ()
) -> dict[str, int]:
    """Write ``uav.tlog``; returns the number of the UAV's messages of each type. ``others``: records
    ``(station µs, MAVLink frame)`` of other systems the station heard (a buoy's), merged in by time."""
    mav = mavutil().mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    msgs = sorted(_messages(sc, motion, clock), key=lambda m: m[0])  # stable: ties keep their order
    send_us = np.array([m[0] for m in msgs], dtype=np.int64) + SEND_LATENCY_US
    extra = exponential(stream(sc, "downlink"), sc.link.jitter_s, len(msgs))
    recv_us = np.maximum.accumulate(
        send_us + np.round((sc.link.delay_s + extra) * 1e6).astype(np.int64)
    )
    counts: dict[str, int] = {}
    records = []
    for (_, name, args), t_us in zip(msgs, clock.station_us(recv_us)):
        msg = getattr(mav, name + "_encode")(*args)
        records.append((int(t_us), msg.pack(mav)))
        counts[msg.get_type()] = counts.get(msg.get_type(), 0) + 1
    with open(path, "wb") as f:
        for t_us, frame in sorted([*records, *others], key=lambda r: r[0]):
            f.write(tlog_record(t_us, frame))
    return counts

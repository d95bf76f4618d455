"""pymavlink set up for MAVLink 2, and MAVLink messages fed into the localizer's telemetry.

The one place where MAVLink units become the localizer's: ATTITUDE radians and
rad/s (FRD body in NED) as they are; GLOBAL_POSITION_INT degE7 → degrees, mm →
metres, cm/s → m/s; GIMBAL_DEVICE_ATTITUDE_STATUS quaternion (w, x, y, z) and
flags as they are; MOUNT_ORIENTATION degrees; GPS_RAW_INT mm → metres, eph/epv
(DOP × 100) → DOP; DISTANCE_SENSOR cm → metres, covariance cm² → a 1-sigma in
metres; RANGEFINDER metres; HEARTBEAT ``base_mode`` → armed; TIMESYNC ns. Samples
keep the autopilot's ``time_boot_ms``; the telemetry maps it onto the station clock
with the receive times. The UUV autopilot's (ArduSub's) depth messages
(:func:`ingest_ardusub`): GLOBAL_POSITION_INT mm → metres, cm/s → m/s; SCALED_PRESSURE{,2,3}
hPa → Pa; GPS_GLOBAL_ORIGIN mm → metres; PARAM_VALUE as it is.
"""

from __future__ import annotations

import os

# must precede pymavlink's import (in mavutil()) to parse MAVLink 2
os.environ.setdefault("MAVLINK20", "1")

import math
from collections.abc import Mapping

from groundstation.mavlink.ids import is_autopilot_heartbeat
from localizer.depth import PRESSURE_MESSAGES, ArduSubDepth, DepthSample
from localizer.telemetry import Telemetry

#: Message types the localizer uses (and the autopilot's HEARTBEAT: whether it is armed).
USED = (
    "ATTITUDE",
    "GLOBAL_POSITION_INT",
    "SYSTEM_TIME",
    "GIMBAL_DEVICE_ATTITUDE_STATUS",
    "MOUNT_ORIENTATION",
    "GPS_RAW_INT",
    "TIMESYNC",
    "PARAM_VALUE",
    "DISTANCE_SENSOR",
    "RANGEFINDER",
)
GIMBAL_MESSAGES = ("GIMBAL_DEVICE_ATTITUDE_STATUS", "MOUNT_ORIENTATION")
RANGEFINDER_MESSAGES = ("DISTANCE_SENSOR", "RANGEFINDER")
#: Message types the UUV's autopilot reader uses: its depth, its thrusters' outputs (COMMAND_ACK: the answers to its
#: rate requests).
ARDUSUB_USED = (
    "GLOBAL_POSITION_INT",
    *PRESSURE_MESSAGES,
    "PARAM_VALUE",
    "GPS_GLOBAL_ORIGIN",
    "SERVO_OUTPUT_RAW",
    "COMMAND_ACK",
)
MAV_MODE_FLAG_SAFETY_ARMED = 128
MAV_SENSOR_ROTATION_PITCH_270 = 25  # DISTANCE_SENSOR orientation: looking down the body's z axis
SIGNAL_QUALITY_INVALID = 1  # DISTANCE_SENSOR signal_quality: 0 unknown, 1 invalid, 2..100
COVARIANCE_UNKNOWN = (
    0,
    255,
)  # DISTANCE_SENSOR covariance (cm²): 0 (ArduPilot) or UINT8_MAX: not given
DOP_UNKNOWN = 65535


def mavutil():
    """pymavlink's ``mavutil`` module, imported with MAVLink 2 enabled; imported on first use (it is slow to load)."""
    from pymavlink import mavutil

    return mavutil


class LinkError(OSError):
    """A MAVLink link that cannot be opened; the message is one line naming the connection string."""


def connect(url: str, **kwargs):
    """``mavutil.mavlink_connection(url, **kwargs)``, with any failure as one :class:`LinkError` line."""
    try:
        return mavutil().mavlink_connection(url, **kwargs)
    except Exception as e:  # noqa: BLE001 - pymavlink fails with ValueError, OSError, serial errors, ...
        raise LinkError(f"MAVLink {url!r}: cannot open: {e}") from None


def names_the_uav(msg) -> bool:
    """Whether ``msg`` makes its system the UAV while none is known: an autopilot's HEARTBEAT or a message the
    localizer uses (:data:`USED`). The one rule, live (pymavlink and MAVSDK) and in a tlog."""
    return is_autopilot_heartbeat(msg) or msg.get_type() in USED


def uav_system(msgs) -> int | None:
    """The UAV's system id in a whole recording ``msgs`` (in order): that of the first ATTITUDE, else of the first
    message that :func:`names_the_uav`.

    A recording has every message at once, so a buoy's or boat's GPS_RAW_INT heard before the drone's first message
    (its own system, reporting a reference's position) does not make it the UAV: only a system that reports an
    attitude is taken while one does.
    """
    msgs = list(msgs)
    attitude = next((m.get_srcSystem() for m in msgs if m.get_type() == "ATTITUDE"), None)
    if attitude is not None:
        return attitude
    return next((m.get_srcSystem() for m in msgs if names_the_uav(m)), None)


def ingest(tel: Telemetry, msg, receive_unix_s: float) -> bool:
    """Feed one decoded pymavlink message of the UAV's system into ``tel``; True if it was used.

    The autopilot is the component whose HEARTBEAT names an autopilot, or that sends
    ATTITUDE first: its clock is the buffers' clock, and its copies alone of
    ATTITUDE, GLOBAL_POSITION_INT, SYSTEM_TIME, GPS_RAW_INT, TIMESYNC, PARAM_VALUE,
    its downward rangefinder (DISTANCE_SENSOR, else ArduPilot's RANGEFINDER) and its
    HEARTBEAT's armed flag are used (before it is known, nothing else is). A gimbal message
    from another component (a MAVLink gimbal with its own ``time_boot_ms``) is
    aligned by its own clock. Samples with values outside their physical range,
    non-finite values or times out of order are refused by the telemetry store
    (the reason in ``tel.refusal``, None for a message that was merely not used),
    and only samples that pass reach the clocks.
    """
    kind = msg.get_type()
    component = msg.get_srcComponent()
    tel.refusal = None
    autopilot_beat = is_autopilot_heartbeat(msg)
    if tel.autopilot_component is None and (kind == "ATTITUDE" or autopilot_beat):
        tel.autopilot_component = component
    if autopilot_beat and component == tel.autopilot_component:
        tel.add_heartbeat(bool(msg.base_mode & MAV_MODE_FLAG_SAFETY_ARMED), receive_unix_s)
        return False
    if kind not in USED:
        return False
    if tel.autopilot_component is None:
        return False  # not refused: which component is the autopilot is not known yet
    own = component == tel.autopilot_component
    if kind in GIMBAL_MESSAGES:
        other = None if own else component
        if kind == "MOUNT_ORIENTATION":
            return tel.add_mount(
                msg.time_boot_ms, msg.roll, msg.pitch, msg.yaw, receive_unix_s, other
            )
        return tel.add_gimbal(msg.time_boot_ms, msg.q, msg.flags, receive_unix_s, other)
    if not own:
        if kind in RANGEFINDER_MESSAGES:  # another component's sensor, on its own clock: not used
            return False
        tel.refusal = f"from component {component}, not the autopilot ({tel.autopilot_component})"
        return False
    if kind == "ATTITUDE":
        return tel.add_attitude(
            msg.time_boot_ms,
            msg.roll,
            msg.pitch,
            msg.yaw,
            (msg.rollspeed, msg.pitchspeed, msg.yawspeed),
            receive_unix_s,
        )
    if kind == "GLOBAL_POSITION_INT":
        return tel.add_position(
            msg.time_boot_ms,
            msg.lat / 1e7,
            msg.lon / 1e7,
            msg.alt / 1000.0,
            msg.relative_alt / 1000.0,
            (msg.vx / 100.0, msg.vy / 100.0, msg.vz / 100.0),
            receive_unix_s,
        )
    if kind == "SYSTEM_TIME":
        return tel.add_system_time(msg.time_boot_ms, msg.time_unix_usec, receive_unix_s)
    if kind == "TIMESYNC":  # the autopilot's own requests (tc1 = 0) need nothing from us
        return msg.tc1 == 0 or tel.add_timesync(msg.tc1, msg.ts1, receive_unix_s)
    if kind == "GPS_RAW_INT":
        # MAVLink 2 extensions: 0 when not sent
        alt_ellipsoid_mm = getattr(msg, "alt_ellipsoid", 0) or 0
        geoid = (alt_ellipsoid_mm - msg.alt) / 1000.0 if alt_ellipsoid_mm else float("nan")

        def dop(x):
            return x / 100.0 if x != DOP_UNKNOWN else float("nan")

        return tel.add_gps_raw(
            msg.time_usec,
            msg.fix_type,
            msg.alt / 1000.0,
            (getattr(msg, "h_acc", 0) or 0) / 1000.0,
            (getattr(msg, "v_acc", 0) or 0) / 1000.0,
            dop(msg.eph),
            dop(msg.epv),
            geoid,
            receive_unix_s,
        )
    if kind == "DISTANCE_SENSOR":  # a downward one; the others look elsewhere
        if msg.orientation != MAV_SENSOR_ROTATION_PITCH_270:
            return False
        tel.distance_sensor_seen = True
        if (getattr(msg, "signal_quality", 0) or 0) == SIGNAL_QUALITY_INVALID:
            tel.rangefinder_out_of_range += 1
            return False
        sigma = None if msg.covariance in COVARIANCE_UNKNOWN else msg.covariance**0.5 / 100.0
        return tel.add_rangefinder(
            msg.time_boot_ms,
            msg.current_distance / 100.0,
            msg.min_distance / 100.0,
            msg.max_distance / 100.0,
            receive_unix_s,
            sigma,
        )
    if (
        kind == "RANGEFINDER"
    ):  # ArduPilot's copy of its downward rangefinder: used only without DISTANCE_SENSOR
        if tel.distance_sensor_seen:
            return False
        return tel.add_rangefinder(None, msg.distance, 0.0, float("inf"), receive_unix_s)
    tel.add_param(param_name(msg.param_id), float(msg.param_value))
    return True


class BadMessage(ValueError):
    """A message whose fields cannot be used; the text names the field and its value."""


def _number(kind: str, fields: Mapping, name: str) -> float:
    value = fields.get(name)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise BadMessage(f"{kind}.{name} = {value!r}: not a finite number")
    return float(value)


def param_name(value) -> str:
    """A PARAM_VALUE's ``param_id`` as text: pymavlink's str or bytes, mavlink-server's string (or, from older
    versions, a list of single characters), without the trailing NULs."""
    if isinstance(value, bytes):
        value = value.decode(errors="replace")
    elif isinstance(value, list) and all(isinstance(c, str) for c in value):
        value = "".join(value)
    if not isinstance(value, str):
        raise BadMessage(f"PARAM_VALUE.param_id = {value!r}: not a name")
    return value.split("\x00", 1)[0]


def servo_pulses_us(fields: Mapping) -> dict[int, int]:
    """SERVO_OUTPUT_RAW's pulses (µs) by output channel, 1–16 (9–16 are MAVLink 2 extensions: missing or 0 when a
    channel is not output); :class:`BadMessage` for one that is not a whole number of microseconds."""
    out = {}
    for n in range(1, 17):
        value = fields.get(f"servo{n}_raw", 0)
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 65535:
            raise BadMessage(f"SERVO_OUTPUT_RAW.servo{n}_raw = {value!r}: not a pulse in µs")
        out[n] = value
    return out


def ingest_ardusub(
    depth: ArduSubDepth, kind: str, fields: Mapping, receive_unix_s: float
) -> DepthSample | None:
    """One message of the UUV's autopilot (its fields: pymavlink's ``to_dict()`` or mavlink-server's JSON
    ``message``) into ``depth``; the depth sample it makes, if any. :class:`BadMessage` for a field that is not
    a finite number (one line naming it)."""
    if kind == "GLOBAL_POSITION_INT":
        return depth.position(
            _number(kind, fields, "time_boot_ms"),
            _number(kind, fields, "relative_alt") / 1000.0,
            _number(kind, fields, "alt") / 1000.0,
            _number(kind, fields, "vz") / 100.0,
            receive_unix_s,
        )
    if kind in PRESSURE_MESSAGES:
        return depth.scaled_pressure(
            PRESSURE_MESSAGES.index(kind),
            _number(kind, fields, "time_boot_ms"),
            _number(kind, fields, "press_abs") * 100.0,
            receive_unix_s,
        )
    if kind == "PARAM_VALUE":
        depth.param(param_name(fields.get("param_id")), _number(kind, fields, "param_value"))
    elif kind == "GPS_GLOBAL_ORIGIN":
        depth.origin(_number(kind, fields, "altitude") / 1000.0)
    return None

"""pymavlink set up for MAVLink 2, and MAVLink messages fed into the localizer's telemetry.

The one place where MAVLink units become the localizer's: ATTITUDE radians (FRD
body in NED) as they are; GLOBAL_POSITION_INT degE7 → degrees and mm → metres;
GIMBAL_DEVICE_ATTITUDE_STATUS quaternion (w, x, y, z) and flags as they are;
MOUNT_ORIENTATION degrees. All samples keep the autopilot's ``time_boot_ms``.
"""

from __future__ import annotations

import os

os.environ.setdefault("MAVLINK20", "1")  # must precede pymavlink's import to parse MAVLink 2

from pymavlink import mavutil as _mavutil

from localizer.telemetry import Telemetry

#: Message types the localizer uses.
USED = ("ATTITUDE", "GLOBAL_POSITION_INT", "SYSTEM_TIME", "GIMBAL_DEVICE_ATTITUDE_STATUS", "MOUNT_ORIENTATION")


def mavutil():
    """pymavlink's ``mavutil`` module, imported with MAVLink 2 enabled."""
    return _mavutil


class LinkError(OSError):
    """A MAVLink link that cannot be opened; the message is one line naming the connection string."""


def connect(url: str, **kwargs):
    """``mavutil.mavlink_connection(url, **kwargs)``, with any failure as one :class:`LinkError` line."""
    try:
        return _mavutil.mavlink_connection(url, **kwargs)
    except Exception as e:  # noqa: BLE001 - pymavlink fails with ValueError, OSError, serial errors, ...
        raise LinkError(f"MAVLink {url!r}: cannot open: {e}") from None


def ingest(tel: Telemetry, msg, receive_unix_s: float) -> bool:
    """Feed one decoded pymavlink message of the UAV's system into ``tel``; True if it was used.

    The component that sends ATTITUDE first is the autopilot: its clock is the
    buffers' clock, and its copies alone of ATTITUDE, GLOBAL_POSITION_INT and
    SYSTEM_TIME are used. A gimbal message from another component (a MAVLink
    gimbal with its own ``time_boot_ms``) is moved onto the autopilot's clock.
    Samples with values outside their physical range, non-finite values or times
    out of order are refused by the telemetry store (and counted there), and only
    samples that pass reach the clock, so a garbage frame cannot fake a reboot.
    """
    kind = msg.get_type()
    if kind not in USED:
        return False
    boot_ms = msg.time_boot_ms
    component = msg.get_srcComponent()
    if tel.autopilot_component is None and kind == "ATTITUDE":
        tel.autopilot_component = component
    own_clock = tel.autopilot_component in (None, component)
    if not own_clock:
        if kind not in ("GIMBAL_DEVICE_ATTITUDE_STATUS", "MOUNT_ORIENTATION"):
            return False  # another component's ATTITUDE, position or time: not the autopilot's clock
        boot_ms = tel.to_autopilot_boot_ms(component, boot_ms, receive_unix_s)
        if boot_ms is None:
            return False
    recv = receive_unix_s if own_clock else None
    if kind == "ATTITUDE":
        return tel.add_attitude(boot_ms, msg.roll, msg.pitch, msg.yaw, receive_unix_s=recv)
    if kind == "GLOBAL_POSITION_INT":
        return tel.add_position(boot_ms, msg.lat / 1e7, msg.lon / 1e7, msg.alt / 1000.0, msg.relative_alt / 1000.0,
                                receive_unix_s=recv)
    if kind == "SYSTEM_TIME":
        tel.clock.add_receive(boot_ms, receive_unix_s)
        tel.clock.add_system_time(boot_ms, msg.time_unix_usec)
        return True
    if kind == "GIMBAL_DEVICE_ATTITUDE_STATUS":
        return tel.add_gimbal(boot_ms, msg.q, msg.flags, receive_unix_s=recv)
    return tel.add_mount(boot_ms, msg.roll, msg.pitch, msg.yaw, receive_unix_s=recv)

"""The output ``gps_input``: MAVLink GPS_INPUT to the UUV's autopilot on its ``gps_input`` link, through the UUV's
safety gates (:class:`~groundstation.runtime.gps_input.GpsInputSink`); nothing when the UUV has none."""

from __future__ import annotations

from groundstation.mavlink.link import read_signing_key
from groundstation.runtime.gps_input import GpsInputSink, mavlink_gps_link
from groundstation.runtime.parts import OutputInput, register
from groundstation.runtime.zenoh_mavlink import ZenohMavlinkIn

ZENOH = "zenoh:"  # gps_input's prefix of a Zenoh key (BlueOS's mavlink-server)


@register(
    "output",
    "gps_input",
    "MAVLink GPS_INPUT to the UUV's autopilot on --gps-input (none: nothing)",
    section="gps_input",
)
def build(out: OutputInput) -> GpsInputSink | None:
    u = out.options
    if not u.gps_input:
        return None
    if u.gps_input.startswith(ZENOH):
        link = ZenohMavlinkIn(out.session, u.gps_input.removeprefix(ZENOH))
    else:
        key = read_signing_key(u.gps_input_signing_key) if u.gps_input_signing_key else None
        link = mavlink_gps_link(u.gps_input, signing_key=key)
    return GpsInputSink(link, out.run.gps_input_hz, out.run.fix_max_age_ms / 1000.0, out.gate)

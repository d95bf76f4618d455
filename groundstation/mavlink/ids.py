"""Who is who on a MAVLink link: skyfix's own ids, and what an autopilot's HEARTBEAT looks like (the one rule
for which system is the UAV is :func:`groundstation.mavlink.ingest.names_the_uav`).

skyfix is system :data:`SKYFIX_SYSID` (not 255, so it does not clash with QGroundControl on the same
link): component :data:`GCS_COMPID` as a ground station on the UAV's and the UUV's links, component
:data:`GPS_COMPID` as the GPS that sends GPS_INPUT.
"""

from __future__ import annotations

SKYFIX_SYSID = 245
GCS_COMPID = 190  # MAV_COMP_ID_MISSIONPLANNER: a ground station
GPS_COMPID = 220  # MAV_COMP_ID_GPS
MAV_AUTOPILOT_INVALID = 8
NOT_AUTOPILOTS = (6, 18, 26, 30)  # MAV_TYPE GCS, ONBOARD_CONTROLLER, GIMBAL, CAMERA


def is_autopilot_heartbeat(msg) -> bool:
    """A HEARTBEAT that names an autopilot (not a ground station, companion computer, gimbal or camera)."""
    return (
        msg.get_type() == "HEARTBEAT"
        and getattr(msg, "autopilot", MAV_AUTOPILOT_INVALID) != MAV_AUTOPILOT_INVALID
        and getattr(msg, "type", None) not in NOT_AUTOPILOTS
    )

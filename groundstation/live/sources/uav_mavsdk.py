"""The UAV's telemetry through MAVSDK-Python 4 (``--mavlink-backend mavsdk``).

The same messages as the pymavlink backend (:data:`groundstation.mavlink.ingest.USED`),
read raw through MAVSDK's MavlinkDirect plugin, so that their ``time_boot_ms``
reaches the telemetry unchanged (MAVSDK's Telemetry plugin drops it for
positions) and both backends yield the same samples; each message is fed through
:func:`groundstation.mavlink.ingest.ingest`. MAVSDK heartbeats as a ground station by
itself. Messages flow once MAVSDK has seen the UAV's autopilot heartbeat. This
backend only listens: it sends no TIMESYNC and no rate or parameter requests
(the pymavlink backend does), so set ``[timing] mavlink_latency_s`` and
``[mount] gimbal_roll_pitch`` with it.

Connection strings: MAVSDK's own (``udpin://0.0.0.0:14550``,
``serial:///dev/ttyUSB0:57600``) or pymavlink's ``udpin:``, ``udpout:``,
``tcp:`` forms, translated. Recording (``--record``) needs the raw frames, which
MAVSDK does not give: it requires the pymavlink backend.
"""

from __future__ import annotations

import asyncio
import json
import logging
import time
from collections.abc import Callable

from groundstation.live.registry import UavInput, register
from groundstation.live.sources.uav_mavlink import LinkHealth, clock_status, gnss_status
from groundstation.mavlink.ingest import USED, ingest, names_the_uav
from localizer.telemetry import Telemetry

log = logging.getLogger("skyfix.uav")

_SCHEMES = {
    "udpin:": "udpin://",
    "udpout:": "udpout://",
    "udp:": "udpin://",
    "tcp:": "tcpout://",
    "tcpin:": "tcpin://",
}


def mavsdk_url(url: str) -> str:
    """MAVSDK's connection URL for a pymavlink-style string (MAVSDK URLs pass through)."""
    if "://" in url:
        return url
    for prefix, scheme in _SCHEMES.items():
        if url.startswith(prefix):
            return scheme + url[len(prefix) :]
    if url.startswith("/dev/"):
        return f"serial://{url}:57600" if ":" not in url else f"serial://{url}"
    raise ValueError(f"--mavlink {url!r}: not a connection string MAVSDK understands")


class DirectMessage:
    """A MavlinkDirect message with the attributes of a pymavlink message that ``ingest`` reads."""

    def __init__(self, m):
        self._type = m.message_name
        self._sysid = m.system_id
        self._compid = m.component_id
        self.__dict__.update(json.loads(m.fields_json))

    def get_type(self) -> str:
        return self._type

    def get_srcSystem(self) -> int:
        return self._sysid

    def get_srcComponent(self) -> int:
        return self._compid


class UavMavsdk:
    """Worker owning the UAV's MAVLink through MAVSDK; same interface as :class:`~.uav_mavlink.UavMavlink`."""

    def __init__(self, url: str, tel: Telemetry, listeners: list[Callable] | None = None):
        self.url = mavsdk_url(url)
        self.tel = tel
        self.listeners = listeners or []
        self.health = LinkHealth()
        self.uav_sysid: int | None = None

    async def run(self) -> None:
        from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
        from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync

        async with Mavsdk(
            Configuration.create_with_component_type(ComponentType.GROUND_STATION)
        ) as drone:
            await drone.add_any_connection(self.url)
            system = None
            while system is None:
                system = await drone.first_autopilot(timeout_s=1.0)
            direct = MavlinkDirectAsync(system)
            async with asyncio.TaskGroup() as tg:
                for name in (*USED, "HEARTBEAT"):  # the autopilot's HEARTBEAT: whether it is armed
                    tg.create_task(self._follow(direct, name))

    async def _follow(self, direct, name: str) -> None:
        async for m in direct.subscribe_message(name):
            self._on_message(DirectMessage(m), time.time())

    def _on_message(self, msg: DirectMessage, t_recv: float) -> None:
        if self.uav_sysid is None and names_the_uav(msg):
            self.uav_sysid = msg.get_srcSystem()
            log.info("UAV MAVLink (MAVSDK): using system %d on %s", self.uav_sysid, self.url)
        if msg.get_srcSystem() != self.uav_sysid:
            self.health.other_systems += 1
            return
        kind = msg.get_type()
        self.health.seen(kind, t_recv)
        try:
            used = ingest(self.tel, msg, t_recv)
        except (AttributeError, TypeError, ValueError) as e:
            log.warning("UAV MAVLink (MAVSDK): %s refused: %s", kind, e)
            used = False
        if not used and self.tel.refusal:
            self.health.refused += 1
        for listener in self.listeners:
            listener(msg, t_recv)

    def status(self, now: float) -> dict:
        return {
            "url": self.url,
            "backend": "mavsdk",
            "sysid": self.uav_sysid,
            "clocks": clock_status(self.tel),
            "gnss": gnss_status(self.tel),
            **self.health.as_dict(now),
        }


@register("uav", "mavsdk", "MAVSDK-Python (the mavsdk extra)", needs=("mavsdk", "skyfix[mavsdk]"))
def build(uav: UavInput) -> UavMavsdk:
    return UavMavsdk(uav.cfg.mavlink, uav.tel)

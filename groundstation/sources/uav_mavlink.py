"""The UAV's telemetry over pymavlink, live.

A reader thread blocks in ``recv_match`` and hands every message, with its
receive time (UNIX seconds), to the event loop, where it is fed into the
:class:`~localizer.telemetry.Telemetry` (only the loop touches the telemetry).
The service heartbeats as a ground station (``MAV_TYPE_GCS``) at 1 Hz as
system ``GCS_SYSID`` / component ``GCS_COMPID`` (not 255, so it does not clash
with QGroundControl on the same link). Only the UAV's messages are used: the
system id of the first autopilot heartbeat or used message; others are counted.
Malformed frames (pymavlink's BAD_DATA) are counted and logged, never fatal.
"""

from __future__ import annotations

import asyncio
import logging
import threading
import time
from collections.abc import Callable

from localizer.telemetry import Telemetry

from ..logs import Throttle
from ..mavlink_io import USED, connect, ingest, mavutil

log = logging.getLogger("skyfix.uav")

GCS_SYSID = 245
GCS_COMPID = 190  # MAV_COMP_ID_MISSIONPLANNER: a ground station


class LinkHealth:
    """Receive time of the newest message of each type and error counters."""

    def __init__(self):
        self.last_seen: dict[str, float] = {}
        self.received = 0
        self.bad_data = 0
        self.other_systems = 0
        self.refused = 0

    def ages_s(self, now: float) -> dict[str, float]:
        return {k: round(now - t, 3) for k, t in sorted(self.last_seen.items())}

    def as_dict(self, now: float) -> dict:
        return {"received": self.received, "bad_data": self.bad_data, "other_systems": self.other_systems,
                "refused": self.refused, "age_s": self.ages_s(now)}


class UavMavlink:
    """Worker owning the UAV's MAVLink link; ``listeners`` get ``(msg, t_recv_unix)`` for every good message."""

    def __init__(self, url: str, tel: Telemetry, listeners: list[Callable] | None = None):
        self.url = url
        self.tel = tel
        self.listeners = listeners or []
        self.health = LinkHealth()
        self.uav_sysid: int | None = None
        self._throttle = Throttle()
        self._stop = threading.Event()

    async def run(self) -> None:
        loop = asyncio.get_running_loop()
        mav = mavutil()
        conn = await asyncio.to_thread(
            connect, self.url, source_system=GCS_SYSID, source_component=GCS_COMPID,
            autoreconnect=True,
        )
        reader = threading.Thread(target=self._read, args=(conn, loop), name="uav-mavlink", daemon=True)
        reader.start()
        try:
            while True:
                conn.mav.heartbeat_send(mav.mavlink.MAV_TYPE_GCS, mav.mavlink.MAV_AUTOPILOT_INVALID, 0, 0,
                                        mav.mavlink.MAV_STATE_ACTIVE)
                await asyncio.sleep(1.0)
        finally:
            self._stop.set()
            await asyncio.to_thread(reader.join, 2.0)
            conn.close()

    def _read(self, conn, loop: asyncio.AbstractEventLoop) -> None:
        while not self._stop.is_set():
            try:
                msg = conn.recv_match(blocking=True, timeout=0.5)
            except Exception as e:  # noqa: BLE001 - pymavlink raises bare errors on some corrupt input
                loop.call_soon_threadsafe(self._bad, repr(e))
                continue
            if msg is None:
                continue
            t = time.time()
            try:
                loop.call_soon_threadsafe(self._on_message, msg, t)
            except RuntimeError:  # loop closed: shutting down
                return

    def _bad(self, reason: str, data: bytes) -> None:
        self.health.bad_data += 1
        if self._throttle(reason):
            shown = data[:16].hex() + ("…" if len(data) > 16 else "")
            log.warning("UAV MAVLink: malformed frame #%d on %s: %s (bytes %s)", self.health.bad_data, self.url,
                        reason, shown)

    def _is_uav(self, msg) -> bool:
        sysid = msg.get_srcSystem()
        if self.uav_sysid is None:
            kind = msg.get_type()
            autopilot_hb = kind == "HEARTBEAT" and msg.autopilot != mavutil().mavlink.MAV_AUTOPILOT_INVALID
            if autopilot_hb or kind in USED:
                self.uav_sysid = sysid
                log.info("UAV MAVLink: using system %d on %s", sysid, self.url)
        return sysid == self.uav_sysid

    def _on_message(self, msg, t_recv: float) -> None:
        kind = msg.get_type()
        if kind == "BAD_DATA":
            self._bad(getattr(msg, "reason", "bad data"), bytes(getattr(msg, "data", b"")))
            return
        if not self._is_uav(msg):
            self.health.other_systems += 1
            return
        self.health.received += 1
        self.health.last_seen[kind] = t_recv
        try:
            used = ingest(self.tel, msg, t_recv)
        except (AttributeError, TypeError, ValueError) as e:
            log.warning("UAV MAVLink: %s refused: %s: %s", kind, e, msg)
            used = False
        if kind in USED and not used:
            self.health.refused += 1
            n = self._throttle(kind)
            if n:
                log.warning("UAV MAVLink: %s #%d refused (not finite, out of range, out of order or not the "
                            "autopilot's): %s", kind, n, msg)
        for listener in self.listeners:
            listener(msg, t_recv)

    def status(self, now: float) -> dict:
        return {"url": self.url, "sysid": self.uav_sysid, "clock": self.tel.clock.source, **self.health.as_dict(now)}

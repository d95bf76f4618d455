"""The UAV's telemetry over pymavlink, live.

The link (:class:`~groundstation.mavlink.link.MavlinkLink`: its own thread, reconnecting
a TCP or serial link that drops, each UDP datagram parsed on its own) hands every
message, with its receive time (station clock, UNIX seconds), to the event loop
through a bounded :class:`~groundstation.runtime.threads.Handoff` (:data:`HANDOFF_MESSAGES`;
when the loop falls that far behind the oldest are dropped, counted in ``handoff``),
where it is fed into the :class:`~localizer.telemetry.Telemetry` (only the loop
touches the telemetry); what skyfix sends is queued for the link's thread, so the
event loop never blocks on a write. As a ground station (``MAV_TYPE_GCS``, system ``SKYFIX_SYSID`` /
component ``GCS_COMPID``, not 255, so it does not clash with QGroundControl on the
same link) its link heartbeats and the worker, once per second, sends a TIMESYNC request
(the autopilot's replies measure the link's delay); once the autopilot is known
it asks for its ``MNT1_TYPE`` parameter (what the gimbal message's roll and
pitch are relative to) and for the telemetry rates skyfix needs
(:mod:`.rates`, DISTANCE_SENSOR's once a downward one came; ``--no-request-rates``
leaves them alone). Only the UAV's
messages are used: the system id of the first autopilot heartbeat or used
message (never a system in ``not_uav``: a buoy's); others are counted and handed to ``others`` (a buoy's reports:
:mod:`groundstation.live.reference_live`). On ``udpin:`` the link takes datagrams from the UAV's address only (the first to
send its messages, or ``--mavlink-peer``); with ``--mavlink-signing-key`` only messages signed with that key. Malformed frames (pymavlink's BAD_DATA) and refused
samples are counted and logged with their reason, never fatal; so are the
telemetry's notices (reboots, clocks that disagree).
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections.abc import Callable

from groundstation.live.registry import UavInput, register
from groundstation.live.sources.rates import RANGEFINDER_HZ, RateMeter, RateRequests, needed_rates
from groundstation.mavlink.ids import GCS_COMPID, SKYFIX_SYSID
from groundstation.mavlink.ingest import USED, ingest, mavutil, names_the_uav
from groundstation.mavlink.link import MavlinkLink, read_signing_key
from groundstation.runtime.logs import Throttle, kind_of
from groundstation.runtime.threads import Handoff, in_thread
from localizer.gnss import horizontal_sigma_m, vertical_sigma_m
from localizer.telemetry import Telemetry

log = logging.getLogger("skyfix.uav")

PARAM_RETRY_S = 5.0
PARAM_TRIES = 3
HANDOFF_MESSAGES = 2000  # ~10 s of telemetry at the rates skyfix asks for


class LinkHealth:
    """Receive time of the newest message of each type, rates and error counters."""

    def __init__(self):
        self.last_seen: dict[str, float] = {}
        self.meter = RateMeter()
        self.received = 0
        self.bad_data = 0
        self.other_systems = 0
        self.refused = 0

    def seen(self, kind: str, t: float) -> None:
        self.received += 1
        self.last_seen[kind] = t
        self.meter.add(kind, t)

    def ages_s(self, now: float) -> dict[str, float]:
        return {k: round(max(0.0, now - t), 3) for k, t in sorted(self.last_seen.items())}

    def as_dict(self, now: float) -> dict:
        return {
            "received": self.received,
            "bad_data": self.bad_data,
            "other_systems": self.other_systems,
            "refused": self.refused,
            "age_s": self.ages_s(now),
            "rates_hz": self.meter.rates(now),
        }


def clock_status(tel: Telemetry) -> dict:
    """How the telemetry's clocks are aligned, for the status."""
    gnss = tel.station_minus_gnss_s
    uuv = tel.uuv_clock_minus_station_s
    measured = tel.measured_latency_s
    return {
        "station_minus_gnss_s": None if gnss is None else round(gnss, 3),
        "gnss_clock_steps": tel.gnss_clock_steps,
        "uav_link_latency_ms": round(tel.uav_latency_s * 1000.0, 1),
        "uav_link_latency_source": tel.latency_source,
        "uav_link_latency_sigma_ms": round(tel.latency_sigma_s * 1000.0, 1),
        "uav_link_latency_measured_ms": None if measured is None else round(measured * 1000.0, 1),
        "uav_reboots": tel.uav_clock.reboots,
        "uuv_clock_minus_station_s": None if uuv is None else round(uuv, 3),
        "depth_aligned_by": tel.depth_aligned_by,
    }


def gnss_status(tel: Telemetry) -> dict | None:
    """The UAV's GNSS receiver as its newest GPS_RAW_INT says, and the 1-sigmas skyfix takes from it."""
    if not len(tel.gnss):
        return None
    h_acc, _, fix, _, v_acc, hdop, vdop = tel.gnss.values[-1]

    def num(x):
        return round(float(x), 3) if math.isfinite(x) else None

    return {
        "fix_type": int(fix),
        "h_acc_m": num(h_acc),
        "v_acc_m": num(v_acc),
        "hdop": num(hdop),
        "vdop": num(vdop),
        "sigma_horizontal_m": num(horizontal_sigma_m(fix, h_acc, hdop)),
        "sigma_vertical_m": num(vertical_sigma_m(fix, v_acc, vdop)),
    }


class UavMavlink:
    """Worker owning the UAV's MAVLink link; ``listeners`` get ``(msg, t_recv_unix)`` for every good message."""

    def __init__(
        self,
        url: str,
        tel: Telemetry,
        needed_hz: dict[str, float],
        request_rates: bool = True,
        listeners: list[Callable] | None = None,
        peer: str | None = None,
        signing_key: bytes | None = None,
    ):
        self.url = url
        self.tel = tel
        self.listeners = listeners or []
        # get ``(msg, t_recv_unix)`` of every good message of another system (a buoy reporting its GNSS)
        self.others: list[Callable] = []
        self.not_uav: set[int] = set()  # systems never taken for the UAV (a buoy's)
        self.health = LinkHealth()
        self.requests = RateRequests(needed_hz, enabled=request_rates)
        self.uav_sysid: int | None = None
        self.autopilot: tuple[int, int] | None = None  # (system, component) to send requests to
        self._params_asked = 0
        self._params_last = 0.0
        self._throttle = Throttle()
        mav = mavutil().mavlink
        self.link = MavlinkLink(
            url,
            SKYFIX_SYSID,
            GCS_COMPID,
            name="UAV MAVLink",
            is_peer=self._from_uav,
            heartbeat=(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID),
            peer=peer,
            signing_key=signing_key,
            require_signed=signing_key is not None,
        )
        self._low_warned: set[str] = set()
        self.handoff: Handoff | None = None

    async def run(self) -> None:
        self.handoff = Handoff(
            asyncio.get_running_loop(), lambda item: self._on_message(*item), HANDOFF_MESSAGES
        )
        # the link's thread
        self.link.on_message = lambda msg, t_recv: self.handoff.put((msg, t_recv))
        await in_thread(self.link.open, name="UAV MAVLink open")
        try:
            next_beat = 0.0
            while True:
                now = time.time()
                if now >= next_beat:
                    self._beat(self.link, now)
                    next_beat = now + 1.0
                self._ask(self.link, now)
                await asyncio.sleep(0.25)
        finally:
            await in_thread(self.link.close, name="UAV MAVLink close")

    def _from_uav(self, msg) -> bool:
        """Whether a message (on the link's thread) is the UAV's: the link answers where those come from."""
        return (
            msg.get_srcSystem() == self.uav_sysid
            if self.uav_sysid is not None
            else names_the_uav(msg) and msg.get_srcSystem() not in self.not_uav
        )

    def _beat(self, conn, now: float) -> None:
        """Once a second: a TIMESYNC request (ts1: our clock in ns; the link itself heartbeats as a ground station)."""
        conn.mav.timesync_send(0, time.time_ns())
        for kind, hz in self.requests.needed.items():
            rate = self.health.meter.rate_hz(kind, now)
            if self.autopilot and now - (self.requests._since or now) > 15.0 and rate < hz / 2:
                if kind not in self._low_warned:
                    self._low_warned.add(kind)
                    log.warning(
                        "UAV MAVLink: %s arrives at %.1f Hz (%g Hz needed; request: %s)",
                        kind,
                        rate,
                        hz,
                        self.requests.state.get(kind, "none sent"),
                    )
            elif rate >= hz / 2:
                self._low_warned.discard(kind)

    def _ask(self, conn, now: float) -> None:
        """Parameter and rate requests to the autopilot, once it is known."""
        if self.autopilot is None:
            return
        if (
            self.tel.mount_type is None
            and self._params_asked < PARAM_TRIES
            and now - self._params_last >= PARAM_RETRY_S
        ):
            conn.mav.param_request_read_send(*self.autopilot, b"MNT1_TYPE", -1)
            self._params_asked += 1
            self._params_last = now
        for line, kind, fields in self.requests.messages(self.health.meter, now, self.autopilot):
            log.info("UAV MAVLink: %s", line)
            conn.queue(kind, fields)

    def _bad(self, reason: str, data: bytes) -> None:
        self.health.bad_data += 1
        if self._throttle(kind_of(reason)):
            shown = data[:16].hex() + ("…" if len(data) > 16 else "")
            log.warning(
                "UAV MAVLink: malformed frame #%d on %s: %s (bytes %s)",
                self.health.bad_data,
                self.url,
                reason,
                shown,
            )

    def _is_uav(self, msg) -> bool:
        sysid = msg.get_srcSystem()
        if self.uav_sysid is None and names_the_uav(msg) and sysid not in self.not_uav:
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
            for listener in self.others:
                listener(msg, t_recv)
            return
        self.health.seen(kind, t_recv)
        measured_before = self.tel.measured_latency_s
        try:
            used = ingest(self.tel, msg, t_recv)
        except (AttributeError, TypeError, ValueError) as e:
            self.tel.refusal = f"{type(e).__name__}: {e}"
            used = False
        if self.autopilot is None and self.tel.autopilot_component is not None:
            self.autopilot = (msg.get_srcSystem(), self.tel.autopilot_component)
            self.requests.start(t_recv)
        if (
            kind == "DISTANCE_SENSOR"
            and self.tel.distance_sensor_seen
            and kind not in self.requests.needed
        ):
            # the UAV has a downward rangefinder: its rate too
            self.requests.needed[kind] = RANGEFINDER_HZ
        if kind == "COMMAND_ACK" and self.autopilot is not None:
            self.requests.on_ack(msg.command, msg.result)
        if kind in USED and not used and self.tel.refusal:
            self.health.refused += 1
            n = self._throttle(kind_of(f"{kind}: {self.tel.refusal}"))
            if n:
                log.warning("UAV MAVLink: %s #%d refused: %s: %s", kind, n, self.tel.refusal, msg)
        while self.tel.notices:
            log.warning("UAV MAVLink: %s", self.tel.notices.pop(0))
        if measured_before is None and self.tel.measured_latency_s is not None:
            log.info(
                "UAV MAVLink: the link's one-way delay measured with TIMESYNC: %.1f ms%s",
                self.tel.measured_latency_s * 1000.0,
                ""
                if self.tel.latency_source == "timesync"
                else f" (not used: {self.tel.latency_source})",
            )
        for listener in self.listeners:
            listener(msg, t_recv)

    def status(self, now: float) -> dict:
        return {
            "url": self.url,
            "sysid": self.uav_sysid,
            "clocks": clock_status(self.tel),
            "gnss": gnss_status(self.tel),
            "rate_requests": dict(self.requests.state),
            **self.health.as_dict(now),
            "link": self.link.status(now),
            "handoff": self.handoff.status() if self.handoff else None,
        }


@register("uav", "pymavlink", "pymavlink (the default)")
def build(uav: UavInput) -> UavMavlink:
    cfg = uav.cfg
    key = cfg.mavlink_signing_key
    return UavMavlink(
        cfg.mavlink,
        uav.tel,
        needed_rates(uav.cal.mount.attitude_source),
        request_rates=not cfg.no_request_rates,
        peer=cfg.mavlink_peer,
        signing_key=key and read_signing_key(key, "--mavlink-signing-key"),
    )

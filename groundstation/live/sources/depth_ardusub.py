"""The UUV's depth as ArduSub reports it, live: over BlueOS's Zenoh, or over a direct MAVLink link.

What is read and how it becomes a depth is :mod:`localizer.depth` (the depth sensor's pressure with ArduSub's
own parameters and formula, cross-checked against its EKF; never VFR_HUD). The two transports:

- ``--depth-source blueos``: BlueOS's mavlink-server publishes each message of the autopilot as JSON on
  ``mavlink/{system}/{component}/{MESSAGE}``; skyfix subscribes to the messages it uses under the prefix
  ``--depth-key`` (``mavlink/1/1``: ArduSub's system and component; Zenoh's thread does only a bounded
  hand-off). It asks through mavlink-server's ``mavlink/in``, which writes to the autopilot
  on BlueOS's own link: the rates it sets there are that link's, shared by BlueOS's other clients
  (QGroundControl): skyfix only raises one that is below what it needs.
- ``--depth-source mavlink``: a link of skyfix's own (``--depth-mavlink``: ArduSub's spare serial port, a BlueOS
  MAVLink endpoint; :class:`~groundstation.mavlink.link.MavlinkLink`, its own thread, reconnecting) as a ground
  station (system 245, component 190, a HEARTBEAT a second); the autopilot is the first component whose
  HEARTBEAT names an autopilot.

Asked for, as a ground station (245/190), once the autopilot is heard: the parameters ``BARO_PRIMARY``,
``BARO_SPEC_GRAV`` and ``BARO{n}_GND_PRESS`` (PARAM_REQUEST_READ, again every :data:`PARAM_RETRY_S` until
answered; the ground pressure again every :data:`PARAM_REFRESH_S`, in case a recalibration's PARAM_VALUE
was missed), ``GPS_GLOBAL_ORIGIN`` when the EKF has an origin whose altitude is unknown
(MAV_CMD_REQUEST_MESSAGE), and the depth sensor's SCALED_PRESSURE message and GLOBAL_POSITION_INT at
:data:`~groundstation.live.sources.rates.DEPTH_HZ` when they arrive slower (SET_MESSAGE_INTERVAL, falling back to
REQUEST_DATA_STREAM).

The same reader takes the autopilot's thruster outputs (SERVO_OUTPUT_RAW at
:data:`~groundstation.live.sources.rates.THRUSTERS_HZ`, with ``FRAME_CONFIG`` and ``SERVOn_FUNCTION``
asked for as the depth parameters are) into a :class:`~localizer.thrusters.Thrusters` that the fix
gate shares: whether the UUV pushes, a second source of its motion.

Every accepted sample passes :class:`localizer.depth.DepthGate` (a jump faster than the vehicle can dive is
refused with one log line) and goes into the telemetry with its sigma, source word and the vehicle's
vertical speed; ``listeners`` (the recorder) get ``(sample, t_recv)``. A message that does not parse is one
log line naming the field and value, counted; the service keeps running.
"""

from __future__ import annotations

import asyncio
import json
import logging
import re
import time
from collections.abc import Callable

import zenoh

from groundstation.live.registry import DepthInput, register
from groundstation.live.sources.rates import DEPTH_HZ, THRUSTERS_HZ, RateMeter, RateRequests
from groundstation.mavlink.ids import GCS_COMPID, SKYFIX_SYSID, is_autopilot_heartbeat
from groundstation.mavlink.ingest import (
    ARDUSUB_USED,
    BadMessage,
    ingest_ardusub,
    mavutil,
    param_name,
    servo_pulses_us,
)
from groundstation.mavlink.link import MavlinkLink
from groundstation.runtime.logs import Throttle, kind_of
from groundstation.runtime.threads import Handoff, in_thread
from groundstation.runtime.zenoh_mavlink import MavlinkIn
from groundstation.runtime.zenoh_session import subscribe
from localizer.depth import (
    PRESSURE_MESSAGES,
    ArduSubDepth,
    DepthGate,
    DepthSample,
    ground_pressure_param,
)
from localizer.telemetry import Telemetry
from localizer.thrusters import Thrusters

log = logging.getLogger("skyfix.depth")

PARAM_RETRY_S = 3.0
PARAM_REFRESH_S = 30.0
ORIGIN_RETRY_S = 5.0
ASK_PERIOD_S = 0.25
# messages received but not yet taken by the event loop (beyond: oldest dropped, counted)
HANDOFF_MESSAGES = 512
MAV_CMD_REQUEST_MESSAGE = 512
GPS_GLOBAL_ORIGIN_ID = 49
_PREFIX = re.compile(
    r"(?:[^*$?#]+/)?mavlink/(\d+)/(\d+)"
)  # a vehicle's Zenoh namespace may come first


def autopilot_prefix(key: str) -> tuple[int, int]:
    """``(system, component)`` of BlueOS's key prefix ``mavlink/{system}/{component}`` (under a vehicle's Zenoh
    namespace in a fleet: ``rov1/mavlink/1/1``); ValueError saying what to write otherwise (VFR_HUD, a message's
    key, is named: it is not ArduSub's depth)."""
    m = _PREFIX.fullmatch(key.rstrip("/"))
    if m is None:
        if key.rstrip("/").endswith("/VFR_HUD"):
            raise ValueError(
                "VFR_HUD is not ArduSub's depth (it is the EKF's altitude above sea level: 0 before "
                "the EKF has an origin); give the autopilot's key prefix, e.g. mavlink/1/1"
            )
        raise ValueError(
            "expected the autopilot's key prefix mavlink/{system}/{component}, e.g. mavlink/1/1"
        )
    return int(m[1]), int(m[2])


def _enum(value) -> int | None:
    """A MAVLink enum value: a number, or mavlink-server's ``{"type": "NAME"}``."""
    if isinstance(value, dict):
        return getattr(mavutil().mavlink, str(value.get("type")), None)
    return value if isinstance(value, int) and not isinstance(value, bool) else None


class ArduSubReader:
    """The transport-independent part: messages in (on the event loop), samples to the telemetry, requests out."""

    def __init__(
        self,
        tel: Telemetry,
        gate: DepthGate,
        sigma_m: float,
        send: Callable[[str, dict], None],
        listeners: list[Callable] | None = None,
        thrusters: Thrusters | None = None,
    ):
        self.tel = tel
        self.gate = gate
        self.send = send  # (message type, fields) to the autopilot
        self.listeners = listeners or []
        self.depth = ArduSubDepth(sigma_m, tel.timing.depth_latency_s, tel.timing.clock_window_s)
        self.thrusters = thrusters if thrusters is not None else Thrusters()
        self.meter = RateMeter()
        self.requests = RateRequests(
            {"GLOBAL_POSITION_INT": DEPTH_HZ, "SERVO_OUTPUT_RAW": THRUSTERS_HZ}
        )
        self.autopilot: tuple[int, int] | None = None
        self.received = self.bad = self.refused = 0
        # the newest accepted sample and its arrival
        self.last: tuple[DepthSample, float] | None = None
        self._asked: dict[str, float] = {}
        self._throttle = Throttle()

    def on_message(self, kind: str, fields: dict, t_recv: float) -> None:
        """One message of the autopilot's component."""
        self.received += 1
        self.meter.add(kind, t_recv)
        if kind == "COMMAND_ACK":
            target = (
                fields.get("target_system") or SKYFIX_SYSID,
                fields.get("target_component") or GCS_COMPID,
            )
            if target == (SKYFIX_SYSID, GCS_COMPID):  # our requests' answers, not another client's
                self.requests.on_ack(_enum(fields.get("command")), _enum(fields.get("result")))
            return
        self.depth.refusal = None
        reboots = self.depth.reboots
        try:
            if kind == "SERVO_OUTPUT_RAW":
                self.thrusters.outputs(t_recv, servo_pulses_us(fields))
                return
            sample = ingest_ardusub(self.depth, kind, fields, t_recv)
            if kind == "PARAM_VALUE":
                self.thrusters.param(
                    param_name(fields.get("param_id")), float(fields["param_value"])
                )
        except BadMessage as e:
            self.bad += 1
            if self._throttle(kind_of(str(e))):
                log.warning("ArduSub depth: %s", e)
            return
        if self.depth.reboots != reboots:
            self.thrusters.restarted()
        while self.depth.notices:
            log.warning("ArduSub depth: %s", self.depth.notices.pop(0))
        if self.depth.refusal:
            self._refuse(f"{kind} refused: {self.depth.refusal}")
        if sample is None:
            return
        last_t = self.tel.depth.last_t
        if last_t is not None and sample.t <= last_t:
            # not after the newest on the station clock: the first samples of a link (the least-delay offset still
            # shrinking), or the EKF's depth handing over to the pressure's; dropped without complaint
            return
        why = self.gate.check(sample.t, sample.depth_m, sample.sigma_m)
        while self.gate.notices:
            log.warning("ArduSub depth: %s", self.gate.notices.pop(0))
        if why is not None:
            self._refuse(f"{sample.source} {why}")
            return
        if not self.tel.add_autopilot_depth(*sample):
            self._refuse(
                f"{sample.source} depth {sample.depth_m:.2f} m refused: {self.tel.refusal}"
            )
            return
        self.last = (sample, t_recv)
        for listener in self.listeners:
            listener(sample, t_recv)

    def _refuse(self, text: str) -> None:
        self.refused += 1
        n = self._throttle(kind_of(text))
        if n:
            log.warning("ArduSub depth: %s (#%d)", text, n)

    def heard(self, target: tuple[int, int], now: float) -> None:
        """The autopilot is known: requests may go out."""
        if self.autopilot is None:
            self.autopilot = target
            self.requests.start(now)
            log.info("ArduSub depth: the autopilot is system %d, component %d", *target)

    def ask(self, now: float) -> None:
        """The requests due now (see the module doc)."""
        if self.autopilot is None:
            return
        sysid, compid = self.autopilot
        names = self.depth.wanted_params() + self.thrusters.wanted_params()
        if (
            self.depth.primary is not None
            and now - self._asked.get("refresh", now) >= PARAM_REFRESH_S
        ):
            names.append(ground_pressure_param(self.depth.primary))
        for name in dict.fromkeys(names):
            if now - self._asked.get(name, -1e9) >= PARAM_RETRY_S:
                self._asked[name] = now
                if name.endswith("_GND_PRESS"):
                    self._asked["refresh"] = now
                self.send(
                    "PARAM_REQUEST_READ",
                    {
                        "target_system": sysid,
                        "target_component": compid,
                        "param_id": name.encode(),
                        "param_index": -1,
                    },
                )
        if self.depth.wants_origin and now - self._asked.get("origin", -1e9) >= ORIGIN_RETRY_S:
            self._asked["origin"] = now
            self.send(
                "COMMAND_LONG",
                {
                    "target_system": sysid,
                    "target_component": compid,
                    "command": MAV_CMD_REQUEST_MESSAGE,
                    "confirmation": 0,
                    "param1": float(GPS_GLOBAL_ORIGIN_ID),
                    "param2": 0.0,
                    "param3": 0.0,
                    "param4": 0.0,
                    "param5": 0.0,
                    "param6": 0.0,
                    "param7": 0.0,
                },
            )
        pressure = self.depth.pressure_message
        if pressure is not None and pressure not in self.requests.needed:
            for other in PRESSURE_MESSAGES:
                self.requests.needed.pop(other, None)
            self.requests.needed[pressure] = DEPTH_HZ
        for line, kind, fields in self.requests.messages(self.meter, now, self.autopilot):
            log.info("ArduSub depth: %s", line)
            self.send(kind, fields)

    def status(self, now: float) -> dict:
        sample, t_recv = self.last if self.last else (None, None)
        return {
            "received": self.received,
            "bad": self.bad,
            "refused": self.refused,
            "jumps": self.gate.refused,
            "age_s": None if t_recv is None else round(max(0.0, now - t_recv), 3),
            "t": None if sample is None else round(sample.t, 3),
            "depth_m": None if sample is None else round(sample.depth_m, 3),
            "sigma_m": None if sample is None else round(sample.sigma_m, 3),
            "source": None if sample is None else sample.source,
            "vertical_speed_mps": self.depth.status()["vertical_speed_mps"],
            "rates_hz": {k: v for k, v in self.meter.rates(now).items() if k in ARDUSUB_USED},
            "rate_requests": dict(self.requests.state),
            "ardusub": self.depth.status(),
            "thrusters": self.thrusters.status(now),
        }


class ArduSubZenoh:
    """Worker: ArduSub's MAVLink as BlueOS's mavlink-server publishes it on Zenoh (``key``: ``mavlink/1/1``)."""

    shape = "blueos"

    def __init__(
        self,
        session: zenoh.Session,
        key: str,
        tel: Telemetry,
        gate: DepthGate,
        sigma_m: float,
        listeners: list[Callable] | None = None,
        thrusters: Thrusters | None = None,
    ):
        self.session = session
        self.key = key.rstrip("/")
        self.target = autopilot_prefix(self.key)
        self._in: MavlinkIn | None = None
        self.reader = ArduSubReader(tel, gate, sigma_m, self._send, listeners, thrusters)
        self.handoff: Handoff | None = None
        self._throttle = Throttle()

    @property
    def listeners(self) -> list[Callable]:
        return self.reader.listeners

    def _send(self, kind: str, fields: dict) -> None:
        if self._in is not None:
            self._in.put(kind, fields)

    async def run(self) -> None:
        self.handoff = Handoff(
            asyncio.get_running_loop(), lambda item: self._on_payload(*item), HANDOFF_MESSAGES
        )
        self._in = MavlinkIn(
            self.session, self.key.rsplit("mavlink/", 1)[0] + "mavlink/in", SKYFIX_SYSID, GCS_COMPID
        )
        try:
            async with asyncio.TaskGroup() as tg:
                for kind in (
                    ARDUSUB_USED
                ):  # one key each: the router forwards only these, not all of ArduSub's
                    tg.create_task(subscribe(self.session, f"{self.key}/{kind}", self.handoff))
                while True:
                    self.reader.ask(time.time())
                    await asyncio.sleep(ASK_PERIOD_S)
        finally:
            self._in.close()
            self._in = None

    def _on_payload(self, key: str, data: bytes, t_recv: float) -> None:
        kind = key.rsplit("/", 1)[-1]
        try:
            obj = json.loads(data)
            message = obj["message"]
            if not isinstance(message, dict) or message.get("type", kind) != kind:
                raise TypeError(
                    f"message type {message.get('type') if isinstance(message, dict) else None!r} on "
                    f"the key of {kind}"
                )
        except (ValueError, UnicodeDecodeError, RecursionError, KeyError, TypeError) as e:
            self.reader.bad += 1
            why = (
                str(e)
                if isinstance(e, TypeError) and str(e).startswith("message type")
                else "not mavlink-server JSON"
            )
            if self._throttle(kind_of(why)):
                log.warning("ArduSub depth on %s: %s: %r", key, why, data[:120])
            return
        self.reader.heard(self.target, t_recv)
        self.reader.on_message(kind, message, t_recv)

    def status(self, now: float) -> dict:
        return {
            "key": self.key,
            "url": None,
            "shape": self.shape,
            **self.reader.status(now),
            "other": 0,
            "link": None,
            "handoff": self.handoff.status() if self.handoff else None,
        }


class ArduSubMavlink:
    """Worker: ArduSub's depth over a MAVLink link of skyfix's own (``url``, pymavlink's connection strings)."""

    shape = "mavlink"

    def __init__(
        self,
        url: str,
        tel: Telemetry,
        gate: DepthGate,
        sigma_m: float,
        listeners: list[Callable] | None = None,
        thrusters: Thrusters | None = None,
    ):
        self.url = url
        mav = mavutil().mavlink
        self.link = MavlinkLink(
            url,
            SKYFIX_SYSID,
            GCS_COMPID,
            name="UUV MAVLink",
            heartbeat=(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID),
            is_peer=self._from_autopilot,
        )
        self.reader = ArduSubReader(tel, gate, sigma_m, self.link.queue, listeners, thrusters)
        self.handoff: Handoff | None = None
        self.other = 0  # messages of other systems and components

    @property
    def listeners(self) -> list[Callable]:
        return self.reader.listeners

    def _from_autopilot(self, msg) -> bool:  # the link's thread: which sender the link answers
        target = self.reader.autopilot
        if target is not None:
            return (msg.get_srcSystem(), msg.get_srcComponent()) == target
        return is_autopilot_heartbeat(msg)

    async def run(self) -> None:
        self.handoff = Handoff(
            asyncio.get_running_loop(), lambda item: self._on_message(*item), HANDOFF_MESSAGES
        )
        # the link's thread
        self.link.on_message = lambda msg, t_recv: self.handoff.put((msg, t_recv))
        await in_thread(self.link.open, name="UUV MAVLink open")
        try:
            while True:
                self.reader.ask(time.time())
                await asyncio.sleep(ASK_PERIOD_S)
        finally:
            await in_thread(self.link.close, name="UUV MAVLink close")

    def _on_message(self, msg, t_recv: float) -> None:
        kind = msg.get_type()
        source = (msg.get_srcSystem(), msg.get_srcComponent())
        if self.reader.autopilot is None and is_autopilot_heartbeat(msg):
            self.reader.heard(source, t_recv)
        if kind == "BAD_DATA":
            self.reader.bad += 1
            return
        if source != self.reader.autopilot:
            self.other += 1
            return
        if kind in ARDUSUB_USED:
            self.reader.on_message(kind, msg.to_dict(), t_recv)

    def status(self, now: float) -> dict:
        return {
            "key": None,
            "url": self.url,
            "shape": self.shape,
            **self.reader.status(now),
            "other": self.other,
            "link": self.link.status(now),
            "handoff": self.handoff.status() if self.handoff else None,
        }


@register(
    "depth",
    "blueos",
    "ArduSub's depth sensor from BlueOS's mavlink-server on Zenoh (--depth-key mavlink/1/1)",
    thrusters=True,
)
def build_blueos(depth: DepthInput) -> ArduSubZenoh:
    key = depth.options.depth_input_key
    return ArduSubZenoh(
        depth.session, key, depth.tel, depth.gate, depth.sigma_m, thrusters=depth.thrusters
    )


@register("depth", "mavlink", "ArduSub's over --depth-mavlink", thrusters=True)
def build_mavlink(depth: DepthInput) -> ArduSubMavlink:
    url = depth.options.depth_mavlink
    return ArduSubMavlink(url, depth.tel, depth.gate, depth.sigma_m, thrusters=depth.thrusters)

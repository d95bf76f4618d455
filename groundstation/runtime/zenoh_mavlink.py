"""GPS_INPUT injected through BlueOS's mavlink-server over Zenoh (``--gps-input zenoh:mavlink/in``).

mavlink-server subscribes to ``mavlink/in`` and hands each JSON MAVLink message
(``{"header": {...}, "message": {"type": "GPS_INPUT", ...}}``) to the autopilot; it
publishes what the autopilot sends on ``mavlink/{sys}/{comp}/{MSG}``. A Zenoh put
with nobody subscribed is not an error: losing the router (or mavlink-server)
would silently stop GPS_INPUT. Link state is therefore Zenoh's *matching status* of
the ``mavlink/in`` publisher — whether a subscriber on that key is reachable
right now — which covers both a lost router and a stopped mavlink-server (it
declares no liveliness token; its subscriber is the thing that must be there).
Zenoh reports a change within milliseconds of a session closing, and after
its TCP keep-alive lease (10 s by default) when a router vanishes without closing.
The status also gives the routers and peers the session is connected to, and the
age of the autopilot's last HEARTBEAT on ``mavlink/*/1/HEARTBEAT``.

Messages put while nobody matches are counted (``sent_unmatched``). A HEARTBEAT
(``MAV_TYPE_ONBOARD_CONTROLLER``, 245/220, as on a MAVLink link) goes out with the
first GPS_INPUT of every second.

:func:`mavlink_json` writes a message the way mavlink-server (rust-mavlink's serde) reads it:
enums as ``{"type": "ENTRY_NAME"}``, bitmasks as ``{"bits": N}``, char arrays as strings, and
HEARTBEAT's ``type`` named ``mavtype``; :class:`MavlinkIn` puts such messages on ``mavlink/in``
as one system and component (the UUV depth reader asks ArduSub through it too).
"""

from __future__ import annotations

import json
import logging
import threading
import time

import zenoh

from groundstation.mavlink.ids import GPS_COMPID, SKYFIX_SYSID
from groundstation.mavlink.ingest import mavutil
from groundstation.mavlink.link import HEARTBEAT_PERIOD_S

log = logging.getLogger("skyfix.gps_input")

AUTOPILOT_HEARTBEAT_KEY = "mavlink/*/1/HEARTBEAT"
RENAMED = {"type": "mavtype"}  # rust-mavlink's names of MAVLink fields that are Rust keywords
HEARTBEAT = {
    "type": 18,
    "autopilot": 8,
    "base_mode": 0,
    "custom_mode": 0,  # MAV_TYPE_ONBOARD_CONTROLLER, no autopilot
    "system_status": 4,
    "mavlink_version": 3,
}  # MAV_STATE_ACTIVE


def mavlink_json(kind: str, fields: dict) -> dict:
    """A message (``kind`` and its fields as pymavlink names them) as mavlink-server's JSON ``message`` object."""
    mavlink = mavutil().mavlink
    cls = getattr(mavlink, f"MAVLink_{kind.lower()}_message")
    out = {"type": kind}
    for name, value in fields.items():
        if cls.fielddisplays_by_name.get(name) == "bitmask":
            value = {"bits": value}
        elif name in cls.fieldenums_by_name:
            entry = mavlink.enums[cls.fieldenums_by_name[name]].get(value)
            value = {"type": entry.name} if entry is not None else value
        elif isinstance(value, bytes):
            value = value.decode()
        out[RENAMED.get(name, name)] = value
    return out


class MavlinkIn:
    """Messages put on mavlink-server's ``key`` (``mavlink/in``) from one MAVLink system and component."""

    def __init__(self, session: zenoh.Session, key: str, system: int, component: int):
        self.session = session
        self.system, self.component = system, component
        self.publisher = session.declare_publisher(key, encoding=zenoh.Encoding.APPLICATION_JSON)
        self._seq = 0

    def put(self, kind: str, fields: dict) -> None:
        header = {"system_id": self.system, "component_id": self.component, "sequence": self._seq}
        self._seq = (self._seq + 1) % 256
        self.publisher.put(
            json.dumps({"header": header, "message": mavlink_json(kind, fields)}, allow_nan=False),
            timestamp=self.session.new_timestamp(),
        )

    def close(self) -> None:
        self.publisher.undeclare()


class ZenohMavlinkIn:
    """GPS_INPUT as mavlink-server's JSON on ``key``; state from the publisher's matching status."""

    def __init__(self, session: zenoh.Session, key: str):
        self.session = session
        self.url = f"zenoh:{key}"
        self.key = key
        self.last_heard: float | None = None
        self.matching = False
        self.state_since = time.time()
        self.written = 0
        self.heartbeats = 0
        self.sent_unmatched = 0
        self._next_beat = 0.0
        self._lock = threading.Lock()
        self._in: MavlinkIn | None = None
        self._listener = None
        self._sub = None

    def open(self) -> None:
        self._in = MavlinkIn(self.session, self.key, SKYFIX_SYSID, GPS_COMPID)
        self._listener = self._in.publisher.declare_matching_listener(self._on_matching)
        self._on_matching(self._in.publisher.matching_status)
        self._sub = self.session.declare_subscriber(AUTOPILOT_HEARTBEAT_KEY, self._on_heartbeat)

    def _on_matching(self, status) -> None:  # Zenoh's thread: state and a log line only
        with self._lock:
            was, self.matching = self.matching, bool(status.matching)
            if was == self.matching:
                return
            self.state_since = time.time()
        if self.matching:
            log.info("GPS_INPUT link %s: up (a subscriber on %s is reachable)", self.url, self.key)
        else:
            log.warning(
                "GPS_INPUT link %s: down: no subscriber on %s (Zenoh router or BlueOS's mavlink-server "
                "gone); GPS_INPUT is not delivered",
                self.url,
                self.key,
            )

    def _on_heartbeat(self, _sample) -> None:  # Zenoh's thread
        self.last_heard = time.time()

    def _put(self, kind: str, fields: dict) -> None:
        self._in.put(kind, fields)
        if not self.matching:
            self.sent_unmatched += 1

    def send(self, kind: str, fields: dict) -> bool:
        """Put one ``kind`` message (and the HEARTBEAT when one is due); False when nobody is subscribed."""
        now = time.monotonic()
        if now >= self._next_beat:
            self._put("HEARTBEAT", HEARTBEAT)
            self.heartbeats += 1
            self._next_beat = now + HEARTBEAT_PERIOD_S
        self._put(kind, fields)
        self.written += 1
        return self.matching

    def close(self, last: tuple[str, dict] | None = None) -> bool:
        """Put ``last`` ``(kind, fields)`` if given, then undeclare; True if a subscriber matched.

        May be called twice."""
        if self._in is None:
            return False
        delivered = last is not None and self.send(*last)
        self._sub.undeclare()
        self._listener.undeclare()
        self._in.close()
        self._in = None
        return delivered

    def status(self, now: float) -> dict:
        info = self.session.info
        with self._lock:
            state, since = ("up" if self.matching else "down"), self.state_since
        return {
            "url": self.url,
            "state": state,
            "state_for_s": round(max(0.0, now - since), 3),
            "error": None if self.matching else f"no subscriber on {self.key} reachable",
            "zenoh_routers": len(info.routers_zid()),
            "zenoh_peers": len(info.peers_zid()),
            "written": self.written,
            "heartbeats": self.heartbeats,
            "sent_unmatched": self.sent_unmatched,
            "peer_age_s": None
            if self.last_heard is None
            else round(max(0.0, now - self.last_heard), 3),
        }

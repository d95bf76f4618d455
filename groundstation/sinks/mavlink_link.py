"""The UUV autopilot's MAVLink link for GPS_INPUT: its own thread, reconnecting, never blocking the event loop.

One thread (``gps-input-link``) owns the transport (:mod:`groundstation.mavlink_transport`):
it opens it, reads what the autopilot sends (noting when it was last heard), writes the
message handed over by :meth:`MavlinkLink.send`, sends a HEARTBEAT every second, and on any
error closes the transport and opens it again with back-off (:data:`BACKOFF_S`, doubling
up to :data:`BACKOFF_MAX_S`, so a returning autopilot gets GPS_INPUT again within about
half a second). Nothing else opens, writes or closes it; the lock guards the state the
event loop reads.

``send`` (on the event loop) never blocks: the message goes into a one-message slot
that the thread empties (a newer message replaces one not yet written: the newest
state wins; counted as ``superseded``). While the link is down (or, for ``udpin:``/
``tcpin:``, no autopilot has shown up yet) a message is dropped at once and counted.
The message that was being written when the link broke is lost (``write_errors``).

Identity: system 245, component 220 (``MAV_COMP_ID_GPS``), MAVLink 2. The HEARTBEAT is
``MAV_TYPE_ONBOARD_CONTROLLER`` with ``MAV_AUTOPILOT_INVALID`` (a component, not a
vehicle or a ground station: it claims no GCS role in ArduPilot's failsafes), so that
routers learn the route and MAVProxy or QGroundControl in between see a live component.

Signing (``signing_key``, 32 bytes): every message goes out MAVLink 2 signed (link id 1,
the timestamp pymavlink's: 10 µs since 2015, rising by one per message); what the
autopilot sends is read signed or not (it only tells when it was last heard).
"""

from __future__ import annotations

import errno
import logging
import os
import select
import threading
import time
from pathlib import Path

from localizer.calibration import ConfigError

from ..mavlink_io import LinkError, mavutil
from ..mavlink_transport import open_transport

log = logging.getLogger("skyfix.gps_input")

GPS_SYSID = 245  # the same system as skyfix's ground-station heartbeat on the UAV link
GPS_COMPID = 220  # MAV_COMP_ID_GPS
HEARTBEAT_PERIOD_S = 1.0
BACKOFF_S = 0.05
BACKOFF_MAX_S = 0.4
SIGNING_LINK_ID = 1
KEY_BYTES = 32
STOP_TIMEOUT_S = 2.0
#: First-open errors that mean "the autopilot's end is not there yet", not a wrong option: keep trying.
_NOT_YET = (ConnectionError, TimeoutError)
_NOT_YET_ERRNO = (errno.EHOSTUNREACH, errno.ENETUNREACH, errno.EHOSTDOWN)


def read_signing_key(path: str) -> bytes:
    """A MAVLink 2 signing key from a file: 32 raw bytes, or 64 hex digits; :class:`ConfigError` otherwise."""
    try:
        data = Path(path).read_bytes()
    except OSError as e:
        raise ConfigError(path, "--gps-input-signing-key", path, e.strerror or str(e)) from None
    if len(data) == KEY_BYTES:
        return data
    text = data.strip()
    if len(text) == 2 * KEY_BYTES:
        try:
            return bytes.fromhex(text.decode("ascii"))
        except (UnicodeDecodeError, ValueError):
            pass
    raise ConfigError(path, "--gps-input-signing-key", f"{len(data)} bytes",
                      f"expected {KEY_BYTES} raw bytes or {2 * KEY_BYTES} hex digits")


class MavlinkLink:
    """GPS_INPUT and HEARTBEAT over a link skyfix owns (see the module doc)."""

    def __init__(self, url: str, signing_key: bytes | None = None):
        self.url = url
        mavlink = mavutil().mavlink
        self._mavlink = mavlink
        self.mav = mavlink.MAVLink(None, srcSystem=GPS_SYSID, srcComponent=GPS_COMPID)
        self.mav.robust_parsing = True
        if signing_key is not None:
            s = self.mav.signing
            s.secret_key, s.sign_outgoing, s.link_id = signing_key, True, SIGNING_LINK_ID
            s.allow_unsigned_callback = lambda *_: True  # reading only tells that the autopilot is there
            s.timestamp = int((max(time.time(), 1420070400) - 1420070400) * 100_000)
        self.signed = signing_key is not None
        self.last_heard: float | None = None
        self.state = "down"
        self.error: str | None = None
        self.state_since = time.time()
        self.connects = 0
        self.disconnects = 0
        self.written = 0
        self.heartbeats = 0
        self.dropped = 0
        self.superseded = 0
        self.write_errors = 0
        self._lock = threading.Lock()
        self._pending: dict | None = None
        self._final: dict | None = None
        self.final_written = False
        self._stop = threading.Event()
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_w, False)
        self._transport = None
        self._thread: threading.Thread | None = None

    # -- event loop side -------------------------------------------------------------------------
    def open(self) -> None:
        """Open the link once (a malformed string, a port in use: :class:`LinkError`), then keep it open."""
        try:
            transport = open_transport(self.url)
        except OSError as e:
            if not (isinstance(e, _NOT_YET) or e.errno in _NOT_YET_ERRNO):
                os.close(self._wake_r)
                os.close(self._wake_w)
                raise LinkError(f"MAVLink {self.url!r}: cannot open: {e.strerror or e}") from None
            transport = None
            self._set_down(e)
        if transport is not None:
            self._set_up(transport)
        self._thread = threading.Thread(target=self._run, name="gps-input-link", daemon=True)
        self._thread.start()

    def send(self, fields: dict) -> bool:
        """Hand GPS_INPUT ``fields`` to the link's thread; False (dropped, counted) while it is down."""
        with self._lock:
            if self.state != "up":
                self.dropped += 1
                return False
            if self._pending is not None:
                self.superseded += 1
            self._pending = fields
        self._wake()
        return True

    def close(self, final: dict | None = None) -> bool:
        """Stop the thread: ``final`` GPS_INPUT fields are written last if the link is up, then it is closed.

        True if ``final`` was written. Blocks up to :data:`STOP_TIMEOUT_S` (call it from a worker
        thread); may be called twice.
        """
        if self._thread is None:
            return self.final_written
        with self._lock:
            self._final = final
        self._stop.set()
        self._wake()
        self._thread.join(STOP_TIMEOUT_S)
        if not self._thread.is_alive():
            os.close(self._wake_r)
            os.close(self._wake_w)
        self._thread = None
        return self.final_written

    def status(self, now: float) -> dict:
        with self._lock:
            return {"url": self.url, "state": self.state, "state_for_s": round(now - self.state_since, 3),
                    "error": self.error, "signed": self.signed, "connects": self.connects,
                    "disconnects": self.disconnects, "written": self.written, "heartbeats": self.heartbeats,
                    "dropped_while_down": self.dropped, "superseded": self.superseded,
                    "write_errors": self.write_errors,
                    "autopilot_age_s": None if self.last_heard is None else round(now - self.last_heard, 3)}

    def _wake(self) -> None:
        try:
            os.write(self._wake_w, b"!")
        except (BlockingIOError, OSError):  # already awake, or closing
            pass

    # -- the link's thread -----------------------------------------------------------------------
    def _set_up(self, transport) -> None:
        with self._lock:
            self._transport = transport
            self.connects += 1
            self.state = "up" if transport.peer_known else "waiting"
            self.state_since, self.error = time.time(), None
        log.info("GPS_INPUT link %s: %s", self.url, "up" if transport.peer_known else "open, waiting for the autopilot")

    def _set_down(self, e: OSError) -> None:
        why = f"{type(e).__name__}: {e.strerror or e}"
        with self._lock:
            was, first = self.state, self.error is None
            if self._transport is not None:
                self._transport.close()
                self._transport = None
                self.disconnects += 1
            self._pending = None
            if was != "down":
                self.state_since = time.time()
            self.state, self.error = "down", why
        if was != "down" or first:
            log.warning("GPS_INPUT link %s: down (%s); GPS_INPUT dropped until it is back", self.url, why)

    def _run(self) -> None:
        backoff = BACKOFF_S
        next_beat = 0.0
        while not self._stop.is_set():
            if self._transport is None:
                try:
                    transport = open_transport(self.url)
                except OSError as e:
                    self._set_down(e)
                    self._stop.wait(backoff)
                    backoff = min(2 * backoff, BACKOFF_MAX_S)
                    continue
                self._set_up(transport)
                backoff, next_beat = BACKOFF_S, 0.0
            try:
                next_beat = self._serve(next_beat)
            except OSError as e:
                self._set_down(e)
        self._finish()

    def _serve(self, next_beat: float) -> float:
        """One wait for input, a wake-up or the heartbeat; then read, beat and write what is pending."""
        t = self._transport
        wait = max(0.0, next_beat - time.monotonic())
        readable = select.select([*t.filenos(), self._wake_r], [], [], wait)[0]
        if self._wake_r in readable:
            os.read(self._wake_r, 4096)
        if any(fd != self._wake_r for fd in readable):
            self._read(t)
        if t.peer_known and self.state == "waiting":
            with self._lock:
                self.state, self.state_since = "up", time.time()
        if time.monotonic() >= next_beat:
            self._write(t, self._heartbeat())
            self.heartbeats += 1
            next_beat = time.monotonic() + HEARTBEAT_PERIOD_S
        with self._lock:
            fields, self._pending = self._pending, None
        if fields is not None:
            try:
                self._write(t, self.mav.gps_input_encode(**fields))
            except OSError:
                self.write_errors += 1
                raise
            self.written += 1
        return next_beat

    def _read(self, t) -> None:
        data = t.read()
        if not data:
            return
        try:
            msgs = self.mav.parse_buffer(data) or ()
        except Exception:  # noqa: BLE001 - pymavlink raises bare errors on some corrupt input
            return
        if any(m.get_type() != "BAD_DATA" for m in msgs):
            self.last_heard = time.time()

    def _heartbeat(self):
        m = self._mavlink
        return m.MAVLink_heartbeat_message(m.MAV_TYPE_ONBOARD_CONTROLLER, m.MAV_AUTOPILOT_INVALID, 0, 0,
                                           m.MAV_STATE_ACTIVE, 3)

    def _write(self, t, msg) -> None:
        buf = msg.pack(self.mav)
        self.mav.seq = (self.mav.seq + 1) % 256
        t.write(buf)

    def _finish(self) -> None:
        with self._lock:
            final, t = self._final, self._transport
            self._transport = None
        if t is not None:
            if final is not None and t.peer_known:
                try:
                    self._write(t, self.mav.gps_input_encode(**final))
                    self.written += 1
                    self.final_written = True
                except OSError as e:
                    log.warning("GPS_INPUT link %s: the last (no fix) message was not sent: %s", self.url, e)
            t.close()
        with self._lock:
            self.state, self.state_since = "closed", time.time()

"""A MAVLink link skyfix owns: one thread that reads, writes and reconnects, never the event loop.

Used for the UAV's telemetry (:mod:`groundstation.live.sources.uav_mavlink`) and for GPS_INPUT to the UUV
(:mod:`groundstation.runtime.gps_input`). One thread (named after the link) owns the transport
(:mod:`groundstation.mavlink.transport`): it opens it, reads and parses what arrives, writes what is
handed over, sends the HEARTBEAT (if the link has one) every second, and on any error
closes the transport and opens it again with back-off (:data:`BACKOFF_S`, doubling up to
:data:`BACKOFF_MAX_S`, so a returning peer is talked to again within about half a
second; a connection that drops within :data:`STABLE_S` of opening, as an unplugged
serial radio or a server that accepts and closes, keeps the back-off growing). The log
says "down" once per kind of error while the link is away, and "up" once it is back for
good (:data:`STABLE_S`). Nothing else opens, writes or closes the transport. The thread is
:class:`~groundstation.runtime.threads.Supervised`: a bug in it (or in ``on_message``) is one log line, the
transport is closed and the thread starts over with back-off (``restarts`` in the status).

Reading: every message, BAD_DATA included, goes to ``on_message(msg, t_recv_unix)`` on the
link's thread, ``t_recv_unix`` its arrival (a UDP datagram's as the kernel received it: the transport's
``t_received``); a message id no dialect knows (pymavlink cannot check its CRC) is BAD_DATA. A UDP datagram is parsed on its own: bytes of a frame it leaves unfinished
are dropped (one BAD_DATA) instead of being joined to the next datagram's — else one
truncated or random datagram swallows the valid frame after it. On ``udpin:`` the link
locks to the first sender whose datagram held a message ``is_peer`` accepts (the vehicle,
not whoever else sends there), or to ``peer`` (``HOST:PORT``) when given: datagrams from
elsewhere are dropped unread, counted in ``foreign_datagrams`` (``peer`` in the status: the
address locked to; see :mod:`~groundstation.mavlink.transport`).

Writing never blocks the caller: ``mav.<message>_send(...)`` (pymavlink's API) queues the
packed frame (at most :data:`OUTBOX`; beyond, the oldest is dropped and counted), and
:meth:`MavlinkLink.send` puts a message into a slot of its own kind where a newer one
replaces one not yet written (``superseded``: the newest state wins). While the link is
down, or no peer has shown up yet on ``udpin:``/``tcpin:``, what is handed over is dropped
at once and counted. A write that fails (or takes longer than the transport's write
timeout) counts in ``write_errors`` and takes the link down; the frame is lost.

Signing (``signing_key``, 32 bytes): every message goes out MAVLink 2 signed (link id 1, the
timestamp pymavlink's: 10 µs units since 2015, rising by one per message); incoming messages
are read signed or not, unless ``require_signed``: then an unsigned message or one signed with another key is
BAD_DATA ("Invalid signature"), never a message. A receiver refuses a
signed message whose timestamp is not after the last it took (replay protection), so what
:meth:`~MavlinkLink.send` and :meth:`~MavlinkLink.queue` hand over is numbered and signed by the
link's thread as it writes it, in the order written (the heartbeat and the last message too); the
fields are checked when they are handed over (a value that does not fit raises there).
``mav.<message>_send(...)`` packs at once: it is for unsigned links.
"""

from __future__ import annotations

import errno
import logging
import os
import select
import threading
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path

from groundstation.mavlink.ingest import LinkError, mavutil
from groundstation.mavlink.transport import open_transport
from groundstation.runtime.threads import Supervised
from localizer.calibration import ConfigError

log = logging.getLogger("skyfix.mavlink")

HEARTBEAT_PERIOD_S = 1.0
BACKOFF_S = 0.05
BACKOFF_MAX_S = 0.4
OUTBOX = 64
SIGNING_LINK_ID = 1
KEY_BYTES = 32
STABLE_S = 1.0
# a stop waits this long for the last message, then leaves the thread to end by itself
STOP_TIMEOUT_S = 0.5
_SIGNING_EPOCH = 1420070400  # 2015-01-01, MAVLink signing's time origin
#: First-open errors that mean "the other end is not there yet", not a wrong option: keep trying.
_NOT_YET = (ConnectionError, TimeoutError)
_NOT_YET_ERRNO = (errno.EHOSTUNREACH, errno.ENETUNREACH, errno.EHOSTDOWN)


def read_signing_key(path: str, option: str = "--gps-input-signing-key") -> bytes:
    """A MAVLink 2 signing key from a file: 32 raw bytes, or 64 hex digits; :class:`ConfigError` otherwise."""
    try:
        data = Path(path).read_bytes()
    except OSError as e:
        raise ConfigError(path, option, path, e.strerror or str(e)) from None
    if len(data) == KEY_BYTES:
        return data
    text = data.strip()
    if len(text) == 2 * KEY_BYTES:
        try:
            return bytes.fromhex(text.decode("ascii"))
        except (UnicodeDecodeError, ValueError):
            pass
    raise ConfigError(
        path,
        option,
        f"{len(data)} bytes",
        f"expected {KEY_BYTES} raw bytes or {2 * KEY_BYTES} hex digits",
    )


def _reset_parser(mav) -> int:
    """Forget an unfinished frame (a datagram boundary); the number of its bytes."""
    left = mav.buf_len()
    mav.buf, mav.buf_index = bytearray(), 0
    mav.expected_length = mavutil().mavlink.HEADER_LEN_V1 + 2
    mav.have_prefix_error = False
    return left


class _Outbox:
    """pymavlink's ``file`` for the link's MAVLink object: frames queue for the link's thread."""

    def __init__(self, link: MavlinkLink):
        self.link = link

    def write(self, buf: bytes) -> None:
        self.link._queue(buf)


class MavlinkLink:
    """A MAVLink link with its own thread (see the module doc).

    ``system``/``component`` are skyfix's ids on it; ``heartbeat`` ``(MAV_TYPE, MAV_AUTOPILOT)`` makes
    the thread send a HEARTBEAT every second; ``on_message`` and ``is_peer`` are called on the thread.
    """

    def __init__(
        self,
        url: str,
        system: int,
        component: int,
        *,
        name: str,
        heartbeat: tuple[int, int] | None = None,
        signing_key: bytes | None = None,
        require_signed: bool = False,
        on_message: Callable | None = None,
        is_peer: Callable | None = None,
        peer: str | None = None,
    ):
        self.url = url
        self.peer = peer
        self.name = name
        self._mavlink = mavlink = mavutil().mavlink
        self._lock = threading.RLock()
        lock = self._lock

        class _Locked(mavlink.MAVLink):  # packing and the sequence number under the link's lock
            def send(self, msg, force_mavlink1=False):
                with lock:
                    super().send(msg, force_mavlink1)

        self.mav = _Locked(_Outbox(self), srcSystem=system, srcComponent=component)
        self.parser = mavlink.MAVLink(None, srcSystem=system, srcComponent=component)
        self.parser.robust_parsing = True
        # packs to check, unsigned
        self._checker = mavlink.MAVLink(None, srcSystem=system, srcComponent=component)
        if signing_key is not None:
            s = self.mav.signing
            s.secret_key, s.sign_outgoing, s.link_id = signing_key, True, SIGNING_LINK_ID
            s.timestamp = int((max(time.time(), _SIGNING_EPOCH) - _SIGNING_EPOCH) * 100_000)
            if require_signed:
                # and no allow_unsigned_callback: unsigned is refused
                self.parser.signing.secret_key = signing_key
        self.signed = signing_key is not None
        self.heartbeat = heartbeat
        self.on_message = on_message or (lambda msg, t: None)
        self.is_peer = is_peer or (lambda msg: msg.get_type() != "BAD_DATA")
        self.last_heard: float | None = None
        self.state = "down"
        self.error: str | None = None
        self.state_since = time.time()
        self.counts = dict.fromkeys(
            (
                "connects",
                "disconnects",
                "written",
                "heartbeats",
                "dropped_while_down",
                "superseded",
                "outbox_dropped",
                "write_errors",
                "reads",
                "unfinished_frames",
                "foreign_datagrams",
            ),
            0,
        )
        self.final_written = False
        self._outbox: deque[bytes] = deque()
        self._newest: dict[str, bytes] = {}
        self._final: bytes | None = None
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_w, False)
        self._transport = None
        self._thread = Supervised(name, self._run)
        self._started = False
        self._connected_at = 0.0  # time.monotonic() of the latest connect
        self._outage: set[str] = set()  # kinds of error logged since the link was last up for good

    # -- callers' side ---------------------------------------------------------------------------
    def open(self) -> None:
        """Open the link once (a malformed string, a port in use: :class:`LinkError`), then keep it open."""
        try:
            transport = open_transport(self.url, self.peer)
        except OSError as e:
            if not (isinstance(e, _NOT_YET) or e.errno in _NOT_YET_ERRNO):
                os.close(self._wake_r)
                os.close(self._wake_w)
                raise LinkError(f"MAVLink {self.url!r}: cannot open: {e.strerror or e}") from None
            transport = None
            self._set_down(e)
        if transport is not None:
            self._set_up(transport)
        self._started = True
        self._thread.start()

    def message(self, kind: str, fields: dict):
        """Message ``kind`` (e.g. ``"GPS_INPUT"``) from its fields, checked by packing it once unnumbered and
        unsigned (a field that does not fit raises here, in the caller)."""
        msg = getattr(self._mavlink, f"MAVLink_{kind.lower()}_message")(**fields)
        msg.pack(self._checker)
        return msg

    def _pack(self, msg) -> bytes:
        """The frame of ``msg``, numbered and signed as the link's next (the link's thread, as it writes)."""
        with self._lock:
            buf = msg.pack(self.mav)
            self.mav.seq = (self.mav.seq + 1) % 256
        return buf

    def send(self, kind: str, fields: dict) -> bool:
        """Hand one ``kind`` message to the thread, replacing one of that kind not yet written; False (dropped,
        counted) while the link is down."""
        buf = self.message(kind, fields)
        with self._lock:
            if self.state != "up":
                self.counts["dropped_while_down"] += 1
                return False
            self.counts["superseded"] += kind in self._newest
            self._newest[kind] = buf
        self._wake()
        return True

    def queue(self, kind: str, fields: dict) -> None:
        """Hand one ``kind`` message to the thread after those before it (never replaced; dropped while down)."""
        self._queue(self.message(kind, fields))

    def _queue(self, buf) -> None:
        """Queue a packed frame (bytes: pymavlink's ``mav.*_send``) or a message to pack as it is written."""
        with self._lock:
            if self.state != "up":
                self.counts["dropped_while_down"] += 1
                return
            if len(self._outbox) >= OUTBOX:
                self._outbox.popleft()
                self.counts["outbox_dropped"] += 1
            self._outbox.append(buf)
        self._wake()

    def close(self, last: tuple[str, dict] | None = None) -> bool:
        """Stop the thread; ``last`` ``(kind, fields)`` is written last if the link is up, then it is closed.

        True if ``last`` was written. Blocks up to :data:`STOP_TIMEOUT_S` (call it from a worker
        thread); may be called twice.
        """
        if not self._started:
            return self.final_written
        self._started = False
        with self._lock:
            self._final = self.message(*last) if last is not None else None
        self._thread.stop.set()
        self._wake()
        if self._thread.join(STOP_TIMEOUT_S):
            os.close(self._wake_r)
            os.close(self._wake_w)
        return self.final_written

    def status(self, now: float) -> dict:
        with self._lock:
            t = self._transport
            dest = getattr(t, "dest", None) if getattr(t, "listen", False) else None
            return {
                "url": self.url,
                "state": self.state,
                "state_for_s": round(max(0.0, now - self.state_since), 3),
                "error": self.error,
                "signed": self.signed,
                **self.counts,
                **self._thread.status(),
                "peer": None if dest is None else f"{dest[0]}:{dest[1]}",
                "relocks": getattr(t, "relocks", 0),
                "peer_age_s": None
                if self.last_heard is None
                else round(max(0.0, now - self.last_heard), 3),
            }

    def _wake(self) -> None:
        try:
            os.write(self._wake_w, b"!")
        except OSError:  # already awake (pipe full), or closing
            pass

    # -- the link's thread -----------------------------------------------------------------------
    def _set_up(self, transport) -> None:
        with self._lock:
            self._transport = transport
            self.counts["connects"] += 1
            self.state = "up" if transport.peer_known else "waiting"
            self.state_since, self.error = time.time(), None
        self._connected_at = time.monotonic()
        if not self._outage:  # after an outage: said once it holds (_stable)
            log.info(
                "%s %s: %s",
                self.name,
                self.url,
                "up" if transport.peer_known else "open, waiting for its peer",
            )

    def _stable(self) -> None:
        """Up for :data:`STABLE_S`: an outage that was logged is over."""
        if (
            self._outage
            and self._transport is not None
            and time.monotonic() - self._connected_at >= STABLE_S
        ):
            self._outage.clear()
            log.info("%s %s: up again", self.name, self.url)

    def _set_down(self, e: Exception) -> None:
        why = f"{type(e).__name__}: {e.strerror or e}" if isinstance(e, OSError) else f"{e}"
        kind = f"{type(e).__name__} {getattr(e, 'errno', None)}"
        with self._lock:
            was = self.state
            if self._transport is not None:
                self._transport.close()
                self._transport = None
                self.counts["disconnects"] += 1
            self._outbox.clear()
            self._newest.clear()
            if was != "down":
                self.state_since = time.time()
            self.state, self.error = "down", why
        if kind not in self._outage:
            self._outage.add(kind)
            log.warning(
                "%s %s: down (%s); reconnecting, messages to it are dropped meanwhile",
                self.name,
                self.url,
                why,
            )

    def _run(self, stop: threading.Event) -> None:
        """The link's thread (under :class:`~groundstation.runtime.threads.Supervised`): connect, serve, reconnect with back-off."""
        backoff = BACKOFF_S
        next_beat = 0.0
        try:
            while not stop.is_set():
                if self._transport is None:
                    try:
                        transport = open_transport(self.url, self.peer)
                    except OSError as e:
                        self._set_down(e)
                        stop.wait(backoff)
                        backoff = min(2 * backoff, BACKOFF_MAX_S)
                        continue
                    self._set_up(transport)
                    next_beat = 0.0
                try:
                    next_beat = self._serve(self._transport, next_beat)
                    self._stable()
                except OSError as e:
                    if time.monotonic() - self._connected_at >= STABLE_S:
                        backoff = BACKOFF_S
                    self._set_down(e)
                    stop.wait(backoff)
                    backoff = min(2 * backoff, BACKOFF_MAX_S)
        except Exception as e:
            self._set_down(e)  # a bug: start over on a new connection
            raise
        self._finish()

    def _serve(self, t, next_beat: float) -> float:
        """One wait for input, a wake-up or the heartbeat; then read, beat and write what is pending."""
        wait = max(0.0, next_beat - time.monotonic()) if self.heartbeat else 1.0
        readable = select.select([*t.filenos(), self._wake_r], [], [], wait)[0]
        if self._wake_r in readable:
            os.read(self._wake_r, 4096)
        if any(fd != self._wake_r for fd in readable):
            self._read(t)
        if t.peer_known and self.state == "waiting":
            with self._lock:
                self.state, self.state_since = "up", time.time()
        if self.heartbeat and time.monotonic() >= next_beat:
            kind, autopilot = self.heartbeat
            m = self._mavlink
            self._write(
                t,
                self.message(
                    "HEARTBEAT",
                    {
                        "type": kind,
                        "autopilot": autopilot,
                        "base_mode": 0,
                        "custom_mode": 0,
                        "system_status": m.MAV_STATE_ACTIVE,
                        "mavlink_version": 3,
                    },
                ),
            )
            self.counts["heartbeats"] += 1
            next_beat = time.monotonic() + HEARTBEAT_PERIOD_S
        while True:
            with self._lock:
                if self._outbox:
                    buf = self._outbox.popleft()
                elif self._newest:
                    buf = self._newest.pop(next(iter(self._newest)))
                else:
                    break
            self._write(t, buf)
        return next_beat

    def _read(self, t) -> None:
        foreign = getattr(t, "foreign", 0)
        data = t.read()
        self.counts["foreign_datagrams"] += getattr(t, "foreign", 0) - foreign
        if not data:
            return
        now = t.t_received
        self.counts["reads"] += 1
        try:
            msgs = self.parser.parse_buffer(data) or []
        except Exception as e:  # noqa: BLE001 - pymavlink raises bare errors on some corrupt input
            msgs = [self._mavlink.MAVLink_bad_data(bytearray(data[:64]), f"parser error: {e!r}")]
            _reset_parser(self.parser)
        if t.datagrams:
            left = _reset_parser(self.parser)
            if left:
                self.counts["unfinished_frames"] += 1
                msgs.append(
                    self._mavlink.MAVLink_bad_data(
                        bytearray(data[-left:][:64]), f"datagram ends inside a frame ({left} bytes)"
                    )
                )
        peer = False
        for i, msg in enumerate(msgs):
            if msg.get_type().startswith(
                "UNKNOWN_"
            ):  # an id no dialect has: its CRC cannot even be checked
                msg = msgs[i] = self._mavlink.MAVLink_bad_data(
                    bytearray(msg.get_msgbuf()[:64]), f"unknown message id {msg.get_msgId()}"
                )
            if msg.get_type() != "BAD_DATA" and self.is_peer(msg):
                peer = True
            self.on_message(msg, now)
        if peer:
            self.last_heard = now
            if t.datagrams:
                t.answer_last_sender()

    def _write(self, t, item) -> None:
        """Write a frame, or a message packed now (numbered and signed in the order written)."""
        buf = item if isinstance(item, bytes | bytearray) else self._pack(item)
        try:
            t.write(buf)
        except OSError:
            self.counts["write_errors"] += 1
            raise
        self.counts["written"] += 1

    def _finish(self) -> None:
        with self._lock:
            final, t = self._final, self._transport
            self._transport = None
        if t is not None:
            if final is not None and t.peer_known:
                try:
                    self._write(t, final)
                    self.final_written = True
                except OSError as e:
                    log.warning("%s %s: the last message was not sent: %s", self.name, self.url, e)
            t.close()
        with self._lock:
            self.state, self.state_since = "closed", time.time()

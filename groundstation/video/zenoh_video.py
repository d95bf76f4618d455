"""BlueOS's camera over Zenoh: ``foxglove.CompressedVideo`` messages, read as a live video input and sent by replay.

What BlueOS's mavlink-camera-manager publishes (its Zenoh sink, ``src/lib/stream/sink/zenoh_sink.rs`` and
``src/lib/stream/sink/types/zenoh_message.rs`` of github.com/mavlink/mavlink-camera-manager, read for this module):

- on the key ``video/<stream name, ASCII letters and digits only>/stream``, one ``put`` per access unit (its
  GStreamer ``h264parse`` ends on ``alignment=au``, ``stream-format=byte-stream``): Annex B H.264 (or H.265), the
  parameter sets wherever the camera's stream carries them (cameras repeat them before each keyframe);
- the payload is CDR, little endian (Rust's ``cdr::CdrLe``: a 4-byte encapsulation header ``00 01 00 00``), of
  the struct ``{timestamp: {sec: u32, nsec: u32}, frame_id: string, data: sequence<u8>, format: string}`` (a
  string is a u32 length counting its terminating NUL, then its bytes and the NUL; a sequence a u32 count; each
  u32 aligned to 4 bytes from the end of the header). ``frame_id`` is ``"vehicle"``, ``format`` ``"h264"`` or
  ``"h265"``; the Zenoh encoding ``application/cdr;foxglove.CompressedVideo``; no attachment;
- ``timestamp`` is the camera computer's UTC clock when the message is published (``Timestamp::now()``, after the
  encoder and parser): the camera's own clock, not the station's;
- the manager is a Zenoh client of BlueOS's router (``tcp/127.0.0.1:7447``), which time-stamps every sample it
  routes with its own Zenoh ID.

Reading (``--video zenoh:KEY[?peer=ZID|any]``, :class:`ZenohVideoInput`, shaped like the container
:class:`~groundstation.video.live.VideoLive` reads, decoded by FFmpeg as RTP's access units are): Zenoh's thread
only queues the payload with its arrival time; each message's ``timestamp`` becomes the access unit's PTS on a
90 kHz clock, which the live reader maps to the station clock as it maps RTP timestamps (the least arrival −
timestamp over a window: the camera computer's clock may be anywhere), so the measured or configured latency is
glass to publication. The sender is the Zenoh ID that time-stamped the sample (BlueOS's router, or a publisher that
stamps its own): ``peer=ZID`` takes that one only; without it the first sender whose message reads as video is
taken (:class:`~groundstation.runtime.sender_lock.SenderLock`, as ``rtp://`` takes the first address); ``any``
takes everyone. Another sender's messages, and messages nobody time-stamped (no identity), are refused and
counted (the status's ``sender``); this keeps a second camera out of the stream, it is no authentication (that
is the session's TLS, :mod:`groundstation.runtime.zenoh_session`). A payload that is not such a message is counted
(``bad_packets``) and logged in one line; a stream that stops is a ``TimeoutError`` after the read timeout,
reported and reopened by the live reader.
"""

from __future__ import annotations

import logging
import queue
import struct
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import av
import zenoh

from groundstation.runtime.logs import Throttle, kind_of
from groundstation.runtime.sender_lock import SenderLock
from groundstation.video.rtp import VIDEO_HZ, AccessUnit
from groundstation.video.send import wait_until
from groundstation.video.udp import DecoderStream, DecoderStreams, packet_of

log = logging.getLogger("skyfix.video")

#: The Zenoh encoding BlueOS's camera manager sets on each message
ENCODING = zenoh.Encoding.APPLICATION_CDR.with_schema("foxglove.CompressedVideo")
#: CDR encapsulation headers: little and big endian plain CDR
CDR_LE, CDR_BE = b"\x00\x01\x00\x00", b"\x00\x00\x00\x00"
FORMATS = ("h264", "h265")
#: Messages received, not yet read (4 s at 30 fps); beyond, the oldest is dropped, counted
MESSAGE_BACKLOG = 120
_THROTTLE = Throttle()  # the inputs' warnings, thinned out across reconnections
#: The encoder of :func:`camera_access_units`: a camera's (no B-frames, parameter sets before each keyframe, 1 s GOP)
ENCODER_OPTIONS = {
    "preset": "ultrafast",
    "tune": "zerolatency",
    "x264-params": "repeat-headers=1:keyint=30:bframes=0",
}


class BadVideoMessage(ValueError):
    """A payload that is not a ``foxglove.CompressedVideo`` message in CDR."""


@dataclass(frozen=True)
class CompressedVideo:
    """One ``foxglove.CompressedVideo`` message: ``sec``/``nsec`` the publisher's clock (UNIX time), ``data`` one
    access unit (Annex B), ``format`` ``h264`` or ``h265``."""

    sec: int
    nsec: int
    frame_id: str
    data: bytes
    format: str

    @property
    def ticks_90khz(self) -> int:
        """The timestamp in 1/90 000 s (the clock of RTP video timestamps)."""
        return self.sec * VIDEO_HZ + self.nsec * VIDEO_HZ // 1_000_000_000


class _Reader:
    """CDR fields read in order from a body (alignment from the body's start)."""

    def __init__(self, body: bytes, order: str):
        self.body, self.order, self.pos = body, order, 0

    def u32(self, what: str) -> int:
        self.pos += -self.pos % 4
        if self.pos + 4 > len(self.body):
            raise BadVideoMessage(f"ends before {what}")
        (value,) = struct.unpack_from(self.order + "I", self.body, self.pos)
        self.pos += 4
        return value

    def raw(self, n: int, what: str) -> bytes:
        if self.pos + n > len(self.body):
            raise BadVideoMessage(f"{what} of {n} bytes runs past the message's end")
        self.pos += n
        return self.body[self.pos - n : self.pos]

    def string(self, what: str) -> str:
        n = self.u32(what)
        text = self.raw(n, what)
        if n == 0 or text[-1] != 0:
            raise BadVideoMessage(f"{what} is not a NUL-terminated string")
        try:
            return text[:-1].decode()
        except UnicodeDecodeError:
            raise BadVideoMessage(f"{what} is not UTF-8") from None


def parse_compressed_video(payload: bytes) -> CompressedVideo:
    """The message in a CDR payload (module doc); :class:`BadVideoMessage` naming what is wrong."""
    head = bytes(payload[:4])
    if head not in (CDR_LE, CDR_BE):
        raise BadVideoMessage(f"CDR header {head.hex()} is not plain CDR (00010000 or 00000000)")
    r = _Reader(payload[4:], "<" if head == CDR_LE else ">")
    sec, nsec = r.u32("timestamp.sec"), r.u32("timestamp.nsec")
    if nsec >= 1_000_000_000:
        raise BadVideoMessage(f"timestamp.nsec {nsec} is not below 1e9")
    frame_id = r.string("frame_id")
    data = r.raw(r.u32("data"), "data")
    fmt = r.string("format")
    if not data:
        raise BadVideoMessage("data is empty")
    return CompressedVideo(sec, nsec, frame_id, bytes(data), fmt)


def encode_compressed_video(msg: CompressedVideo) -> bytes:
    """The CDR payload (little endian) of a message, as the camera manager serializes it."""
    out = bytearray(CDR_LE)

    def u32(value: int) -> None:
        out.extend(b"\x00" * (-(len(out) - 4) % 4))
        out.extend(struct.pack("<I", value))

    def string(text: str) -> None:
        raw = text.encode() + b"\x00"
        u32(len(raw))
        out.extend(raw)

    u32(msg.sec)
    u32(msg.nsec)
    string(msg.frame_id)
    u32(len(msg.data))
    out.extend(msg.data)
    string(msg.format)
    return bytes(out)


def sender_of(sample: zenoh.Sample) -> str | None:
    """The Zenoh ID that time-stamped a sample (its publisher or the first router on its way); None: unstamped."""
    return None if sample.timestamp is None else str(sample.timestamp.get_id())


@dataclass
class MessageCounts:
    """What a Zenoh video input could not use, in the live status's ``rtp``/``mpegts`` terms: ``lost_packets``
    messages dropped while the reader was behind, ``bad_packets`` payloads that are not video messages."""

    lost_packets: int = 0
    dropped_units: int = 0  # never: a message is one whole access unit
    bad_packets: int = 0


class ZenohVideoInput:
    """``key``'s ``foxglove.CompressedVideo`` messages on ``session`` from the senders ``lock`` admits, as a
    container with one video stream (module doc). The open waits up to ``open_timeout_s`` for the first message
    (its ``format`` is the codec); :meth:`demux` raises ``TimeoutError`` when nothing came for ``read_timeout_s``."""

    def __init__(
        self,
        session: zenoh.Session,
        key: str,
        open_timeout_s: float,
        read_timeout_s: float,
        lock: SenderLock | None = None,
    ):
        self.key = key
        self.read_timeout_s = read_timeout_s
        self.lock = SenderLock() if lock is None else lock
        # the live reader's name for an input's losses
        self.depacketizer = self.counts = MessageCounts()
        self.codec: str | None = None
        self._messages: queue.Queue = queue.Queue(maxsize=MESSAGE_BACKLOG)
        self._queue_lock = threading.Lock()
        self._first: AccessUnit | None = None
        self._sub = session.declare_subscriber(key, self._on_sample)
        try:
            self._first = self._next(time.monotonic() + open_timeout_s)
        except TimeoutError:
            self.close()
            raise TimeoutError(f"no video message within {open_timeout_s:g} s") from None
        except BaseException:
            self.close()
            raise
        self.streams = DecoderStreams(DecoderStream(self.codec))

    def _on_sample(self, sample: zenoh.Sample) -> None:  # Zenoh's thread: a bounded hand-off only
        item = (sample.payload.to_bytes(), sender_of(sample))
        with self._queue_lock:
            if self._messages.full():
                self._messages.get_nowait()
                self.counts.lost_packets += 1
            self._messages.put_nowait(item)

    def _bad(self, why: str, payload: bytes) -> None:
        self.counts.bad_packets += 1
        if _THROTTLE(kind_of(why)):
            log.warning("video on %s: %s: %r", self.key, why, payload[:40])

    def _next(self, deadline: float) -> AccessUnit:
        """The next access unit from an admitted sender (``TimeoutError`` when none came by ``deadline``,
        monotonic s). A message that reads as video locks its sender."""
        while True:
            try:
                payload, sender = self._messages.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                raise TimeoutError from None
            if sender is None and self.lock.locked:
                self.lock.foreign += 1
                if _THROTTLE("unstamped"):
                    log.warning(
                        "video on %s: a message without a Zenoh timestamp (no sender identity) refused; "
                        "peer=any takes it",
                        self.key,
                    )
                continue
            if sender is not None and not self.lock.admits(sender):
                continue
            try:
                msg = parse_compressed_video(payload)
            except BadVideoMessage as e:
                self._bad(str(e), payload)
                continue
            if msg.format not in FORMATS or msg.format != (self.codec or msg.format):
                self._bad(
                    f"format {msg.format!r} is not {self.codec or ' or '.join(FORMATS)}", payload
                )
                continue
            self.codec = msg.format
            if sender is not None:
                self.lock.lock(sender)
            return AccessUnit(msg.data, msg.ticks_90khz, False)

    def demux(self, stream) -> Iterator[av.Packet]:
        unit, self._first = self._first, None
        while True:
            if unit is not None:
                yield packet_of(unit, stream)
            try:
                unit = self._next(time.monotonic() + self.read_timeout_s)
            except TimeoutError:
                raise TimeoutError(f"nothing received for {self.read_timeout_s:g} s") from None

    def close(self) -> None:
        self._sub.undeclare()


def camera_encoder(width: int, height: int, time_base: Fraction):
    """A camera's H.264 encoder (:data:`ENCODER_OPTIONS`): frames of ``width`` x ``height`` px, their ``pts`` in
    ``time_base`` s, in; one access unit (Annex B) per frame out."""
    ctx = av.CodecContext.create("libx264", "w")
    ctx.width, ctx.height, ctx.pix_fmt = width, height, "yuv420p"
    ctx.time_base = time_base
    ctx.options = ENCODER_OPTIONS
    return ctx


def camera_access_units(path: Path) -> Iterator[tuple[float, av.Packet]]:
    """``path``'s video as a camera's encoder makes it (:data:`ENCODER_OPTIONS`): ``(seconds after the first
    frame, one access unit, Annex B)`` per frame."""
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        enc = camera_encoder(
            stream.codec_context.width, stream.codec_context.height, stream.time_base
        )
        t_first = None
        for frame in container.decode(stream):
            if frame.pts is None:
                continue
            t_s = float(frame.pts * stream.time_base)
            t_first = t_s if t_first is None else t_first
            frame.pict_type = av.video.frame.PictureType.NONE  # the encoder's own GOP
            for packet in enc.encode(frame):
                yield t_s - t_first, packet


def publish_video(
    path: Path,
    key: str,
    t0_unix: float,
    stop: threading.Event,
    skip: Callable[[float, bool], bool] | None = None,
    *,
    session: zenoh.Session,
) -> int:
    """Publish ``path``'s video on ``key`` of ``session`` as BlueOS's camera manager does (module doc: one
    CDR message per access unit of :func:`camera_access_units`, stamped when it leaves, no Zenoh timestamp of its
    own): each frame's at ``t0_unix`` + its time after the first frame; the number of messages sent.
    ``skip(t_s, keyframe)`` as in :func:`~groundstation.video.send.send_video` (a cut link)."""
    sent = 0
    publisher = session.declare_publisher(key, encoding=ENCODING)
    try:
        for t_s, packet in camera_access_units(path):
            if not wait_until(t0_unix + t_s, stop):
                break
            if skip is not None and skip(t_s, packet.is_keyframe):
                continue
            now_ns = time.time_ns()
            msg = CompressedVideo(
                now_ns // 1_000_000_000, now_ns % 1_000_000_000, "vehicle", bytes(packet), "h264"
            )
            publisher.put(encode_compressed_video(msg))
            sent += 1
    finally:
        publisher.undeclare()
    return sent

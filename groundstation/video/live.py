"""The UAV's video, live: frames timed by the stream, reconnecting by itself.

A reader thread opens ``--video`` (:mod:`.inputs`: MPEG-TS over UDP, RTP
with or without an SDP file, RTSP, a V4L2 camera, a file) with PyAV for low
delay. A demuxing thread reads its packets as they come and notes when each was
read from the network (``t_recv``); the reader decodes them (slice threads only:
no frame held back for threading). Reading apart from decoding keeps ``t_recv``
true when the decoder falls behind (a loaded laptop, 1080p): the packets wait in a
queue of at most :data:`PACKET_BACKLOG`, not in the socket. While more than
:data:`BEHIND_PACKETS` wait, a live stream's decoded frames are not converted nor
handed over (they would be stale; ``skipped_behind`` in the status), so the
decoder catches up instead of falling further behind (not the run's first frame: ``[tracker] init_bbox`` is its); while more than :data:`CATCH_UP_PACKETS` wait (a decoder
slower than the stream: a saturated laptop), the packets before the newest keyframe among them are dropped
unread (newest wins; counted in ``skipped_behind`` too): decoding restarts there, fresh frames come out again
instead of none at all (every decoded frame stale, skipped) with the stream seconds behind. Each frame handed over goes
to the event loop as a :class:`LiveFrame` (its BGR image and, beside it, its luma plane as decoded: the default
tracker's grey levels, the same as ``skyfix process`` reads; :func:`frame_images`) through a bounded
:class:`~groundstation.runtime.threads.Handoff` (:data:`HANDOFF_FRAMES`; beyond, the oldest
is dropped and counted). The thread is :class:`~groundstation.runtime.threads.Supervised`
(a bug in it is one log line and a restart with back-off). A stop does not wait for
it: FFmpeg's open or read cannot be interrupted from outside and may block for up to
its timeout, so the daemon thread is left to see the stop and end by itself.

Time: a frame's presentation timestamp (PTS: the RTP timestamp for RTP/RTSP, the
MPEG-TS PTS) is put on the station clock by the least ``arrival − PTS`` over a
sliding window (:class:`localizer.clock.ClockMap`), which is the stream slot: when
the frame's packets arrive over the fastest path. Its exposure ``t_unix`` is that
slot minus ``latency_s`` (``--video-latency-ms``: glass to first packet, i.e.
camera + encoder + network; None with ``auto`` until the estimate from the image's
motion has settled: the slot itself, the frame marked not ``aligned``). Decoding
delay, jitter and bursts move neither.
Each connection starts a new map (a camera that restarts restarts its clock).
The packets read while a connection is being opened are stamped when the open
returns, late: the first frames of a connection may be late by that much until a
packet read live lowers the offset (so a slot may be earlier than the one before
it just after a connection starts). A frame without a PTS (RTP's first access
unit may lose it) takes its arrival as its slot. H.264/H.265 from an ``.sdp``
file or RTSP reach skyfix one frame late: FFmpeg ends an access unit only when
the next one starts, so an access unit's arrival is taken as the hand-over of the
one before it (timed as if it came when it was handed over, every frame was a
frame interval late: 33 ms at 30 fps, centimetres on a moving UAV). ``rtp://`` and
``udp://`` (MPEG-TS) are read by skyfix itself (:mod:`.udp`), which ends a frame at its
marker bit (:mod:`.rtp`) or its PES's last packet (:mod:`.mpegts`).

Failures: a stream that cannot be opened (refused, a port another program holds)
is retried with back-off from :data:`RETRY_MIN_S` to ``retry_max_s``; one that
sent nothing for ``open_timeout_s`` is opened again at once (a UDP port is not
left unbound between attempts, where a camera starting then would lose its first
keyframe, and with it up to a second of frames); one that stops sending for ``read_timeout_s`` is closed and
reopened. FFmpeg's own error text goes into the log (once per distinct text) and
into :meth:`VideoLive.status` ``error``. A file is read once, as fast as it decodes.
"""

from __future__ import annotations

import asyncio
import errno
import logging
import queue
import threading
import time
from collections import deque
from collections.abc import Callable

import av
import numpy as np

from groundstation.runtime.sender_lock import SenderLock
from groundstation.runtime.threads import Handoff, Supervised, in_thread
from groundstation.video.ffmpeg_log import last_ffmpeg_error, route_ffmpeg_log
from groundstation.video.frames import (
    LiveFrame,
    VideoError,
    chroma_planes,
    decoder,
    ffmpeg_reason,
    luma,
    put_until,
)
from groundstation.video.inputs import VideoInput, parse_video_input
from groundstation.video.mpegts import TsDepacketizer
from groundstation.video.rtp import Depacketizer
from groundstation.video.udp import DatagramInput
from groundstation.video.zenoh_video import ZenohVideoInput
from localizer.clock import ClockMap
from localizer.tracking.colour import Chroma

log = logging.getLogger("skyfix.video")

OPEN_TIMEOUT_S = 2.0  # an open waits this long for the stream
RTSP_OPEN_TIMEOUT_S = 5.0
RETRY_MIN_S = 0.25  # first wait after a failed open; doubles up to retry_max_s
CLOCK_WINDOW_S = 30.0  # the stream-to-station offset follows drift over this window
STATS_FRAMES = 300  # frames the status's delay percentiles are taken over
# packets read but not yet decoded, at most (4 s at 30 fps); then reading waits
PACKET_BACKLOG = 120
BEHIND_PACKETS = 2  # live: with more than this many packets waiting, decoded frames are skipped
# live: with more than this many waiting (1 s at 30 fps), skip to the newest keyframe
CATCH_UP_PACKETS = 30
HANDOFF_FRAMES = 8  # frames decoded but not yet taken by the event loop
READER_STOP_S = 0.3  # a stop waits this long for the reader thread
RTP_KINDS = ("sdp", "rtsp")  # inputs FFmpeg depacketizes from RTP (rtp://: skyfix itself, .rtp)


_END = object()  # the demuxer's last word: the stream or file ended


def _demux(container, stream, packets: queue.Queue, done: threading.Event) -> None:
    """Read ``stream``'s packets into ``packets`` as ``(packet, t_recv)``, then :data:`_END` or the exception that
    ended the reading; until ``done``."""
    try:
        for packet in container.demux(stream):
            if not put_until(packets, (packet, time.time()), done):
                return
        put_until(packets, _END, done)
    except (av.error.FFmpegError, OSError) as e:
        put_until(packets, e, done)


def frame_images(frame: av.VideoFrame) -> tuple[np.ndarray, np.ndarray | None, Chroma | None]:
    """A decoded frame's images as they are handed over (:class:`LiveFrame`): ``image`` in BGR (the listeners', the
    page's), ``grey``, its luma plane (what a tracker of grey levels reads), and its chroma planes (the colour the
    tracker's check reads); None for a pixel format other than yuv420p."""
    return frame.to_ndarray(format="bgr24"), luma(frame), chroma_planes(frame)


def catch_up(packets: queue.Queue, waiting: deque) -> tuple[int, float | None]:
    """A live decoder far behind: the queued packets moved into ``waiting`` (up to :data:`PACKET_BACKLOG`), those
    before the newest keyframe among them dropped (its decoding needs none of them); (how many were dropped, the
    last dropped one's ``t_recv``)."""
    while len(waiting) < PACKET_BACKLOG:
        try:
            waiting.append(packets.get_nowait())
        except queue.Empty:
            break
    newest = max(
        (i for i, item in enumerate(waiting) if isinstance(item, tuple) and item[0].is_keyframe),
        default=0,
    )
    t_last = None
    for _ in range(newest):  # packets all (the demuxer's last word comes after every packet)
        t_last = waiting.popleft()[1]
    return newest, t_last


def _drain(packets: queue.Queue) -> None:
    while True:
        try:
            packets.get_nowait()
        except queue.Empty:
            return


def _reason(source: VideoInput, e: Exception, t_try: float, timeout_s: float) -> str:
    """One line saying why ``source`` could not be read, in FFmpeg's words where it has any."""
    code = getattr(e, "errno", None)
    if code == errno.EADDRINUSE:
        return f"{source.url}: UDP port {source.port} is already in use by another program"
    if isinstance(e, (av.error.ExitError, TimeoutError)):
        text = f"{source.url}: nothing received for {timeout_s:g} s"
    else:
        text = f"{source.url}: {ffmpeg_reason(e)}"
    said = last_ffmpeg_error(t_try)
    return f"{text} (ffmpeg {said})" if said and said not in text else text


class VideoLive:
    """Worker owning the video link; ``on_frame(LiveFrame)`` is called on the event loop."""

    def __init__(
        self,
        url: str,
        latency_s: float | None,
        on_frame: Callable[[LiveFrame], None],
        expected_size: tuple[int, int] | None = None,
        open_timeout_s: float | None = None,
        read_timeout_s: float = 2.0,
        retry_max_s: float = 1.0,
        session=None,  # the service's Zenoh session, for a zenoh: input
    ):
        self.source = parse_video_input(url)
        self.session = session
        if open_timeout_s is None:  # an RTSP session takes several round trips to set up
            open_timeout_s = RTSP_OPEN_TIMEOUT_S if self.source.kind == "rtsp" else OPEN_TIMEOUT_S
        self.url = url
        self.latency_s = latency_s
        self.on_frame = on_frame
        self.expected_size = expected_size
        self.open_timeout_s = open_timeout_s
        self.read_timeout_s = read_timeout_s
        self.retry_max_s = retry_max_s
        self.frames = 0
        self.connects = 0
        self.decode_errors = 0
        self.skipped_behind = 0
        self.caught_up = 0  # times the decoder skipped to a keyframe to catch up
        self.backlog = 0
        self.state = "starting"
        self.last_recv: float | None = None
        self.last_error: str | None = None
        self.clock: ClockMap | None = None
        self._late_s: deque[float] = deque(maxlen=STATS_FRAMES)  # t_recv − t_slot
        self._decode_s: deque[float] = deque(maxlen=STATS_FRAMES)  # t_recv → frame handed over
        self.handoff: Handoff | None = None
        self.reader = Supervised("video", self._read)
        self._datagrams: DatagramInput | None = None  # the open rtp:// or udp:// input
        # rtp://, udp://: the one sender taken, kept across its connections (groundstation.runtime.sender_lock)
        src = self.source
        self.sender_lock = (
            SenderLock(src.peer, not src.any_sender, relock_s=read_timeout_s)
            if src.kind in ("rtp", "udp", "zenoh")
            else None
        )
        self._datagrams_before = {
            "lost_packets": 0,
            "dropped_frames": 0,
            "bad_packets": 0,
        }  # its predecessors'

    async def run(self) -> None:
        route_ffmpeg_log()
        self.handoff = Handoff(asyncio.get_running_loop(), self.on_frame, HANDOFF_FRAMES)
        self.reader.start()
        try:
            await asyncio.Event().wait()
        finally:
            self.handoff.close()
            # a reader between packets ends at once; one blocked in FFmpeg is left to end by itself (module doc)
            await in_thread(self.reader.join, READER_STOP_S, name="video stop")

    def _read(self, stop: threading.Event) -> None:
        backoff = RETRY_MIN_S
        while not stop.is_set():
            t_try = time.time()
            try:
                if self.source.port_in_use():
                    raise OSError(errno.EADDRINUSE, "port in use")
                container = self._open()
            except (av.error.FFmpegError, OSError, VideoError) as e:
                self.state = "waiting"
                self._error(
                    f"{self.url}: {e}"
                    if isinstance(e, VideoError)
                    else _reason(self.source, e, t_try, self.open_timeout_s)
                )
                if not isinstance(
                    e, (av.error.ExitError, TimeoutError)
                ):  # a timeout already waited: listen again
                    stop.wait(backoff)
                    backoff = min(2.0 * backoff, self.retry_max_s)
                continue
            frames_before = self.frames
            self.state = "open"  # opened; receiving from the first packet on
            try:
                ended = self._receive(container, stop)
            except (av.error.FFmpegError, OSError) as e:
                ended = _reason(self.source, e, t_try, self.read_timeout_s)
            except VideoError as e:
                ended = str(e)
            finally:
                container.close()
                if self._datagrams is not None:
                    self._datagrams_before = self._datagram_counts()
                    self._datagrams = None
            if ended is None:  # the end of a file, or stopping
                self.state = "ended" if not stop.is_set() else "stopped"
                return
            self.state = "waiting"
            self._error(f"{ended}; reconnecting")
            if self.frames > frames_before:
                backoff = RETRY_MIN_S
            stop.wait(RETRY_MIN_S)

    def _open(self):
        src = self.source
        if src.kind in ("rtp", "udp"):
            depacketizer = (
                Depacketizer(src.codec, src.payload_type) if src.kind == "rtp" else TsDepacketizer()
            )
            self._datagrams = DatagramInput(
                src.file,
                src.port,
                depacketizer,
                self.open_timeout_s,
                self.read_timeout_s,
                self.sender_lock,
            )
            return self._datagrams
        if src.kind == "zenoh":
            if self.session is None:
                raise VideoError(f"{self.url}: a zenoh: video needs the service's Zenoh session")
            self._datagrams = ZenohVideoInput(
                self.session, src.file, self.open_timeout_s, self.read_timeout_s, self.sender_lock
            )
            return self._datagrams
        return av.open(
            src.file,
            format=src.format,
            container_options=src.options,
            timeout=(self.open_timeout_s, self.read_timeout_s),
        )

    def _receive(self, container, stop: threading.Event) -> str | None:
        """Demux (in a thread of its own) and decode until the stream ends; a reason to reconnect, or None at a
        file's end or a stop. The demuxing thread has ended when this returns: the container can be closed."""
        if not container.streams.video:
            raise VideoError(f"{self.url}: no video stream in it")
        stream = container.streams.video[0]
        ctx = decoder(stream, low_delay=True)
        packets: queue.Queue = queue.Queue(maxsize=PACKET_BACKLOG)
        done = threading.Event()
        demuxer = threading.Thread(
            target=_demux, args=(container, stream, packets, done), name="video-demux", daemon=True
        )
        demuxer.start()
        ends_at_next = self.source.kind in RTP_KINDS and ctx.name in ("h264", "hevc")
        try:
            return self._decode(ctx, float(stream.time_base), packets, stop, ends_at_next)
        finally:
            done.set()
            while (
                demuxer.is_alive()
            ):  # it waits on a full queue, or on the network for read_timeout_s at most
                _drain(packets)
                demuxer.join(0.05)

    def _decode(
        self, ctx, tb: float, packets: queue.Queue, stop: threading.Event, ends_at_next: bool
    ) -> str | None:
        """Decode and hand over frames. ``ends_at_next``: the demuxer hands an access unit over when the next
        one's first packet comes (FFmpeg's H.264/H.265 RTP depacketizer ignores the marker bit that ends a
        frame, and its parser waits for the next frame's start): an access unit's own first packet then
        came when the one before it was handed over, and its slot is timed by that."""
        self.clock = clock = ClockMap(window_s=CLOCK_WINDOW_S)
        first_recv: dict[int, float] = {}
        connected = False
        # ends_at_next: when the previous access unit was handed over
        previous_out: float | None = None
        waiting: deque = deque()  # taken from the queue by a catch-up, not yet decoded
        while not stop.is_set():
            if self.source.live and len(waiting) + packets.qsize() > CATCH_UP_PACKETS:
                dropped, t_last = catch_up(packets, waiting)
                if dropped:
                    self.skipped_behind += dropped
                    previous_out = t_last if ends_at_next else previous_out
                    if not self.caught_up:
                        log.warning(
                            "video: the decoder is %d frames behind the stream: skipped to the newest keyframe "
                            "(again whenever it is; counted in skipped_behind)",
                            dropped,
                        )
                    self.caught_up += 1
            try:
                item = waiting.popleft() if waiting else packets.get(timeout=0.1)
            except queue.Empty:
                continue
            if isinstance(item, BaseException):
                raise item
            if item is _END:
                break
            packet, t_recv = item
            if not connected:
                connected = True
                self._connected()
            if packet.pts is not None:
                t_first: float | None = t_recv
                if ends_at_next:
                    t_first, previous_out = previous_out, t_recv
                if t_first is not None:
                    clock.add(packet.pts * tb, t_first)
                    first_recv.setdefault(packet.pts, t_first)
            try:
                decoded = ctx.decode(packet)
            except av.error.InvalidDataError:
                self.decode_errors += 1
                continue
            self.backlog = len(waiting) + packets.qsize()
            # the run's first frame is handed over however late: [tracker] init_bbox belongs to it (the pipeline
            # never drops it either), and a box put on a later frame, the UUV moved, is pixels off it in every fix
            behind = self.source.live and self.backlog > BEHIND_PACKETS and self.frames > 0
            for frame in decoded:
                t_first = first_recv.pop(frame.pts, t_recv)
                if behind:
                    self.skipped_behind += 1
                elif frame.pts is None or clock.offset_s is not None:
                    self._hand_over(frame, tb, clock, t_first)
                # else: RTP's first access unit, whose first packet's arrival (and so its time) is unknown
            while len(first_recv) > 64:  # packets whose frame never came out (undecodable)
                del first_recv[next(iter(first_recv))]
        else:
            return None  # stopping
        if not self.source.live:
            log.info("video: end of file %s after %d frames", self.url, self.frames)
            return None
        return f"{self.url}: the stream ended after frame {self.frames - 1}"

    def _connected(self) -> None:
        """The first packet of a connection."""
        self.connects += 1
        self.state = "receiving"
        self.last_error = None
        log.info("video: receiving %s (connection %d)", self.url, self.connects)

    def _hand_over(self, frame, tb: float, clock: ClockMap, t_recv: float) -> None:
        image, grey, chroma = frame_images(frame)
        h, w = image.shape[:2]
        if self.expected_size is not None and (w, h) != tuple(self.expected_size):
            ew, eh = self.expected_size
            raise VideoError(
                f"{self.url}: frames are {w}x{h} pixels, the calibration's camera is {ew}x{eh}"
            )
        t_slot = float(clock.to_arrival(frame.pts * tb)) if frame.pts is not None else t_recv
        latency_s = self.latency_s  # read once: the event loop may set it meanwhile (auto)
        live = LiveFrame(
            self.frames,
            t_slot - (latency_s or 0.0),
            t_recv,
            image,
            t_slot,
            latency_s is not None,
            grey=grey,
            chroma=chroma,
        )
        self.frames += 1
        self.last_recv = t_recv
        self._late_s.append(t_recv - t_slot)
        self._decode_s.append(time.time() - t_recv)
        self.handoff.put(live)

    def _error(self, why: str) -> None:
        if why != self.last_error:
            log.warning("video: %s", why)
        self.last_error = why

    def _datagram_counts(self) -> dict:
        """What the network lost on ``rtp://`` or ``udp://``, since the start (all connections)."""
        if self._datagrams is None:
            return dict(self._datagrams_before)
        d = self._datagrams.depacketizer
        now = {
            "lost_packets": d.lost_packets,
            "dropped_frames": d.dropped_units,
            "bad_packets": d.bad_packets,
        }
        return {k: self._datagrams_before[k] + now[k] for k in now}

    def status(self, now: float) -> dict:
        age = None if self.last_recv is None else round(max(0.0, now - self.last_recv), 3)

        def p(values, q):
            return round(float(np.percentile(values, q)) * 1000.0, 1) if values else None

        late, dec = list(self._late_s), list(self._decode_s)
        offset = self.clock.offset_s if self.clock is not None else None
        return {
            "url": self.url,
            "kind": self.source.kind,
            "state": self.state,
            "frames": self.frames,
            "connects": self.connects,
            "age_s": age,
            "decode_errors": self.decode_errors,
            "backlog": self.backlog,
            "skipped_behind": self.skipped_behind,
            "latency_ms": None if self.latency_s is None else round(self.latency_s * 1000.0, 1),
            "arrival_after_slot_ms": {"p50": p(late, 50), "p99": p(late, 99)},
            "decode_ms": {"p50": p(dec, 50), "p99": p(dec, 99)},
            "stream_offset_s": None if offset is None else round(offset, 6),
            "error": self.last_error,
            **self.reader.status(),
            "handoff": self.handoff.status() if self.handoff else None,
            "rtp": self._datagram_counts() if self.source.kind == "rtp" else None,
            "mpegts": self._datagram_counts() if self.source.kind == "udp" else None,
            "zenoh": self._datagram_counts() if self.source.kind == "zenoh" else None,
            "sender": self.sender_lock.status() if self.sender_lock is not None else None,
        }

"""The UAV's video, live: frames with their exposure time, reconnecting by itself.

A reader thread opens the URL with :func:`groundstation.video.open_video`
(FFmpeg: ``udp://127.0.0.1:5600`` MPEG-TS, an ``.sdp`` for RTP, ``rtsp://``, a
file) and hands each decoded frame to the event loop. A frame's exposure time is
its receive time minus ``latency_s`` (the camera → decoder delay, measured once
per setup; ``--video-latency-ms``). Frames that come out of a buffer (after
FFmpeg's probing at connection, or after a stall) are marked ``buffered``: their
time is unknown, so they get no fix. When the stream stops (read timeout) or
cannot be opened, the reader closes it and retries every ``retry_s`` until it
comes back (a read that fails at once is an undecodable frame, counted and
skipped); frame numbers keep counting across reconnects. A file (not a URL) is
read once, as fast as it decodes.
"""

from __future__ import annotations

import asyncio
import logging
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..video import VideoError, open_video

log = logging.getLogger("skyfix.video")

# FFmpeg probes a UDP stream for several seconds by default, then delivers the probed frames
# in a burst. Probing must see a keyframe, or OpenCV decodes nothing on that connection:
# 1 s suits cameras sending a keyframe at least every second.
UDP_CAPTURE_OPTIONS = "analyzeduration;1000000|probesize;5000000"
MAX_QUICK_FAILURES = 30  # undecodable frames in a row before reconnecting
MIN_OPEN_TIMEOUT_MS = 10_000  # an open interrupted while probing leaves a capture that decodes nothing
STALL_FRAMES = 4  # a frame decoded this many frame intervals after the previous one may have waited in the decoder


@dataclass
class LiveFrame:
    """A received frame: running index, exposure and receive times (UNIX s), BGR image.

    ``buffered``: the frame may have waited in a buffer (the first frame of a
    connection, one decoded less than half a frame interval after the previous
    one, or one decoded more than :data:`STALL_FRAMES` intervals after it: the
    decoder holds frames back and releases them when the stream stalls or stops),
    so its receive time is not when it arrived and its exposure time is unknown;
    such frames only keep the tracker going.
    """

    index: int
    t_unix: float
    t_recv: float
    image: np.ndarray
    buffered: bool = False


class VideoLive:
    """Worker owning the video link; ``on_frame(LiveFrame)`` is called on the event loop."""

    def __init__(self, url: str, latency_s: float, on_frame: Callable[[LiveFrame], None],
                 expected_size: tuple[int, int] | None = None, read_timeout_ms: int = 2000, retry_s: float = 0.5):
        self.url = url
        self.latency_s = latency_s
        self.on_frame = on_frame
        self.expected_size = expected_size
        self.read_timeout_ms = read_timeout_ms
        self.retry_s = retry_s
        self.frames = 0
        self.connects = 0
        self.decode_errors = 0
        self.buffered = 0
        self.last_recv: float | None = None
        self.last_error: str | None = None
        self._stop = threading.Event()

    async def run(self) -> None:
        loop = asyncio.get_running_loop()
        if self.url.startswith("udp://"):
            os.environ.setdefault("OPENCV_FFMPEG_CAPTURE_OPTIONS", UDP_CAPTURE_OPTIONS)
        reader = threading.Thread(target=self._read, args=(loop,), name="video", daemon=True)
        reader.start()
        try:
            await asyncio.Event().wait()
        finally:
            self._stop.set()
            await asyncio.to_thread(reader.join, self.read_timeout_ms / 1000.0 + 3.0)

    def _read(self, loop: asyncio.AbstractEventLoop) -> None:
        while not self._stop.is_set():
            try:
                video = open_video(self.url, self.expected_size,
                                   open_timeout_ms=max(self.read_timeout_ms, MIN_OPEN_TIMEOUT_MS),
                                   read_timeout_ms=self.read_timeout_ms, threads=1, max_bad_reads=0)
            except VideoError as e:
                self._error(str(e))
                self._stop.wait(self.retry_s)
                continue
            self.connects += 1
            self.last_error = None
            log.info("video: receiving %s (connection %d)", self.url, self.connects)
            fps = video.fps if 1.0 <= video.fps <= 240.0 else 30.0
            try:
                quick_failures = 0
                t_prev = None
                while not self._stop.is_set():
                    t_read = time.monotonic()
                    frame = video.read()
                    t_recv = time.time()
                    if frame is None:
                        if "://" not in self.url:
                            log.info("video: end of file %s after %d frames", self.url, self.frames)
                            return
                        # a read failing at once is a frame FFmpeg could not decode (joined mid-GOP, lost
                        # packets); only a read that waited for the timeout means the stream stopped
                        quick = time.monotonic() - t_read < self.read_timeout_ms / 2000.0
                        if quick and quick_failures < MAX_QUICK_FAILURES:
                            quick_failures += 1
                            self.decode_errors += 1
                            continue
                        self._error(f"{self.url}: stream stopped after frame {self.frames - 1}; reconnecting")
                        break
                    quick_failures = 0
                    # the first frame of a connection may have waited through FFmpeg's probing, and the
                    # first after a stall in the decoder (H.264 with B-frames holds frames back)
                    gap_s = None if t_prev is None else t_recv - t_prev
                    buffered = gap_s is None or gap_s < 0.5 / fps or gap_s > STALL_FRAMES / fps
                    t_prev = t_recv
                    self.buffered += buffered
                    live = LiveFrame(self.frames, t_recv - self.latency_s, t_recv, frame.image, buffered)
                    self.frames += 1
                    self.last_recv = t_recv
                    try:
                        loop.call_soon_threadsafe(self.on_frame, live)
                    except RuntimeError:  # loop closed: shutting down
                        return
            except VideoError as e:
                self._error(str(e))
            finally:
                video.close()

    def _error(self, why: str) -> None:
        if why != self.last_error:
            log.warning("video: %s", why)
        self.last_error = why

    def status(self, now: float) -> dict:
        age = None if self.last_recv is None else round(now - self.last_recv, 3)
        return {"url": self.url, "frames": self.frames, "connects": self.connects, "age_s": age,
                "decode_errors": self.decode_errors, "buffered": self.buffered,
                "error": self.last_error}

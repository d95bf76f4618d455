"""What the video readers hand on: frames (a file's :class:`VideoFrame`, a live stream's :class:`LiveFrame`),
their one error type, and what both readers share: the decoder's set-up, a bounded hand-over."""

from __future__ import annotations

import queue
import threading
from dataclasses import dataclass, field

import av
import numpy as np


class VideoError(RuntimeError):
    """A video that cannot be read as required; the message is one line."""


@dataclass
class VideoFrame:
    """One decoded frame: ``index`` 0-based (see the module doc), ``image`` BGR uint8 (or, read ``grey``, the luma
    plane (H, W) uint8 of a yuv420p video: see :func:`~groundstation.video.file.open_video`), ``t_s`` its
    presentation time in seconds from the video's first frame."""

    index: int
    image: np.ndarray
    t_s: float = 0.0
    # read grey: the decoded frame whose luma plane ``image`` is a view of
    decoded: av.VideoFrame | None = None
    # the conversion of ``decoded``, once made (the UUVs measured in one frame share it)
    _bgr: np.ndarray | None = field(default=None, repr=False, compare=False)

    def bgr(self) -> np.ndarray:
        """The frame in BGR uint8: ``image``, or converted from the decoded frame (as a frame not read grey is),
        converted once per frame (read-only: it is shared)."""
        if self.decoded is None:
            return self.image
        if self._bgr is None:
            self._bgr = self.decoded.to_ndarray(format="bgr24")
            self._bgr.flags.writeable = False
        return self._bgr


def ffmpeg_reason(e: Exception) -> str:
    """FFmpeg's own words for a failure (PyAV's message without the URL it repeats)."""
    text = getattr(e, "strerror", None) or str(e)
    return str(text).splitlines()[0] if text else type(e).__name__


@dataclass
class LiveFrame:
    """A received frame (UNIX seconds on the station clock).

    ``t_unix`` its exposure: ``t_slot`` − the configured glass-to-first-packet latency;
    ``t_recv`` when its first packet was read from the network (before decoding);
    ``t_slot`` its stream slot: its PTS on the station clock (least arrival − PTS), ≤ ``t_recv``;
    ``aligned`` False while the latency is not known yet (``auto`` before its estimate settled);
    ``t_recv_mono`` ``t_recv`` on the monotonic clock (s; None: not known yet, the pipeline sets it on arrival).
    """

    index: int
    t_unix: float
    t_recv: float
    image: np.ndarray
    t_slot: float | None = None
    aligned: bool = True
    t_recv_mono: float | None = None


def put_until(q: queue.Queue, item, stop: threading.Event) -> bool:
    """Put ``item`` into the bounded ``q``, waiting for room, unless ``stop`` is set first (then False)."""
    while not stop.is_set():
        try:
            q.put(item, timeout=0.1)
            return True
        except queue.Full:
            continue
    return False


def decoder(stream, *, threads: int = 0, frame_threads: bool = False, low_delay: bool = False):
    """The video ``stream``'s codec context, set up as the readers decode: ``threads`` threads (0: FFmpeg's choice),
    slice threads, and with ``frame_threads`` frame threads too (a file read for throughput: a damaged packet can then
    take the frames in flight with it, see :mod:`groundstation.video.file`); ``low_delay`` for a live stream (each
    frame out as soon as it is decoded, no frame threads)."""
    ctx = stream.codec_context
    ctx.thread_type = "AUTO" if frame_threads else "SLICE"
    ctx.thread_count = int(threads)
    if low_delay:
        ctx.flags |= av.codec.context.Flags.low_delay
    return ctx

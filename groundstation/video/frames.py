"""What the video readers hand on: frames (a file's :class:`VideoFrame`, a live stream's :class:`LiveFrame`),
their one error type, and what both readers share: the decoder's set-up, a bounded hand-over."""

from __future__ import annotations

import queue
import threading
from dataclasses import dataclass, field

import av
import numpy as np

from localizer.tracking.colour import Chroma


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
    _regions: BgrRegions | None = field(default=None, repr=False, compare=False)

    def bgr(self) -> np.ndarray:
        """The frame in BGR uint8: ``image``, or converted from the decoded frame (as a frame not read grey is),
        converted once per frame (read-only: it is shared)."""
        if self.decoded is None:
            return self.image
        if self._bgr is None:
            self._bgr = self.decoded.to_ndarray(format="bgr24")
            self._bgr.flags.writeable = False
        return self._bgr

    def bgr_regions(self) -> BgrRegions | np.ndarray:
        """The frame in BGR uint8 where it is read (:class:`BgrRegions`; the UUVs measured in one frame share it), or
        ``image`` where that is BGR already."""
        if self.decoded is None:
            return self.image
        if self._regions is None:
            planes = [plane_array(p) for p in self.decoded.planes]
            self._regions = BgrRegions(planes, (self.decoded.colorspace, self.decoded.color_range))
        return self._regions

    def chroma(self) -> Chroma | None:
        """The frame's colour as the tracker's check reads it (:class:`~localizer.tracking.colour.Chroma`): the
        decoded frame's chroma planes, or ``image``'s when that is BGR."""
        planes = None if self.decoded is None else [plane_array(p) for p in self.decoded.planes]
        return Chroma.of(self.image, planes)


def plane_array(plane) -> np.ndarray:
    """A view (height, width) of an FFmpeg frame's plane, without its rows' padding."""
    return np.frombuffer(plane, np.uint8).reshape(plane.height, plane.line_size)[:, : plane.width]


def luma(frame: av.VideoFrame) -> np.ndarray | None:
    """A view (H, W) of a yuv420p frame's luma plane as decoded (what a tracker of grey levels reads, no conversion
    and no copy), None for other pixel formats (read in BGR)."""
    return plane_array(frame.planes[0]) if frame.format.name == "yuv420p" else None


def chroma_planes(frame: av.VideoFrame) -> Chroma | None:
    """A yuv420p frame's chroma planes as decoded (views, no conversion), None for other pixel formats."""
    if frame.format.name != "yuv420p":
        return None
    return Chroma.of(None, [plane_array(p) for p in frame.planes])


#: A region :class:`BgrRegions` converts reaches this far (pixels) beyond the rows and columns read: the windows one
#: height-from-size measurement reads lie around one vehicle.
REGION_MARGIN_PX = 48


class BgrRegions:
    """A yuv420p frame in BGR uint8, converted where it is read: ``regions[rows, cols]`` (two slices without a step)
    is what the whole frame's conversion holds there, converted by FFmpeg with the region around it
    (:data:`REGION_MARGIN_PX` beyond, on even pixels) the first time it is read; ``shape`` is the whole frame's.

    The height from size reads a few windows around each vehicle: converting them costs a fraction of converting the
    whole frame (swscale's work is per pixel). FFmpeg's conversion of a same-sized yuv420p frame takes each pixel's
    own chroma sample, so a region cut on even pixels converts to the whole frame's bytes there
    (``tests/test_video_bgr_regions.py``). A frame of odd height it converts otherwise (a region's bytes differ): a
    frame of odd size is converted whole. ``planes``: Y (H, W), U and V; ``colour``: the frame's (colorspace,
    color_range)."""

    ndim = 3

    def __init__(self, planes: list[np.ndarray], colour: tuple[int, int]):
        self.planes, self.colour = planes, colour
        self.shape = (*planes[0].shape, 3)
        self._converted: list[tuple[int, int, np.ndarray]] = []  # (first row, first column, BGR)

    def __getitem__(self, key: tuple[slice, slice]) -> np.ndarray:
        rows, cols = key
        if rows.step not in (None, 1) or cols.step not in (None, 1):
            raise IndexError("BgrRegions: slices without a step only")
        y0, y1, _ = rows.indices(self.shape[0])
        x0, x1, _ = cols.indices(self.shape[1])
        for ry, rx, bgr in self._converted:
            if ry <= y0 and rx <= x0 and y1 <= ry + bgr.shape[0] and x1 <= rx + bgr.shape[1]:
                return bgr[y0 - ry : y1 - ry, x0 - rx : x1 - rx]
        ry, rx, bgr = self._convert(y0, y1, x0, x1)
        self._converted.append((ry, rx, bgr))
        return bgr[y0 - ry : y1 - ry, x0 - rx : x1 - rx]

    def _convert(self, y0: int, y1: int, x0: int, x1: int) -> tuple[int, int, np.ndarray]:
        """The region around rows ``y0:y1`` and columns ``x0:x1`` converted: (its first row, first column, BGR)."""
        H, W = self.shape[:2]
        m = REGION_MARGIN_PX
        ry, rx = max(0, y0 - m) // 2 * 2, max(0, x0 - m) // 2 * 2
        ry1, rx1 = min(H, (y1 + m + 1) // 2 * 2), min(W, (x1 + m + 1) // 2 * 2)
        if H % 2 or W % 2:  # swscale converts a frame of odd size otherwise: whole
            ry, rx, ry1, rx1 = 0, 0, H, W
        frame = av.VideoFrame(rx1 - rx, ry1 - ry, "yuv420p")
        frame.colorspace, frame.color_range = self.colour
        cuts = [(ry, ry1, rx, rx1)] + [(ry // 2, (ry1 + 1) // 2, rx // 2, (rx1 + 1) // 2)] * 2
        for plane, source, (a, b, c, d) in zip(frame.planes, self.planes, cuts, strict=True):
            np.copyto(plane_array(plane), source[a:b, c:d])
        bgr = frame.to_ndarray(format="bgr24")
        bgr.flags.writeable = False
        return ry, rx, bgr


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
    ``t_recv_mono`` ``t_recv`` on the monotonic clock (s; None: not known yet, the pipeline sets it on arrival);
    ``grey`` the decoded frame's luma plane (:func:`luma`) beside ``image`` (BGR), None where it has none (another
    pixel format, a frame not from a decoder): a tracker of grey levels reads it, as ``skyfix process`` reads a
    video's (the frame's grey levels are then the same live and offline, where converting ``image`` to grey gives
    other levels). ``chroma``: likewise its chroma planes (:func:`chroma_planes`), the colour the tracker's check
    reads offline (:meth:`colour`).
    """

    index: int
    t_unix: float
    t_recv: float
    image: np.ndarray
    t_slot: float | None = None
    aligned: bool = True
    t_recv_mono: float | None = None
    grey: np.ndarray | None = field(default=None, repr=False)
    chroma: Chroma | None = field(default=None, repr=False)

    def colour(self) -> Chroma | None:
        """The frame's colour as the tracker's check reads it: the decoded chroma planes where handed over, else
        ``image``'s (BGR converted: other values, on sub-sampled colour)."""
        return self.chroma if self.chroma is not None else Chroma.of(self.image)


def live_frame(frame: VideoFrame, t_unix: float) -> LiveFrame:
    """A file's ``frame`` handed over as the live reader hands a stream's (exposure, arrival and slot at ``t_unix``):
    in BGR and, where it was read grey, its luma plane beside it (replays of a file through the live pipeline)."""
    decoded = frame.decoded is not None
    return LiveFrame(
        frame.index,
        t_unix,
        t_unix,
        frame.bgr(),
        t_unix,
        grey=frame.image if decoded else None,
        chroma=frame.chroma() if decoded else None,
    )


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

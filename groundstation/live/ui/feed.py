"""The video for the web page: tracked frames as JPEG with their fix's overlay, only while a page watches.

A frame is shown once its fix is out (:meth:`VideoFeed.on_fix`, a pipeline sink), so
its overlay is that frame's own: the tracker's box, the window the telemetry had it
searched in, the status word and the fix's accuracy. At most ``max_fps`` frames a
second are encoded, one at a time, in the feed's own thread (downscaled to at most
``max_width`` pixels wide with ``cv2.INTER_AREA``, then ``cv2.imencode``), which runs at a
lower priority (nice +10, on Linux) so that on a busy machine the tracker and the video
decoder go first; a frame that comes while one is encoding is skipped, never queued.
Without a watching page nothing is kept and nothing is encoded.

A packet is ``[4 bytes: length of the JSON, big-endian][overlay JSON][JPEG]``; the
overlay's pixels are full-resolution (OpenCV's: the top-left pixel's centre is 0, 0)
and ``frame`` is the running frame number a selection names.

Several UUVs (``[[uuv]]``): still one JPEG per frame. Each UUV's pipeline is a sink of its own
(:attr:`VideoFeed.sinks`); a frame is shown once every UUV's fix for it is out (or that UUV's
pipeline has gone past it, having dropped it: ``"status": "dropped"``), and its overlay has,
besides the first UUV's fields at the top as with one, ``uuvs``: per UUV in the run's order its
``id``, ``colour`` (:mod:`.palette`), ``status``, ``state``, ``origin``, ``h_acc_m``, ``u``, ``v``,
``box`` and ``window``.
"""

from __future__ import annotations

import asyncio
import json
import math
import os
import struct
import threading
import time
from collections import OrderedDict, deque
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor

import cv2
import numpy as np

from groundstation.live.ui.palette import colour
from groundstation.runtime.threads import not_realtime
from localizer.fix import Fix

ENCODER_NICE = 10  # the encoding thread's niceness, above the service's other threads
# frames kept (references) while a page watches: enough for the telemetry wait at 30 fps
KEEP_FRAMES = 16


def lower_priority() -> None:
    """Make the calling thread nicer than the rest of the process (Linux: a thread is a task), never realtime
    (:func:`~groundstation.runtime.threads.not_realtime`); elsewhere a no-op."""
    try:
        not_realtime()
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), ENCODER_NICE)
    except (AttributeError, OSError):
        pass


def encode_jpeg(image: np.ndarray, max_width: int, quality: int) -> bytes:
    """The image as JPEG, downscaled to at most ``max_width`` pixels wide."""
    h, w = image.shape[:2]
    if w > max_width:
        image = cv2.resize(
            image, (max_width, max(1, round(h * max_width / w))), interpolation=cv2.INTER_AREA
        )
    ok, buf = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise ValueError(f"cv2.imencode could not encode a {w}x{h} frame")
    return buf.tobytes()


def _timed(image: np.ndarray, max_width: int, quality: int) -> tuple[bytes, float]:
    """:func:`encode_jpeg` and the CPU time it took this thread (waiting for a core not counted)."""
    t0 = time.thread_time()
    jpeg = encode_jpeg(image, max_width, quality)
    return jpeg, time.thread_time() - t0


def pack(overlay: dict, jpeg: bytes) -> bytes:
    head = json.dumps(overlay, allow_nan=False).encode()
    return struct.pack(">I", len(head)) + head + jpeg


def _num(x) -> float | None:
    return round(float(x), 3) if x is not None and math.isfinite(x) else None


class VideoFeed:
    """Frame listener (``on_frame``), pipeline sink (``on_fix``) and worker (``run``) making the page's video.

    ``target()`` is the tracking session's status (its state word goes into the overlay); with several UUVs,
    ``target`` is each one's ``(id, target)`` in the run's order, and ``sinks[i]`` is the i-th UUV's pipeline sink
    (with one, ``sinks`` is ``[feed]``). The page's server
    (:class:`~groundstation.live.ui.server.WebUi`) takes the feed when it is built and sets ``deliver(packet)``,
    which hands each packet to the watching pages, and ``watching()``, whether any page wants video; until then
    nobody watches.
    """

    def __init__(
        self,
        target: Callable[[], dict] | Sequence[tuple[str, Callable[[], dict]]],
        max_fps: float = 10.0,
        max_width: int = 960,
        quality: int = 80,
    ):
        self.deliver: Callable[[bytes], None] = lambda packet: None
        self.watching: Callable[[], bool] = lambda: False
        several = not callable(target)
        self.ids = [i for i, _ in target] if several else []
        self._targets = [t for _, t in target] if several else [target]
        self.target = self._targets[0]
        self.sinks = [_UuvSink(self, k) for k in range(len(self._targets))] if several else [self]
        self._parts: dict[
            int, dict[int, tuple]
        ] = {}  # several UUVs: frame index → UUV → its (fix, info)
        # several UUVs: the newest frame each one's fix came for
        self._newest = [-1] * len(self._targets)
        self.min_interval_s = 1.0 / max_fps
        self.max_width = max_width
        self.quality = quality
        self.encoded = 0
        self.encode_s: deque[float] = deque(maxlen=100)  # CPU time per frame, the encoding thread's
        self._recent: OrderedDict[int, np.ndarray] = OrderedDict()
        self._pending: tuple[np.ndarray, dict] | None = None
        self._ready = asyncio.Event()
        self._busy = False
        self._last_taken = -math.inf
        self._encoder = ThreadPoolExecutor(
            1, thread_name_prefix="ui-jpeg", initializer=lower_priority
        )

    def on_frame(self, frame) -> None:
        """Every received frame (a reference, no copy), kept only while a page watches."""
        if not self.watching():
            self._recent.clear()
            return
        self._recent[frame.index] = frame.image
        while len(self._recent) > KEEP_FRAMES:
            self._recent.popitem(last=False)

    def on_fix(self, fix: Fix, info) -> None:
        """The one UUV's fix (with several, each UUV's goes to its own sink, :attr:`sinks`)."""
        image = self._image(info.index)
        if image is None:
            return
        overlay = {
            "frame": info.index,
            "t": _num(fix.t_unix),
            **self._part(0, fix, info),
            "width": int(image.shape[1]),
            "height": int(image.shape[0]),
        }
        self._take(image, overlay)

    def _image(self, index: int) -> np.ndarray | None:
        """The frame to show now, if one is to be shown (no page watching, too soon, encoding: None)."""
        if (
            self._busy
            or time.monotonic() - self._last_taken < self.min_interval_s
            or not self.watching()
        ):
            return None
        return self._recent.get(index)

    def _take(self, image: np.ndarray, overlay: dict) -> None:
        self._last_taken = time.monotonic()
        self._pending = (image, overlay)
        self._busy = True
        self._ready.set()

    def _part(self, k: int, fix: Fix | None, info) -> dict:
        """The ``k``-th UUV's part of a frame's overlay (``fix`` None: its pipeline dropped the frame)."""
        target = self._targets[k]()
        return {
            "status": fix.status if fix else "dropped",
            "state": target.get("state"),
            "origin": target.get("origin"),
            "h_acc_m": _num(fix.h_acc_m) if fix else None,
            "u": _num(fix.u) if fix else None,
            "v": _num(fix.v) if fix else None,
            "box": list(info.box) if fix and info.box else None,
            "window": [round(c, 1) for c in info.window] if fix and info.window else None,
        }

    def _uuv_fix(self, k: int, fix: Fix, info) -> None:
        """Several UUVs: the ``k``-th one's fix; a frame goes out once each UUV's fix for it is in (or that UUV's
        pipeline has gone past it)."""
        if not self.watching():
            self._parts.clear()
            return
        self._newest[k] = max(self._newest[k], info.index)
        if info.index in self._recent:
            self._parts.setdefault(info.index, {})[k] = (fix, info)
        while self._parts:
            index = min(self._parts)
            parts = self._parts[index]
            if not all(j in parts or self._newest[j] > index for j in range(len(self._targets))):
                break
            del self._parts[index]
            image = self._image(index)
            if image is None:
                continue
            each = [self._part(j, *parts.get(j, (None, None))) for j in range(len(self._targets))]
            t = next((_num(f.t_unix) for f, _ in parts.values()), None)
            overlay = {
                "frame": index,
                "t": t,
                **each[0],
                "width": int(image.shape[1]),
                "height": int(image.shape[0]),
                "uuvs": [{"id": self.ids[j], "colour": colour(j), **p} for j, p in enumerate(each)],
            }
            self._take(image, overlay)
        while len(self._parts) > KEEP_FRAMES:
            del self._parts[min(self._parts)]

    async def run(self) -> None:
        loop = asyncio.get_running_loop()
        try:
            while True:
                await self._ready.wait()
                self._ready.clear()
                image, overlay = self._pending
                self._pending = None
                try:
                    jpeg, cpu_s = await loop.run_in_executor(
                        self._encoder, _timed, image, self.max_width, self.quality
                    )
                    self.encode_s.append(cpu_s)
                finally:
                    self._busy = False
                self.encoded += 1
                self.deliver(pack(overlay, jpeg))
        finally:
            self._encoder.shutdown(wait=False, cancel_futures=True)

    def status(self) -> dict:
        mean = sum(self.encode_s) / len(self.encode_s) if self.encode_s else None
        return {
            "frames_encoded": self.encoded,
            "encode_ms": None if mean is None else round(mean * 1000.0, 2),
        }


class _UuvSink:
    """One UUV's pipeline sink of a :class:`VideoFeed` of several."""

    def __init__(self, feed: VideoFeed, k: int):
        self.feed = feed
        self.k = k

    def on_fix(self, fix: Fix, info) -> None:
        self.feed._uuv_fix(self.k, fix, info)

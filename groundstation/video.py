"""Reading video through FFmpeg (OpenCV's CAP_FFMPEG backend): files and live URLs.

:func:`open_video` opens a file or a URL (``udp://127.0.0.1:5600``, ``rtsp://…``,
an ``.sdp`` file) and checks the frame size against the calibration's;
:meth:`Video.read` returns one decoded BGR frame with its index, or None at the
end. Every failure the caller should report is a :class:`VideoError` with a
one-line message naming the video and the offending value.

Damaged files: FFmpeg skips a frame it cannot decode and OpenCV reports a failed
read; :meth:`Video.read` retries past up to ``max_bad_reads`` such failures and
numbers frames by their presentation time, so a skipped frame leaves a gap in the
indices instead of shifting every later frame onto the wrong time.
"""

from __future__ import annotations

import math
import os
import queue
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Self

import cv2
import numpy as np

# FFmpeg's own per-packet complaints about damaged files would flood the terminal;
# damage is reported once per video instead (Video.bad_reads, missing frame indices).
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "8")  # AV_LOG_FATAL


class VideoError(RuntimeError):
    """A video that cannot be read as required; the message is one line."""


@dataclass
class VideoFrame:
    """One decoded frame: ``index`` 0-based (by presentation time for files), ``image`` BGR uint8."""

    index: int
    image: np.ndarray


def _is_url(url: str) -> bool:
    return "://" in url


class Video:
    """An open video; use :func:`open_video`. Iterating yields :class:`VideoFrame`."""

    def __init__(self, cap, url: str, expected_size, max_bad_reads: int):
        self._cap = cap
        self.url = url
        self.expected_size = expected_size
        self.max_bad_reads = max_bad_reads
        self.fps = cap.get(cv2.CAP_PROP_FPS)
        self.frame_count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))  # -1 or 0 when unknown (streams)
        self.bad_reads = 0  # failed reads skipped so far
        self._last_index = -1
        self._pts_origin: int | None = None
        self._by_pts = not _is_url(url) and self.fps > 0 and math.isfinite(self.fps)
        self._prefetching: tuple[threading.Event, threading.Thread] | None = None

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) the container declares, in pixels (0 when unknown)."""
        return int(self._cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(self._cap.get(cv2.CAP_PROP_FRAME_HEIGHT))

    def _index(self) -> int:
        """The frame's index from its presentation time (files), else its arrival order."""
        index = self._last_index + 1
        if self._by_pts:
            pos_ms = self._cap.get(cv2.CAP_PROP_POS_MSEC)
            if math.isfinite(pos_ms) and pos_ms >= 0:
                by_pts = round(pos_ms * self.fps / 1000.0)
                if self._pts_origin is None:
                    self._pts_origin = by_pts
                index = max(index, by_pts - self._pts_origin)
        return index

    def read(self) -> VideoFrame | None:
        """The next decodable frame, or None at the end of the video (or after too many bad reads)."""
        failures = 0
        while True:
            try:
                ok, image = self._cap.read()
            except cv2.error:
                ok, image = False, None
            if ok and image is not None:
                break
            failures += 1
            if failures > self.max_bad_reads:
                return None  # the end (failures at the end of a file are not counted as bad)
        self.bad_reads += failures
        self._check_size(image)
        index = self._index()
        self._last_index = index
        return VideoFrame(index, image)

    def _check_size(self, image: np.ndarray) -> None:
        if self.expected_size is None:
            return
        h, w = image.shape[:2]
        if (w, h) != tuple(self.expected_size):
            ew, eh = self.expected_size
            raise VideoError(
                f"{self.url}: frame {self._last_index + 1} is {w}x{h} pixels, the calibration's camera is {ew}x{eh}"
            )

    def __iter__(self) -> Iterator[VideoFrame]:
        while (frame := self.read()) is not None:
            yield frame

    def prefetch(self, depth: int = 8) -> Iterator[VideoFrame]:
        """Iterate with decoding in a background thread (FFmpeg releases the GIL), ``depth`` frames ahead.

        A :class:`VideoError` raised while decoding is re-raised in the caller's thread.
        """
        q: queue.Queue = queue.Queue(maxsize=depth)
        stop = threading.Event()

        def put(item) -> bool:
            """Hand an item over unless the consumer has stopped; False if it has."""
            while not stop.is_set():
                try:
                    q.put(item, timeout=0.1)
                    return True
                except queue.Full:
                    continue
            return False

        def work():
            try:
                for frame in self:
                    if not put(frame):
                        return
                put(None)
            except VideoError as e:
                put(e)

        worker = threading.Thread(target=work, name="video-decode", daemon=True)
        self._prefetching = (stop, worker)
        worker.start()
        try:
            while True:
                try:
                    item = q.get(timeout=0.1)
                except queue.Empty:
                    if stop.is_set() or not worker.is_alive():
                        return  # closed under us
                    continue
                if item is None:
                    return
                if isinstance(item, VideoError):
                    raise item
                yield item
        finally:
            stop.set()
            worker.join()

    def close(self) -> None:
        """Release the decoder (after stopping a :meth:`prefetch` thread still reading from it)."""
        if self._prefetching is not None:
            stop, worker = self._prefetching
            stop.set()
            worker.join()
            self._prefetching = None
        self._cap.release()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def open_video(
    url,
    expected_size: tuple[int, int] | None = None,
    open_timeout_ms: int = 10_000,
    read_timeout_ms: int = 5_000,
    threads: int = 0,
    max_bad_reads: int = 25,
) -> Video:
    """Open a video file or stream with FFmpeg.

    ``expected_size`` (width, height) in pixels, usually the calibration's: a
    different frame size is a :class:`VideoError` (checked on open when the
    container declares it, and on every frame). ``threads`` is FFmpeg's decoding
    thread count (0: FFmpeg chooses). Timeouts apply to network streams.
    """
    url = str(url)
    if not _is_url(url):
        path = Path(url)
        if not path.exists():
            raise VideoError(f"{url}: missing")
        if not path.is_file():
            raise VideoError(f"{url}: not a file")
        if path.stat().st_size == 0:
            raise VideoError(f"{url}: empty file")
    params = [
        cv2.CAP_PROP_N_THREADS, int(threads),
        cv2.CAP_PROP_OPEN_TIMEOUT_MSEC, int(open_timeout_ms),
        cv2.CAP_PROP_READ_TIMEOUT_MSEC, int(read_timeout_ms),
    ]
    if url.endswith(".sdp") and "OPENCV_FFMPEG_CAPTURE_OPTIONS" not in os.environ:
        os.environ["OPENCV_FFMPEG_CAPTURE_OPTIONS"] = "protocol_whitelist;file,rtp,udp"
    cap = cv2.VideoCapture(url, cv2.CAP_FFMPEG, params)
    if not cap.isOpened():
        cap.release()
        why = "FFmpeg cannot open it (truncated, not a video, or no stream)"
        raise VideoError(f"{url}: {why}")
    video = Video(cap, url, expected_size, max_bad_reads)
    w, h = video.size
    if expected_size is not None and w > 0 and h > 0 and (w, h) != tuple(expected_size):
        video.close()
        ew, eh = expected_size
        raise VideoError(f"{url}: frame size {w}x{h} pixels differs from the calibration's camera {ew}x{eh}")
    return video

"""Reading video files through FFmpeg (PyAV): frames with their index and container time.

:func:`open_video` opens a file and checks the frame size against the
calibration's; :meth:`Video.read` returns one decoded BGR frame with its index
and presentation time, or None at the end. Every failure the caller should report
is a :class:`VideoError` with a one-line message naming the video and the
offending value. Live streams are read by :mod:`groundstation.video.live`.

Read ``grey`` (for a reader of the grey levels alone, as the default tracker), a yuv420p frame's ``image``
is a view of its luma plane as decoded: no conversion and no copy, where FFmpeg's conversion to BGR
(swscale, in the decoding thread) added a quarter to the CPU time of decoding (``bench/offline_speed.py``'s
40 s of 1080p: 12.3 CPU-s decoded, 15.1 to BGR, 15.6 to grey); :meth:`VideoFrame.bgr` converts the frames
that need colour, as they would have been (:meth:`VideoFrame.bgr_regions` only the windows read of them). Frames in
other pixel formats are read in BGR, as without ``grey``.

A frame's index comes from the container's timestamps, found by reading every
packet's presentation time first (demuxing only, no decoding):

- regular timestamps (a camera's or an encoder's constant frame rate, where
  every step is a whole number of frame periods): index = (pts − first pts) /
  period, so a frame lost to damage leaves a gap in the indices instead of
  shifting every later frame onto the wrong time;
- irregular timestamps (a live recording, stamped as the frames arrived): index
  = the frame's rank in presentation order;
- given the session's frame indices (``video_frames.csv``'s ``frame`` column), when
  the video holds exactly that many frames: the n-th frame is the n-th row's. A
  live recording is one: its timestamps are the camera's regular slots, with a gap
  wherever the service skipped frames (its decoder behind), and every frame it kept
  has its row.
Decoding is throughput work: frame and slice threads; read ``grey``, at least :data:`GREY_FRAME_THREADS` frames
in flight (FFmpeg's own choice, one more than the cores, leaves them partly idle on its frames' dependencies on each
other; a BGR read keeps FFmpeg's count: its conversion, in the reading thread, is then the bottleneck, and more
decoding threads take the cores from it). A packet FFmpeg cannot decode fails the
frames decoded beside it in the other frame threads too (PyAV raises before handing them over, and
at the end no more can be drained), so at the first failure the file is opened again and decoded
with slice threads only from the keyframe before the first frame not yet handed on (the frames
handed on already are skipped): every frame the slice-threaded decoder can decode is delivered,
with its own index and time. Each packet that fails to decode is then skipped and counted
(:attr:`Video.bad_reads`).

:func:`decoding_early` starts decoding a file before its reader is ready (``skyfix process`` while it reads the
session, with a core idle): the reader's :func:`open_video` takes that video as it is and reads on from its first
frame, numbered by the ``indices`` given then (frames are numbered in the reader's thread, as it takes them).
"""

from __future__ import annotations

import contextlib
import math
import os
import queue
import threading
from collections.abc import Iterator, Sequence
from fractions import Fraction
from pathlib import Path
from typing import Self

import av
import numpy as np

from groundstation.video.ffmpeg_log import route_ffmpeg_log
from groundstation.video.frames import (
    VideoError,
    VideoFrame,
    decoder,
    ffmpeg_reason,
    luma,
    put_until,
)

#: A step between timestamps within this share of a whole number of periods counts as regular.
REGULAR_TOLERANCE = 0.05
#: Frame threads decoding a file read grey, at least (FFmpeg's cores + 1 when more). ``bench/offline_speed.py``'s
#: videos on 2 cores: 1080p 1200 frames 4.2-4.8 s with FFmpeg's 3 (1.6 cores busy), 3.0-3.6 s with 8-16 (1.9); 4K
#: 300 frames 3.3-3.7 s with 3, 2.7-2.9 s with 8 (peak RSS 228 → 364 MB; 535 MB with 16). Read in BGR, 8 were
#: slower than 3 (``bench/import_long.py``'s 4K video, 600 frames: 3.7-4.9 s → 5.5-6.3 s).
GREY_FRAME_THREADS = 8
#: A video decoding early (:func:`decoding_early`) keeps at most about this many bytes of frames ahead of its reader
#: (yuv420p 1080p: 67 frames, 4K: 16).
EARLY_BYTES = 200 * 2**20
#: A video decoding early keeps at least this many frames ahead (the prefetching reader's default).
EARLY_FRAMES = 8

#: The videos decoding early (:func:`decoding_early`), by (resolved path, grey), until :func:`open_video` takes one.
_early: dict[tuple[Path, bool], _Early] = {}


def frame_indices(pts: list[int], indices: Sequence[int] | None = None) -> dict[int, int]:
    """Presentation timestamps (any order, in stream ticks) → 0-based frame index (see the module doc);
    ``indices``: the session's frame indices, one per row, in order."""
    ordered = sorted(set(pts))
    if indices is not None and len(indices) == len(ordered):
        return {p: int(i) for p, i in zip(ordered, indices, strict=True)}
    if len(ordered) < 2:
        return {p: i for i, p in enumerate(ordered)}
    steps = np.diff(ordered)
    period = float(np.min(steps))
    ratio = steps / period
    if period > 0 and np.all(np.abs(ratio - np.round(ratio)) <= REGULAR_TOLERANCE):
        return {p: round((p - ordered[0]) / period) for p in ordered}
    return {p: i for i, p in enumerate(ordered)}


class Video:
    """An open video file; use :func:`open_video`. Iterating yields :class:`VideoFrame`."""

    def __init__(
        self,
        container,
        url: str,
        expected_size,
        max_bad_reads: int,
        index_of: dict[int, int],
        threads: int = 0,
        grey: bool = False,
    ):
        self._container = container
        self._stream = container.streams.video[0]
        self.url = url
        self.expected_size = expected_size
        self.max_bad_reads = max_bad_reads
        self.threads = threads
        self.grey = grey
        rate = self._stream.average_rate or self._stream.guessed_rate
        self.fps = float(rate) if rate else 0.0
        self.frame_count = len(index_of)
        self.bad_reads = 0  # packets that could not be decoded, skipped
        self._index_of = index_of
        self._t0 = min(index_of) if index_of else 0
        self._tb = float(self._stream.time_base or Fraction(1, 90000))
        self._last_index = -1
        self._ctx = None  # the frame-threaded decoder while :meth:`_decode` decodes with it
        self._frames = self._decode()
        self._prefetching: tuple[threading.Event, threading.Thread, queue.Queue] | None = None

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) the container declares, in pixels (0 when unknown)."""
        ctx = self._stream.codec_context
        return int(ctx.width or 0), int(ctx.height or 0)

    def _decode(self) -> Iterator[av.VideoFrame]:
        """Decoded frames in presentation order: frame-threaded until a packet fails, then slice-threaded from the
        keyframe before the first frame not handed on yet (see the module doc)."""
        threads = self.threads or (
            max(GREY_FRAME_THREADS, (os.cpu_count() or 1) + 1) if self.grey else 0
        )
        ctx = self._ctx = decoder(self._stream, threads=threads, frame_threads=True)
        keyframes: list[
            tuple[int, int]
        ] = []  # (pts, packet number) of the keyframe packets demuxed
        last = None  # pts of the last frame handed on
        for number, packet in enumerate(self._container.demux(self._stream)):
            if packet.is_keyframe and packet.pts is not None:
                keyframes.append((packet.pts, number))
            try:
                frames = ctx.decode(packet)
            except av.error.InvalidDataError:
                break
            except av.error.EOFError:
                return
            for frame in frames:
                last = frame.pts if frame.pts is not None else last
                yield frame
        else:
            return
        first = min((p for p in self._index_of if last is None or p > last), default=math.inf)
        yield from self._decode_slices(
            max((n for pts, n in keyframes if pts <= first), default=0), last
        )

    def _decode_slices(self, start: int, last: int | None) -> Iterator[av.VideoFrame]:
        """The file opened again and decoded with slice threads from packet number ``start`` on, frames up to pts
        ``last`` (handed on already) left out; each packet that fails is counted and skipped."""
        self._ctx = None
        self._container.close()
        self._container = av.open(self.url)
        self._stream = self._container.streams.video[0]
        ctx = decoder(self._stream, threads=self.threads)
        for number, packet in enumerate(self._container.demux(self._stream)):
            if number < start:
                continue
            try:
                frames = ctx.decode(packet)
            except av.error.InvalidDataError:
                self.bad_reads += 1
                if self.bad_reads > self.max_bad_reads > 0:
                    return
                continue
            except av.error.EOFError:
                return
            yield from (f for f in frames if last is None or f.pts is None or f.pts > last)

    def read(self) -> VideoFrame | None:
        """The next decodable frame, or None at the end of the video (a video decoding early,
        :func:`decoding_early`, goes on from the frames it decoded meanwhile)."""
        if self._prefetching is not None:
            return self._numbered(_queued(*self._prefetching))
        return self._numbered(self._next_decoded())

    def _next_decoded(self) -> tuple[av.VideoFrame, np.ndarray, av.VideoFrame | None] | None:
        """The next decoded frame, its image (luma view or BGR, as :meth:`read` hands it on) and the frame again
        where the image is its luma plane (:attr:`VideoFrame.decoded`), or None at the end; in the decoding thread
        when prefetching."""
        try:
            frame = next(self._frames, None)
        except av.error.FFmpegError as e:
            raise VideoError(f"{self.url}: {ffmpeg_reason(e)}") from None
        if frame is None:
            return None
        if self.grey and (grey := luma(frame)) is not None:
            return frame, grey, frame
        return frame, frame.to_ndarray(format="bgr24"), None

    def _numbered(self, decoded: tuple | None) -> VideoFrame | None:
        """:meth:`_next_decoded`'s frame checked and numbered (in the reader's thread: the numbering may be set after
        decoding started, :func:`decoding_early`)."""
        if decoded is None:
            return None
        frame, image, luma_of = decoded
        self._check_size(image)
        pts = frame.pts if frame.pts is not None else None
        index = (
            self._index_of.get(pts, self._last_index + 1)
            if pts is not None
            else self._last_index + 1
        )
        index = max(index, self._last_index + 1)
        self._last_index = index
        t_s = (pts - self._t0) * self._tb if pts is not None else index / (self.fps or 30.0)
        return VideoFrame(index, image, t_s, luma_of)

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
        """Iterate with decoding in a background thread (FFmpeg releases the GIL), ``depth`` frames ahead (a
        video decoding early, :func:`decoding_early`, goes on from the frames it decoded meanwhile, then keeps
        ``depth`` ahead).

        A :class:`VideoError` raised while decoding is re-raised in the caller's thread.
        """
        if self._prefetching is None:
            self._start(depth)
        stop, worker, q = prefetching = self._prefetching
        with q.mutex:
            q.maxsize = depth
        try:
            while (frame := self._numbered(_queued(*prefetching))) is not None:
                yield frame
        finally:
            stop.set()
            worker.join()
            if self._prefetching is prefetching:
                self._prefetching = None

    def _start(self, depth: int) -> None:
        """Decoding in a background thread, at most ``depth`` frames ahead of the reader (:meth:`prefetch`)."""
        q: queue.Queue = queue.Queue(maxsize=depth)
        stop = threading.Event()

        def work():
            try:
                while (item := self._next_decoded()) is not None:
                    if not put_until(q, item, stop):
                        return
                put_until(q, None, stop)
            except VideoError as e:
                put_until(q, e, stop)

        worker = threading.Thread(target=work, name="video-decode", daemon=True)
        self._prefetching = (stop, worker, q)
        worker.start()

    def close(self) -> None:
        """Release the decoder (after stopping a :meth:`prefetch` thread still reading from it).

        A video closed before its end has frames in flight in FFmpeg's frame threads, and each thread logs as it
        parses (PyAV's log callback takes the interpreter's lock for every message, FFmpeg's debug lines too).
        Freeing the decoder waits for those threads; freed where the lock is held (by the garbage collector: the
        decoding generator and the video refer to each other), it waited forever for a thread waiting for the lock.
        So the decoding ends here: the generator is closed and the decoder drained (its frames in flight decoded,
        the lock released meanwhile), and the decoder freed later has idle threads."""
        if self._prefetching is not None:
            stop, worker, _ = self._prefetching
            stop.set()
            worker.join()
            self._prefetching = None
        self._frames.close()
        if self._ctx is not None:
            with contextlib.suppress(av.error.FFmpegError):
                self._ctx.decode(None)
            self._ctx = None
        self._container.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _queued(stop: threading.Event, worker: threading.Thread, q: queue.Queue):
    """The decoding thread's next item (:meth:`Video._next_decoded`'s), None at the end or once stopped; its
    :class:`VideoError` raised here, in the reader's thread."""
    while True:
        try:
            item = q.get(timeout=0.1)
        except queue.Empty:
            if stop.is_set() or not worker.is_alive():
                return None  # closed under us
            continue
        if isinstance(item, VideoError):
            raise item
        return item


class _Early:
    """A video file opened and decoding in a thread of its own (:func:`decoding_early`); ``video``: the open
    :class:`Video`, prefetching, once ``opened`` is set (None: it could not be opened, :func:`open_video` will say
    why)."""

    def __init__(self, path: Path, grey: bool):
        self.path, self.grey = path, grey
        self.video: Video | None = None
        self.opened = threading.Event()
        self._thread = threading.Thread(target=self._open, name="video-early", daemon=True)
        self._thread.start()

    def _open(self) -> None:
        """Open and start decoding; whatever fails, ``opened`` is set (the reader's :func:`open_video` then opens
        the file itself and reports what is wrong with it)."""
        try:
            video = _opened(str(self.path), 0, 0, self.grey)
            w, h = video.size
            frame_bytes = w * h * (3 if not self.grey else 1.5)
            video._start(max(EARLY_FRAMES, int(EARLY_BYTES // frame_bytes) if frame_bytes else 0))
            self.video = video
        except VideoError:
            pass
        finally:
            self.opened.set()

    def taken(self) -> Video | None:
        """The open video (None: it could not be opened), once open."""
        self.opened.wait()
        return self.video


@contextlib.contextmanager
def decoding_early(url, grey: bool = False) -> Iterator[None]:
    """Within the block, the video file ``url`` is decoding already in the background (read ``grey`` or not, FFmpeg's
    thread count, no limit on bad reads: :func:`open_video`'s defaults), up to :data:`EARLY_BYTES` of its frames
    ahead: the block's first :func:`open_video` of that file with the same ``grey`` and those defaults takes it, as
    it is, and reads on from its first frame (numbered by the ``indices`` given then). ``skyfix process`` starts
    decoding so while it reads the session, which leaves a core idle (issue 30). A video not taken is closed at the
    end of the block."""
    key = (Path(url).resolve(), grey)
    early = _early[key] = _early.get(key) or _Early(key[0], grey)
    try:
        yield
    finally:
        if _early.get(key) is early:
            del _early[key]
            if (video := early.taken()) is not None:
                video.close()


def _presentation_times(path: str) -> tuple[list[int], Fraction]:
    """Every video packet's pts (demuxing only), packets the container marks to discard left out, and the stream's
    time base (s per tick)."""
    with av.open(path) as container:
        stream = container.streams.video[0]
        return [
            p.pts for p in container.demux(stream) if p.pts is not None and not p.is_discard
        ], stream.time_base


def frame_times(url) -> tuple[np.ndarray, np.ndarray]:
    """A video file's frame indices (numbered as :func:`open_video` numbers them) and their container times from
    the first frame (s), in order (demuxing only); :class:`VideoError` for a file FFmpeg cannot read."""
    try:
        pts, base = _presentation_times(str(url))
    except (av.error.FFmpegError, IndexError) as e:
        why = ffmpeg_reason(e) if isinstance(e, av.error.FFmpegError) else "no video stream"
        raise VideoError(f"{url}: FFmpeg cannot read its frames' times ({why})") from None
    if not pts:
        raise VideoError(f"{url}: no video frames")
    ordered = sorted(set(pts))
    index_of = frame_indices(ordered)
    return np.array([index_of[p] for p in ordered]), np.array(
        [float((p - ordered[0]) * base) for p in ordered]
    )


def open_video(
    url,
    expected_size: tuple[int, int] | None = None,
    threads: int = 0,
    max_bad_reads: int = 0,
    indices: Sequence[int] | None = None,
    grey: bool = False,
) -> Video:
    """Open a video file with FFmpeg.

    ``expected_size`` (width, height) in pixels, usually the calibration's: a
    different frame size is a :class:`VideoError` (checked on open when the
    container declares it, and on every frame). ``threads`` is FFmpeg's decoding
    thread count (frame and slice threads; 0: as the module doc says). ``max_bad_reads`` > 0 ends the
    video after that many undecodable packets (0: no limit). ``indices``: the session's frame
    indices (``video_frames.csv``), which number the frames when the counts agree. ``grey``: frames as their
    luma plane where the video is yuv420p (see the module doc).
    """
    url = str(url)
    path = Path(url)
    early = (
        _early.pop((path.resolve(), grey), None) if threads == 0 and max_bad_reads == 0 else None
    )
    if early is not None and (video := early.taken()) is not None:
        video.url = url
        return _adopted(video, expected_size, indices)
    return _adopted(_opened(url, threads, max_bad_reads, grey), expected_size, indices)


def _opened(url: str, threads: int, max_bad_reads: int, grey: bool) -> Video:
    """The file ``url`` opened as :func:`open_video` opens it, its frames numbered by their timestamps alone, no
    size expected yet."""
    route_ffmpeg_log()
    path = Path(url)
    if not path.exists():
        raise VideoError(f"{url}: missing")
    if not path.is_file():
        raise VideoError(f"{url}: not a file")
    if path.stat().st_size == 0:
        raise VideoError(f"{url}: empty file")
    try:
        index_of = frame_indices(_presentation_times(url)[0])
        container = av.open(url)
        if not container.streams.video:
            container.close()
            raise VideoError(f"{url}: FFmpeg cannot open it (no video stream)")
    except (av.error.FFmpegError, IndexError) as e:
        why = ffmpeg_reason(e) if isinstance(e, av.error.FFmpegError) else "no video stream"
        raise VideoError(f"{url}: FFmpeg cannot open it ({why})") from None
    return Video(container, url, None, max_bad_reads, index_of, threads, grey)


def _adopted(video: Video, expected_size, indices: Sequence[int] | None) -> Video:
    """``video`` (open, no frame read yet by its reader) with the ``expected_size`` and the frames numbered by
    ``indices``, as :func:`open_video` describes."""
    if indices is not None:
        video._index_of = frame_indices(list(video._index_of), indices)
    video.expected_size = expected_size
    url = video.url
    w, h = video.size
    if expected_size is not None and w > 0 and h > 0 and (w, h) != tuple(expected_size):
        video.close()
        ew, eh = expected_size
        raise VideoError(
            f"{url}: frame size {w}x{h} pixels differs from the calibration's camera {ew}x{eh}"
        )
    return video

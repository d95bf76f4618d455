"""Each UUV's tracking in a process of its own, the decoded frames shared (offline, issue 30).

:func:`groundstation.offline.track.track_sessions` decodes the video and measures its motion in the main process
and hands every frame to :class:`TrackWorkers`: one worker process per UUV steps that UUV's
:class:`~groundstation.offline.track.UuvTrack` (its tracker, its height from its size, its tracing back) on the
frames in order. Tracking and measuring are Python holding the interpreter's lock; in one process the UUVs took
turns on one core (``bench/offline_speed.py --uuvs``, py-spy of ``skyfix process --uuv all`` at 1080p with three
UUVs: the main thread busy all the time, tracking and measuring 80 % of it, the decoding thread waiting on it).

**The frame is read once.** It is copied once into a ring of :data:`RING_SLOTS` frames in one block of memory
shared with the workers (an anonymous shared mapping made before they are forked: nothing to name, nothing left
behind by a crash), a yuv420p frame as its three planes as decoded, another as BGR; every worker reads it in place.
A worker acknowledges each frame once stepped; a slot is written again once every worker has acknowledged the
frame in it. A worker's :meth:`RingFrame.bgr_regions` converts the planes with FFmpeg where they are read, as the
decoded frame's own :meth:`~groundstation.video.frames.VideoFrame.bgr_regions` does (the same colour space and
range: the same bytes).

**The same results.** The workers are forked after the poses are computed, so each inherits its UUV's track as it
is (nothing pickled on the way in). At the end a worker sends back its UUV's per-frame results and the heights
from size it took, in order; the main process takes those into its own
:class:`~groundstation.height_from_size.HeightFromSize` (:meth:`~groundstation.offline.track.UuvTrack.adopt`):
``due`` and ``take`` depend on nothing else, so its estimate, its warnings and (``auto``) the heights handed to
the telemetry's fusion are the ones the main process would have had stepping the tracks itself. The worker's own
copy logs nothing (its warnings would be the main process's twice).

**The height from size in a process of its own (the default).** Without the track workers, the UUVs are stepped
in the main process but their heights from size are measured by one :class:`SizeWorker` process beside it (issue
30: py-spy of ``skyfix process --uuv all``, three UUVs at 1080p: the measurements were 45 % of the main thread,
~11 ms each of Python and NumPy). A frame to measure is copied into a free slot of a ring of :data:`SIZE_SLOTS`,
as above, with the track's number, the row and the tracked pixel; the process converts it to BGR, measures and
sends the result back, in the order handed over. The main process tracks on meanwhile and takes each result into
its UUV's :class:`~groundstation.height_from_size.HeightFromSize`, in order, at the latest before that UUV's next
``due`` whose answer depends on the estimate
(:meth:`~groundstation.height_from_size.HeightFromSize.asks_estimate`: a fifth of a second later at 5 Hz): the
frames measured, the estimate, the warnings and the heights handed to the fusion are the ones measuring in place
gives.

Where ``fork`` is not available (Windows, macOS' default), :func:`available` is False and the main process steps
the tracks and measures their heights itself.
"""

from __future__ import annotations

import logging
import mmap
import multiprocessing
import pickle
import signal
from collections import deque
from dataclasses import dataclass

import numpy as np

from groundstation.session.read import SessionError
from groundstation.video.frames import BgrRegions, plane_array
from localizer.tracking.colour import Chroma

#: Frames in the shared ring: how far the fastest worker may run ahead of the slowest.
RING_SLOTS = 6
#: Frames in the height-from-size process's ring: measurements handed over and not yet taken, at most.
SIZE_SLOTS = 6
#: While waiting on a worker, check this often (s) that it is still alive.
POLL_S = 0.5
#: A worker's acknowledgement of one frame stepped.
DONE = None


def available() -> bool:
    """Whether this platform forks (see the module doc)."""
    return "fork" in multiprocessing.get_all_start_methods()


@dataclass
class RingFrame:
    """A frame in a slot of the ring as a worker reads it: ``image`` as
    :attr:`~groundstation.video.frames.VideoFrame.image` (a yuv420p frame's luma plane, or BGR), ``planes`` a
    yuv420p frame's three planes (None for BGR) and ``colour`` its (colorspace, color_range)."""

    image: np.ndarray
    planes: list[np.ndarray] | None = None
    colour: tuple[int, int] = (0, 0)

    def bgr_regions(self) -> BgrRegions | np.ndarray:
        """The frame in BGR uint8 where it is read, converted by FFmpeg as the decoded frame's would be
        (:meth:`~groundstation.video.frames.VideoFrame.bgr_regions`), or ``image`` where that is BGR."""
        if self.planes is None:
            return self.image
        return BgrRegions(self.planes, self.colour)

    def chroma(self) -> Chroma | None:
        """The frame's colour as :meth:`~groundstation.video.frames.VideoFrame.chroma` reads it."""
        return Chroma.of(self.image, self.planes)


def _layout(frame) -> tuple[list[tuple[int, ...]], tuple[int, int] | None]:
    """How a decoded :class:`~groundstation.video.frames.VideoFrame` lies in a slot: its arrays' shapes (a yuv420p
    frame's three planes, or the BGR image) and a yuv420p frame's (colorspace, color_range)."""
    decoded = frame.decoded
    if decoded is None:
        return [frame.image.shape], None
    shapes = [(p.height, p.width) for p in decoded.planes]
    return shapes, (int(decoded.colorspace), int(decoded.color_range))


def _views(ring: mmap.mmap, offset: int, shapes) -> list[np.ndarray]:
    """The arrays of ``shapes`` (uint8) one after another in ``ring`` from byte ``offset``."""
    views = []
    for shape in shapes:
        size = int(np.prod(shape))
        views.append(np.frombuffer(ring, np.uint8, size, offset).reshape(shape))
        offset += size
    return views


def put_frame(ring: mmap.mmap, slot: int, slot_bytes: int, frame, video) -> tuple:
    """Copy the decoded ``frame`` into slot ``slot`` of ``ring`` (slots of ``slot_bytes``); its layout
    (:func:`_layout`), which :func:`ring_frame` reads it by. A frame larger than a slot is a
    :class:`SessionError` naming the ``video``."""
    layout = _layout(frame)
    shapes, colour = layout
    if sum(int(np.prod(s)) for s in shapes) > slot_bytes:
        raise SessionError(f"{video}: a frame of shape {shapes} is larger than the calibration's")
    views = _views(ring, slot * slot_bytes, shapes)
    sources = [frame.image] if colour is None else [plane_array(p) for p in frame.decoded.planes]
    for view, source in zip(views, sources, strict=True):
        np.copyto(view, source)
    del views  # no view may outlive the ring's close
    return layout


def ring_frame(ring: mmap.mmap, offset: int, layout) -> RingFrame:
    """The frame a slot from byte ``offset`` holds (``layout``: :func:`_layout`'s)."""
    shapes, colour = layout
    views = _views(ring, offset, shapes)
    if colour is None:
        return RingFrame(views[0])
    return RingFrame(views[0], views, colour)


class TrackWorkers:
    """The UUVs' ``tracks`` (:class:`~groundstation.offline.track.UuvTrack`, their poses set) each stepped in a
    worker process (see the module doc); ``frame_bytes``: the most a decoded frame takes (bytes). :meth:`step`
    each decoded frame, :meth:`finish` at the end, :meth:`close` always (stops the workers)."""

    def __init__(self, tracks: list, frame_bytes: int):
        self.tracks = tracks
        self.slot_bytes = frame_bytes
        self.ring = mmap.mmap(
            -1, RING_SLOTS * frame_bytes
        )  # anonymous, MAP_SHARED: the forked workers see it
        self.sent = 0
        self.done = [0] * len(tracks)
        ctx = multiprocessing.get_context("fork")
        self.links, self.procs = [], []
        for track in tracks:
            mine, theirs = ctx.Pipe()
            proc = ctx.Process(
                target=_work,
                args=(track, theirs, self.ring, frame_bytes),
                name=f"track {track.session.path.name}",
                daemon=True,
            )
            proc.start()
            theirs.close()
            self.links.append(mine)
            self.procs.append(proc)

    def step(self, row: int, frame) -> None:
        """Hand the decoded ``frame`` (row ``row`` of ``video_frames.csv``) to every worker: into the next slot once
        every worker is done with the frame in it. Raises a worker's error."""
        slot = self.sent % RING_SLOTS
        self._wait_done(self.sent - RING_SLOTS + 1)
        layout = put_frame(
            self.ring, slot, self.slot_bytes, frame, self.tracks[0].session.video_path
        )
        for link in self.links:
            link.send((row, slot, layout))
        self.sent += 1

    def finish(self) -> None:
        """Every frame handed on: each worker's results adopted by its track in this process."""
        for link in self.links:
            link.send(None)
        for i, track in enumerate(self.tracks):
            while (message := self._receive(i)) is DONE:
                pass
            track.adopt(message[1])

    def close(self) -> None:
        """Stop the workers (any time) and release the ring."""
        for link, proc in zip(self.links, self.procs, strict=True):
            if proc.is_alive():
                proc.terminate()
            proc.join()
            link.close()
        self.ring.close()

    def _wait_done(self, frames: int) -> None:
        """Wait until every worker has stepped at least ``frames`` frames."""
        for i in range(len(self.links)):
            while self.done[i] < frames:
                self._receive(i)

    def _receive(self, i: int):
        """Worker ``i``'s next message: an acknowledgement (counted) or its results; its error raised here."""
        message = _received(self.links[i], self.procs[i])
        if message is DONE:
            self.done[i] += 1
        return message


def _received(link, proc):
    """The next message of the worker ``proc`` on ``link``; its error raised here, its end a :class:`SessionError`."""
    while not link.poll(POLL_S):
        if not proc.is_alive():
            raise SessionError(f"{proc.name}: the process ended (exit code {proc.exitcode})")
    message = link.recv()
    if message is not DONE and message[0] == "error":
        raise message[1]
    return message


class SizeWorker:
    """The heights from size of the UUVs' ``tracks`` (:class:`~groundstation.offline.track.UuvTrack`, their poses
    set) measured in one process beside the pass (see the module doc); ``frame_bytes``: the most a decoded frame
    takes (bytes). A track hands its frames to :meth:`submit`, and calls :meth:`settle` before its size's
    :meth:`~groundstation.height_from_size.HeightFromSize.due` whenever that depends on the estimate
    (:meth:`~groundstation.height_from_size.HeightFromSize.asks_estimate`); :meth:`finish` at the end,
    :meth:`close` always (stops the process)."""

    def __init__(self, tracks: list, frame_bytes: int):
        self.tracks, self.slot_bytes = tracks, frame_bytes
        self.ring = mmap.mmap(
            -1, SIZE_SLOTS * frame_bytes
        )  # anonymous, MAP_SHARED: seen by the fork
        self.free = list(range(SIZE_SLOTS))
        self.pending: deque = deque()  # (track, t_unix, slot) of each frame handed over, in order
        ctx = multiprocessing.get_context("fork")
        self.link, theirs = ctx.Pipe()
        self.proc = ctx.Process(
            target=_measure,
            args=(tracks, theirs, self.ring, frame_bytes),
            name="height from size",
            daemon=True,
        )
        self.proc.start()
        theirs.close()

    def submit(self, track, row: int, frame, u: float, v: float) -> None:
        """Measure ``track``'s height from size in the decoded ``frame`` (row ``row``) around its pixel (u, v): the
        frame copied into a free slot (waiting for the oldest measurement when none is)."""
        if not self.free:
            self._take_oldest()
        slot = self.free.pop()
        layout = put_frame(self.ring, slot, self.slot_bytes, frame, track.session.video_path)
        self.link.send((self.tracks.index(track), row, u, v, slot, layout))
        self.pending.append((track, float(track.t[row]), slot))

    def settle(self, track) -> None:
        """Every measurement handed over for ``track``, and for the tracks whose heights share its estimate
        (:class:`~groundstation.height_from_size.SharedEstimate`), taken, in order."""
        shared = track.size.shared
        while any(mine.size.shared is shared for mine, _, _ in self.pending):
            self._take_oldest()

    def finish(self) -> None:
        """Every measurement handed over taken; the process ends."""
        while self.pending:
            self._take_oldest()
        self.link.send(None)

    def close(self) -> None:
        """Stop the process (any time) and release the ring."""
        if self.proc.is_alive():
            self.proc.terminate()
        self.proc.join()
        self.link.close()
        self.ring.close()

    def _take_oldest(self) -> None:
        measured = _received(self.link, self.proc)[1]
        track, t_unix, slot = self.pending.popleft()
        self.free.append(slot)
        track.took(t_unix, measured)


def _measure(tracks: list, link, ring: mmap.mmap, slot_bytes: int) -> None:
    """The measuring process: each frame ``link`` names (track number, row, u, v, slot, layout) until None measured
    and its result sent back (``("result", SizeHeight or why not)``), or its first error (``("error", exception)``;
    the frames after it are read and ignored)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the main process stops it
    failed = False
    while (message := link.recv()) is not None:
        if failed:
            continue
        i, row, u, v, slot, layout = message
        track = tracks[i]
        try:
            image = ring_frame(ring, slot * slot_bytes, layout).bgr_regions()
            link.send(("result", track.size.measure(image, track.pose, row, u, v)))
        except Exception as e:  # noqa: BLE001 - raised again in the main process
            failed = True
            link.send(("error", picklable(e)))


def _work(track, link, ring: mmap.mmap, slot_bytes: int) -> None:
    """A worker: step ``track`` on each frame ``link`` names (row, slot, layout) until None, acknowledging each;
    then send its results (``("result", track.state())``), or its first error (``("error", exception)``; the frames
    after it are read and ignored)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the main process stops the workers
    logging.getLogger("skyfix.size").disabled = True
    failed = False
    while (message := link.recv()) is not None:
        if failed:
            continue
        row, slot, layout = message
        try:
            track.step(row, ring_frame(ring, slot * slot_bytes, layout))
        except Exception as e:  # noqa: BLE001 - raised again in the main process
            failed = True
            link.send(("error", picklable(e)))
            continue
        link.send(DONE)
    if not failed:
        link.send(("result", track.state()))


def picklable(e: Exception) -> Exception:
    """``e``, or a RuntimeError with its words when it cannot be sent to the main process."""
    try:
        pickle.dumps(e)
    except Exception:  # noqa: BLE001 - any failure to pickle
        return RuntimeError(f"{type(e).__name__}: {e}")
    return e

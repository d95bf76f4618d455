"""The per-frame pipeline of the live service: tracker → time alignment → geometry → sinks.

Frames wait in a short queue; when the tracker falls behind, the oldest waiting
frame is dropped (and counted), so a fix is never computed for a frame that is
already old. The tracker runs in a worker thread (OpenCV releases the GIL); the
telemetry is only read on the event loop, where it is written. The first frame
initialises the tracker with the calibration's ``[tracker] init_bbox`` (its
``init_t`` is for recorded sessions and is not used live). After a good fix, each
frame's tracker gets a prediction the way the offline tracking makes it
(:mod:`groundstation.track_video`): that fix's position projected into the new
frame, shifted by the residual between the fix's pixel and the projection at its
own frame, with an uncertainty growing with the time since the fix
(:func:`localizer.tracking.predict.follow`). The tracker reports the centre of
the UUV's top face, the point its depth refers to
(:func:`localizer.tracking.predict.init_target`).

A tracked frame is located at once when the camera's attitude telemetry
(ATTITUDE, and the gimbal message) reaches to within :data:`EXTRAPOLATE_S` of its
time: a short extrapolation with the rates costs little, and the accuracy grows to
match. Otherwise it waits, in order, for a sample after its time, so that it is
interpolated as offline; at most ``telemetry_wait_s`` after the frame arrived (a
slow radio: ATTITUDE at 4 Hz needs about 0.3 s), then it is located with what
there is (extrapolated within ``[timing]`` limits, or a ``stale_…`` status).
Tracking goes on meanwhile.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections import Counter, deque
from collections.abc import Sequence
from dataclasses import dataclass

from localizer.calibration import Calibration
from localizer.fix import Fix, locate
from localizer.pose import camera_pose
from localizer.telemetry import Telemetry
from localizer.tracking import TrackResult, make_tracker
from localizer.tracking.predict import follow, init_target, project_uuv

from .sources.video_live import LiveFrame

log = logging.getLogger("skyfix.pipeline")

#: A frame up to this far (s) after the newest attitude sample is located without waiting for the next one.
EXTRAPOLATE_S = 0.03


@dataclass(frozen=True)
class FrameInfo:
    """Timing of one processed frame (UNIX seconds): when it arrived and when its fix was ready."""

    index: int
    t_recv: float
    t_fix: float


class Pipeline:
    """Worker turning frames into :class:`~localizer.fix.Fix` es for every sink (``on_fix(fix, info)``)."""

    def __init__(self, cal: Calibration, tel: Telemetry, tracker: str, sinks: Sequence, queue_len: int = 2,
                 telemetry_wait_s: float = 0.3):
        self.cal = cal
        self.tel = tel
        self.tracker_name = tracker
        make_tracker(tracker, cal)  # fail early on a wrong name
        self.sinks = list(sinks)
        self.queue_len = queue_len
        self.telemetry_wait_s = telemetry_wait_s
        self._queue: deque[LiveFrame] = deque()
        self._ready = asyncio.Event()
        self._tracked: deque[tuple[LiveFrame, TrackResult]] = deque()  # waiting for their telemetry
        self._tracked_ready = asyncio.Event()
        self._telemetry = asyncio.Event()
        self._angle_series = [tel.attitude] + (
            [tel.gimbal] if cal.mount.attitude_source == "gimbal_device"
            else [tel.mount] if cal.mount.attitude_source == "mount_orientation" else [])
        self.waited_s = 0.0  # total time frames waited for telemetry
        self.held = 0  # frames that waited for telemetry
        self._holding: int | None = None
        self._tracker = None
        self._last_ok: Fix | None = None
        self.processed = 0
        self.dropped = 0
        self.statuses: Counter[str] = Counter()
        self.last_status: str | None = None

    def submit(self, frame: LiveFrame) -> None:
        """Queue a frame (on the event loop); drops the oldest waiting frame when the queue is full.

        The very first frame is never dropped: ``init_bbox`` belongs to it.
        """
        if len(self._queue) >= self.queue_len:
            first_waiting = self._tracker is None and self.processed == 0 and self._queue[0].index == 0
            del self._queue[1 if first_waiting else 0]
            self.dropped += 1
        self._queue.append(frame)
        self._ready.set()

    def telemetry_arrived(self, *_) -> None:
        """Called (on the loop) whenever UAV telemetry arrives: waiting frames look again."""
        self._telemetry.set()

    async def run(self) -> None:
        async with asyncio.TaskGroup() as tg:
            tg.create_task(self._track_frames())
            tg.create_task(self._locate_frames())

    async def _track_frames(self) -> None:
        while True:
            if not self._queue:
                self._ready.clear()
                await self._ready.wait()
                continue
            frame = self._queue.popleft()
            self._tracked.append((frame, await self._track(frame)))
            self._tracked_ready.set()

    def _needs_telemetry(self, frame: LiveFrame, result: TrackResult) -> bool:
        """Whether a tracked frame is further past its newest attitude telemetry than :data:`EXTRAPOLATE_S`."""
        if not result.ok:
            return False
        t = float(self.tel.uav_time(frame.t_unix)) - EXTRAPOLATE_S
        return any(s.last_t is None or s.last_t < t for s in self._angle_series)

    async def _locate_frames(self) -> None:
        loop = asyncio.get_running_loop()
        while True:
            if not self._tracked:
                self._tracked_ready.clear()
                await self._tracked_ready.wait()
                continue
            frame, result = self._tracked[0]
            left = frame.t_recv + self.telemetry_wait_s - time.time()
            if left > 0 and self._needs_telemetry(frame, result):
                if self._holding != frame.index:
                    self._holding = frame.index
                    self.held += 1
                self._telemetry.clear()
                t0 = loop.time()
                try:
                    await asyncio.wait_for(self._telemetry.wait(), timeout=left)
                except TimeoutError:
                    pass
                self.waited_s += loop.time() - t0
                continue
            self._tracked.popleft()
            self._emit(frame, self._locate(frame, result))

    def _emit(self, frame: LiveFrame, fix: Fix) -> None:
        info = FrameInfo(frame.index, frame.t_recv, time.time())
        self.processed += 1
        self.statuses[fix.status] += 1
        if fix.status != self.last_status:
            log.info("frame %d: status %s", frame.index, fix.status)
        self.last_status = fix.status
        for sink in self.sinks:
            sink.on_fix(fix, info)

    async def process(self, frame: LiveFrame) -> Fix:
        """The fix of one frame with the telemetry there is now (status says why when there is none)."""
        return self._locate(frame, await self._track(frame))

    def _locate(self, frame: LiveFrame, result: TrackResult) -> Fix:
        """A tracked frame's fix."""
        if not result.ok:
            fix = Fix(frame.t_unix, result.status)
        else:
            fix = locate(self.cal, camera_pose(self.cal, self.tel, frame.t_unix), result.u, result.v)[0]
        fix.frame = frame.index
        fix.confidence = result.confidence
        if fix.ok:
            self._last_ok = fix
        return fix

    async def _track(self, frame: LiveFrame) -> TrackResult:
        if self._tracker is None:
            box = self.cal.init_bbox
            if box is None:
                return TrackResult("no_init_bbox")
            tracker = make_tracker(self.tracker_name, self.cal)
            point, prediction = init_target(self.cal, camera_pose(self.cal, self.tel, frame.t_unix), box)
            try:
                await asyncio.to_thread(tracker.init, frame.image, box, prediction, point)
            except ValueError as e:
                log.warning("tracker init on frame %d: %s", frame.index, e)
                return TrackResult("bad_init_bbox")
            self._tracker = tracker
            return TrackResult("ok", point[0], point[1], box)
        return await asyncio.to_thread(self._tracker.update, frame.image, self._predict(frame.t_unix))

    def _predict(self, t_unix: float):
        last = self._last_ok
        if last is None:
            return None
        pose = camera_pose(self.cal, self.tel, [t_unix, last.t_unix])
        u, v, px_per_m = project_uuv(self.cal, pose, last.lat, last.lon)
        return follow((u[0], v[0], px_per_m[0]), (u[1], v[1]), (last.u, last.v), t_unix - last.t_unix)

    def status(self) -> dict:
        return {"processed": self.processed, "dropped": self.dropped, "queued": len(self._queue),
                "waiting_for_telemetry": len(self._tracked), "held_for_telemetry": self.held,
                "waited_s": round(self.waited_s, 3),
                "last_status": self.last_status, "statuses": dict(self.statuses)}

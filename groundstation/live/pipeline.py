"""The per-frame pipeline of the live service: tracking session → time alignment → geometry → sinks.

Frames wait in a short queue; when the tracker falls behind, the oldest waiting
frame is dropped (and counted), so a fix is never computed for a frame that is
already old. Each frame's camera pose is computed once, on the event loop (where
the telemetry is written), when the frame is taken for tracking: its UAV's part once for
every UUV tracked in the video (:class:`FramePoses`), each UUV's depth added; the
:class:`~localizer.tracking.session.TrackingSession` (the same as offline) tracks it
in a worker thread (OpenCV releases the GIL) with that pose, and the geometry
locates the tracked pixel with the same pose. The first frame is selected with the
calibration's ``[tracker] init_bbox`` when there is one (its ``init_t`` is for
recorded sessions and is not used live); otherwise the session awaits a target: the
operator's selection (:meth:`Pipeline.select`), or a candidate found near the UUV's
own position estimate (``prior``) and confirmed over several frames. A tracker of grey levels (the default,
:data:`~localizer.tracking.GREY_TRACKERS`) and the steer to the silhouette read each frame's luma plane as decoded
(``LiveFrame.grey``), as ``skyfix process`` reads the video's: the same grey levels live and offline (a frame without
one is read in BGR). Each located frame the UUV was tracked in goes, with its final pose and BGR image, to the
``on_tracked`` listeners (the height from the UUV's size) before its fix goes out.

A tracked frame is located at once when the camera's attitude telemetry
(ATTITUDE, and the gimbal message) reached to within :data:`EXTRAPOLATE_S` of its
time when it was tracked: a short extrapolation with the rates costs little, and
the accuracy grows to match. Otherwise it waits, in order, for a sample after its
time, so that it is interpolated as offline; at most ``telemetry_wait_s`` after the
frame arrived (a slow radio: ATTITUDE at 4 Hz needs about 0.3 s); then its pose is
computed again with what there is (extrapolated within ``[timing]`` limits, or a
``stale_…`` status). Tracking goes on meanwhile.

Time: a frame is aligned to the telemetry by the UAV link's delay (configured, measured
by TIMESYNC, or unknown: taken as 0 with its sigma in h_acc, logged once), unless
``alignment`` (``--video-latency-ms auto``) says the video's latency from the image's
motion aligns it. A frame stamped before that estimate settled (``LiveFrame.aligned``
False) is tracked but gets no fix: status ``latency_unsettled``.

Operator commands (:meth:`Pipeline.select`, :meth:`Pipeline.release`,
:meth:`Pipeline.acquire`) run in the tracking worker between frames. The last
``history_s`` seconds of tracked frames are held with their poses, so a selection
refers to a frame the operator saw: the session is re-initialised there and then
catches up through the held frames after it before the next live frame. An operator's
box must hold a vehicle-sized object standing out of the water (a box on open water is
refused, not tracked as the seafloor), checked over the frames of the next
:data:`~localizer.tracking.session.STEADY_S` it is followed in (``TrackingSession.select(..., steady=True)``: through
wind waves one frame does not tell a deep UUV from a caustic on the seafloor); meanwhile its frames are
``awaiting_target`` (no fix) and the target's state ``confirming``. A box drawn on a held frame is checked on the
held frames after it as it catches up, then on the frames to come: the command answers with the verdict (a refusal
is a SelectionError), or after :data:`VERDICT_WAIT_S` with the target still ``confirming`` (its refusal then a
warning; the status says). ``init_bbox`` is checked the same way from the first frame: kept as drawn when
it holds the vehicle's outline, snapped onto the outline when it is off it, refused (awaiting a target) when no
vehicle stands out in it; one warning names the box, and the status's ``target.init_bbox`` says which (``confirming``
meanwhile). A first frame without a camera pose cannot size the vehicle: the box is then tracked unchecked and
checked from the first frame tracked with a pose (before any fix can be ok, since a fix needs the pose). A click is
checked on its frame alone. A release
also turns frames tracked before it but not yet located into ``released`` ones: no
fix goes out after it.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections import Counter, deque
from collections.abc import Callable, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass

import numpy as np

from groundstation.video.frames import LiveFrame
from localizer.calibration import Calibration
from localizer.fix import Fix, locate
from localizer.height import take_notices
from localizer.pose import CameraPose, uav_pose, with_depth
from localizer.telemetry import Telemetry
from localizer.timeline import Series
from localizer.tracking import GREY_TRACKERS, TrackResult
from localizer.tracking.centroid import CentroidSteer
from localizer.tracking.predict import window as search_window
from localizer.tracking.session import STEADY_S, Prior, SelectionError, TrackingSession

log = logging.getLogger("skyfix.pipeline")

#: A frame up to this far (s) after the newest attitude sample is located without waiting for the next one.
EXTRAPOLATE_S = 0.03
#: How long an operator's selection waits for its box's check over the frames after it (STEADY_S of frames, on a
#: stalled stream longer) before it answers "confirming".
VERDICT_WAIT_S = 5.0
#: At most this many frames are held for selections, whatever ``history_s``.
MAX_HELD = 300
#: The poses of this many recent frames are kept for the other UUVs (:class:`FramePoses`).
KEEP_FRAMES = 64


class FramePoses:
    """The UAV's part of each frame's camera pose (:func:`localizer.pose.uav_pose`), computed once for all the UUVs
    tracked in the video, on the event loop: each UUV's pipeline asks when it takes the frame for tracking and, when
    the frame was early for its telemetry, again when it locates it; the first to ask computes, the others take
    what it computed (``again``: the first to ask again computes anew, with the telemetry there is then). The last
    :data:`KEEP_FRAMES` frames' are kept."""

    def __init__(self, cal: Calibration, tel: Telemetry):
        self.cal, self.tel = cal, tel
        self.computed = 0  # poses computed
        self.shared = 0  # poses taken as computed for another UUV
        self._poses: dict[int, tuple[CameraPose, tuple | None, bool]] = {}

    def pose(self, frame: LiveFrame, alignment: tuple | None, again: bool = False) -> CameraPose:
        kept = self._poses.get(frame.index)
        if kept is not None and kept[1] == alignment and (kept[2] or not again):
            self.shared += 1
            return kept[0]
        pose = uav_pose(self.cal, self.tel, frame.t_unix, alignment)
        self.computed += 1
        self._poses[frame.index] = (pose, alignment, again)
        while len(self._poses) > KEEP_FRAMES:
            del self._poses[next(iter(self._poses))]
        return pose


@dataclass(frozen=True)
class FrameInfo:
    """One processed frame beside its fix: when it arrived and when its fix was ready (UNIX seconds), the
    tracker's box (x, y, w, h) around the UUV in it, when it has one, and the window (x, y, w, h, pixels) the
    telemetry's prediction had it searched in, when there was one; ``t_recv_mono`` its arrival on the monotonic
    clock (None: not known); ``lock`` the operator's commands before it was tracked (a new number: a new lock)."""

    index: int
    t_recv: float
    t_fix: float
    box: tuple[int, int, int, int] | None = None
    window: tuple[float, float, float, float] | None = None
    t_recv_mono: float | None = None
    lock: int = 0


@dataclass
class Tracked:
    """A tracked frame on its way to the geometry, with the pose it was tracked with."""

    frame: LiveFrame
    pose: CameraPose
    result: TrackResult
    early: bool  # the pose was computed more than EXTRAPOLATE_S past the newest attitude sample
    # where the prediction had the UUV searched
    window: tuple[float, float, float, float] | None = None
    lock: int = 0  # the operator's commands before it was tracked


@dataclass(frozen=True)
class _Checking:
    """A box being checked over frames: the frame it was drawn on (or checked from), the box, whether it is
    ``init_bbox`` (``late``: checked from the first frame with a camera pose)."""

    frame: int
    box: tuple
    init: bool = False
    late: bool = False


class Pipeline:
    """Worker turning frames into :class:`~localizer.fix.Fix` es for every sink (``on_fix(fix, info)``).

    ``prior(t_unix)``: the UUV's own position estimate at a frame's time (None: none);
    ``history_s``: how long tracked frames are held for selections; ``alignment()``: the (source word,
    1-sigma s) of aligned frames' times when not the link delay's (see the module doc);
    ``depth``: the UUV's depth series when not ``tel``'s own (one of several UUVs in the video); ``vet(frame,
    box)``: a status word when a tracked box may not be this UUV's (:meth:`localizer.tracking.crowd.Crowd.vet`),
    called with every frame's box (None when the tracker has none); ``tracking``: the thread the tracker steps run
    in (several UUVs' pipelines share one: their steps, mostly the interpreter's work, would otherwise contend for
    its lock, measured with ``bench/uuvs.py``; default: asyncio's pool); ``poses``: the frames' poses shared with the
    other UUVs' pipelines (default: its own); ``correct(fix, pose)``: each located fix as corrected beyond the
    telemetry (a reference in view: :meth:`groundstation.live.reference_live.LiveReference.correct`);
    ``on_tracked``: see :attr:`on_tracked`.
    """

    def __init__(
        self,
        cal: Calibration,
        tel: Telemetry,
        tracker: str,
        sinks: Sequence,
        queue_len: int = 2,
        telemetry_wait_s: float = 0.3,
        prior: Callable[[float], Prior | None] | None = None,
        history_s: float = 1.0,
        on_tracked: Sequence[Callable] = (),
        alignment: Callable[[], tuple[str, float]] | None = None,
        depth: Series | None = None,
        vet: Callable[[int, tuple | None], str | None] | None = None,
        tracking: Executor | None = None,
        poses: FramePoses | None = None,
        correct: Callable[[Fix, CameraPose], Fix] | None = None,
    ):
        self.cal = cal
        self.tel = tel
        self.session = TrackingSession(cal, tracker)  # ValueError for an unknown tracker
        self._grey = tracker in GREY_TRACKERS  # it reads a frame's luma plane where it has one
        # the reported pixel held to the vehicle's silhouette through waves
        self.centre = CentroidSteer()
        self.sinks = list(sinks)
        self.queue_len = queue_len
        self.telemetry_wait_s = telemetry_wait_s
        self.prior = prior or (lambda t_unix: None)
        self.history_s = history_s
        self.alignment = alignment
        self.depth = depth
        self.vet = vet
        self.tracking = tracking
        self.poses = poses or FramePoses(cal, tel)
        self.correct = correct
        self._told_unknown = False
        self._queue: deque[LiveFrame] = deque()
        self._ready = asyncio.Event()
        self._commands: deque[tuple[Callable, asyncio.Future]] = deque()
        self._tracked: deque[Tracked] = deque()  # waiting for their telemetry
        self._tracked_ready = asyncio.Event()
        self._telemetry = asyncio.Event()
        self._held: deque[Tracked] = deque()  # recent tracked frames, for selections
        # the first frame was taken, or a command came first: init_bbox no longer applies
        self._started = False
        # the operator's select, release and acquire commands done: a frame's FrameInfo.lock
        self.commands = 0
        self._angle_series = [tel.attitude] + (
            [tel.gimbal]
            if cal.mount.attitude_source == "gimbal_device"
            else [tel.mount]
            if cal.mount.attitude_source == "mount_orientation"
            else []
        )
        self.waited_s = 0.0  # total time frames waited for telemetry
        self.held = 0  # frames that waited for telemetry
        self._holding: int | None = None
        self.processed = 0
        self.dropped = 0
        self.statuses: Counter[str] = Counter()
        self.last_status: str | None = None
        # how ``[tracker] init_bbox`` was taken (None: not configured, or not yet): kept, snapped, refused, unchecked
        self.init_bbox: str | None = None
        # init_bbox was taken without a camera pose: checked on the first frame tracked with one (unless a command
        # came first)
        self._unchecked = False
        # a box being checked over frames (init_bbox's, or the operator's): how to name its verdict (see _checked)
        self._checking: _Checking | None = None
        # the operator's selection awaiting the check's verdict (the held frames did not span it), and its answer's
        # frame and catch-up
        self._answer: asyncio.Future | None = None
        self._answer_info: dict = {}
        # the tracking session's status after the latest frame or command
        self.target = self._status()
        #: ``listener(image, pose, u, v)`` for each located frame with an ok track (its one-frame pose, the pixel)
        self.on_tracked: list[Callable] = list(on_tracked)

    def submit(self, frame: LiveFrame) -> None:
        """Queue a frame (on the event loop); drops the oldest waiting frame when the queue is full.

        The very first frame is never dropped when ``init_bbox`` belongs to it. Its arrival on the monotonic clock
        is taken now when the reader did not give it.
        """
        if frame.t_recv_mono is None:
            frame.t_recv_mono = time.monotonic() - (time.time() - frame.t_recv)
        if len(self._queue) >= self.queue_len:
            first_waiting = (
                self.cal.init_bbox is not None and not self._started and self._queue[0].index == 0
            )
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

    # -- operator commands -------------------------------------------------------------------------
    async def select(self, frame: int | None = None, box=None, point=None) -> dict:
        """Track the UUV in ``box`` (x, y, w, h) or at ``point`` (u, v) of held frame ``frame`` (default: the newest).

        Raises :class:`~localizer.tracking.session.SelectionError` for a frame no longer
        held, a box outside it, a click with nothing there.
        """
        answer = await self._command(lambda: self._select(frame, box, point))
        if not isinstance(answer, asyncio.Future):
            return answer
        try:  # a box still being checked when the held frames ran out: its verdict on the frames to come
            return await asyncio.wait_for(asyncio.shield(answer), VERDICT_WAIT_S)
        except TimeoutError:  # no verdict yet (the stream stalled): the target says "confirming"
            self._answer = None
            return {
                **self._answer_info,
                "target": self.target,
                "latest_frame": self._latest_frame(),
            }

    async def release(self) -> dict:
        """Let go of the target: no fix until a new selection (or :meth:`acquire`)."""
        return await self._command(self._release)

    async def acquire(self) -> dict:
        """Await a target again: a selection, or automatic acquisition from the prior."""
        return await self._command(self._acquire)

    async def _command(self, command: Callable) -> dict:
        done = asyncio.get_running_loop().create_future()
        self._commands.append((command, done))
        self._ready.set()
        return await done

    async def _select(self, index: int | None, box, point) -> dict | asyncio.Future:
        if not self._held:
            raise SelectionError("no frame received yet")
        held = (
            self._held[-1]
            if index is None
            else next((h for h in self._held if h.frame.index == index), None)
        )
        if held is None:
            raise SelectionError(
                f"frame {index} is not held (held: frames {self._held[0].frame.index}"
                f"…{self._held[-1].frame.index}, the last {self.history_s:g} s)"
            )
        later = [h for h in self._held if h.frame.index > held.frame.index]

        def select_and_catch_up() -> TrackResult | None:
            """The selection and the held frames after it; None: the box refused on them."""
            self.centre.restart()
            image = self._seen(held.frame)
            result = self._steered(
                held,
                self.session.select(
                    image,
                    held.pose,
                    box=box,
                    point=point,
                    verify=True,
                    steady=box is not None,
                    chroma=held.frame.colour(),
                ),
            )
            self._checking = _Checking(held.frame.index, box) if self.session.check else None
            for h in later:
                result = self._steered(
                    h,
                    self.session.step(self._seen(h.frame), h.pose, chroma=h.frame.colour()),
                )
                if self._checking is not None and self.session.check != "confirming":
                    self._checking = None
                    if self.session.check.startswith("refused"):
                        self.centre.restart()
                        return None
            return result

        result = await asyncio.get_running_loop().run_in_executor(
            self.tracking, select_and_catch_up
        )
        self._started = True
        self.commands += 1
        self.target = self._status()
        if result is None:  # refused by the check over the held frames: awaiting a target
            raise SelectionError(self.session.check.removeprefix("refused: "))
        log.info(
            "target selected on frame %d (%s %s), caught up %d frames: %s",
            held.frame.index,
            "point" if point is not None else "box",
            list(point if point is not None else box),
            len(later),
            self.target["state"],
        )
        self._answer_info = {"frame": held.frame.index, "caught_up": len(later)}
        if (
            self._checking is not None
        ):  # the held frames did not span the check: answered on its verdict
            self._answer = asyncio.get_running_loop().create_future()
            return self._answer
        return self._answered(result)

    def _answered(self, result: TrackResult) -> dict:
        """A selection's answer once taken: where the target is on the latest frame tracked."""
        return {
            **self._answer_info,
            "u": result.u,
            "v": result.v,
            "box": list(result.box) if result.box else None,
            "latest_frame": self._latest_frame(),
            "target": self.target,
        }

    def _give_verdict(self, result: TrackResult) -> None:
        """The operator's box checked over the frames after the held ones: its answer (on the loop)."""
        answer, self._answer = self._answer, None
        if answer.done():  # timed out
            return
        verdict = self.session.check
        if verdict.startswith("refused"):
            answer.set_exception(SelectionError(verdict.removeprefix("refused: ")))
        else:
            answer.set_result(self._answered(result))

    async def _release(self) -> dict:
        self._started = True  # the operator's word wins over init_bbox
        self.commands += 1
        self.session.release()
        self.centre.restart()
        for item in self._tracked:  # tracked before the release, not yet located: no fix from them
            item.result = TrackResult("released")
        self.target = self._status()
        log.info("target released")
        return {"latest_frame": self._latest_frame(), "target": self.target}

    async def _acquire(self) -> dict:
        self._started = True
        self.commands += 1
        self.session.acquire()
        self.centre.restart()
        self.target = self._status()
        log.info("awaiting a target")
        return {"latest_frame": self._latest_frame(), "target": self.target}

    def _status(self) -> dict:
        """The tracking session's status and how ``init_bbox`` was taken."""
        return {**self.session.status(), "init_bbox": self.init_bbox}

    def _latest_frame(self) -> int | None:
        """The newest frame tracked: the command applies to every later frame."""
        return self._held[-1].frame.index if self._held else None

    # -- frames --------------------------------------------------------------------------------------
    async def _track_frames(self) -> None:
        while True:
            if self._commands:
                command, done = self._commands.popleft()
                if (
                    self._answer is not None
                ):  # a selection still being checked: this command comes first
                    answer, self._answer = self._answer, None
                    if not answer.done():
                        answer.set_exception(
                            SelectionError("a later command came before the box was checked")
                        )
                try:
                    done.set_result(await command())
                except (SelectionError, ValueError) as e:
                    done.set_exception(e)
                continue
            if not self._queue:
                self._ready.clear()
                await self._ready.wait()
                continue
            frame = self._queue.popleft()
            self._tracked.append(await self._track(frame))
            self._tracked_ready.set()

    def _early(self, frame: LiveFrame) -> bool:
        """Whether the frame is further past its newest attitude telemetry than :data:`EXTRAPOLATE_S`."""
        t = float(self.tel.uav_time(frame.t_unix)) - EXTRAPOLATE_S
        return any(s.last_t is None or s.last_t < t for s in self._angle_series)

    def _pose(self, frame: LiveFrame, again: bool = False) -> CameraPose:
        """The camera at the frame's time, with the telemetry there is now (on the loop; ``again``: when it was
        early, see :class:`FramePoses`), and this UUV's depth."""
        alignment = self.alignment() if self.alignment is not None and frame.aligned else None
        depth = self.tel.depth if self.depth is None else self.depth
        return with_depth(self.cal, self.poses.pose(frame, alignment, again), depth)

    async def _track(self, frame: LiveFrame) -> Tracked:
        """Track one frame with its pose (computed here, on the loop) and hold it for selections."""
        pose = self._pose(frame)
        early = self._early(frame)
        prior = self.prior(frame.t_unix)
        result = await asyncio.get_running_loop().run_in_executor(
            self.tracking, self._step, frame, pose, prior
        )
        item = Tracked(
            frame, pose, result, early, search_window(self.session.sought), self.commands
        )
        self._held.append(item)
        while (
            len(self._held) > MAX_HELD or frame.t_recv - self._held[0].frame.t_recv > self.history_s
        ):
            self._held.popleft()
        self.target = self._status()
        if self._answer is not None and self._checking is None:
            self._give_verdict(result)
        return item

    def _seen(self, frame: LiveFrame) -> np.ndarray:
        """The frame as the tracker reads it: its luma plane for a tracker of grey levels (as offline), else BGR."""
        return frame.grey if self._grey and frame.grey is not None else frame.image

    def _step(self, frame: LiveFrame, pose: CameraPose, prior: Prior | None) -> TrackResult:
        image = self._seen(frame)
        if not self._started:
            self._started = True
            if self.cal.init_bbox is not None:
                try:
                    return self.centre.after(
                        self.session, image, self._init_select(frame, image, pose), frame.t_unix
                    )
                except SelectionError as e:
                    self.init_bbox = f"refused: {e}"
                    log.warning(
                        "tracker.init_bbox on frame %d: %s; awaiting a target", frame.index, e
                    )
        result = self.session.step(image, pose, prior=prior, chroma=frame.colour())
        if self._checking is not None and self.session.check != "confirming":
            self._checked(frame, result)
        if self._unchecked and not self.commands and result.ok and pose.status[0] == "ok":
            result = self._check_late(frame, image, pose, result)
        return self.centre.after(self.session, image, result, frame.t_unix)

    def _init_select(self, frame: LiveFrame, image, pose: CameraPose) -> TrackResult:
        """The first frame selected with ``[tracker] init_bbox``, checked over the frames after it as an operator's box
        is (:meth:`_checked` names the verdict); without a camera pose, taken unchecked (:meth:`_check_late`)."""
        box = self.cal.init_bbox
        result = self.session.select(
            image,
            pose,
            box=box,
            verify=True,
            keep_drawn=True,
            steady=True,
            chroma=frame.colour(),
        )
        if self.session.check == "confirming":
            self._checking = _Checking(frame.index, box, init=True)
            self.init_bbox = (
                f"confirming: checked over the frames of {STEADY_S:g} s from frame {frame.index}"
            )
        else:  # no pose to size the vehicle there
            self._unchecked = pose.status[0] != "ok"
            self.init_bbox = (
                f"unchecked: no camera pose on frame {frame.index} ({pose.status[0]})"
                if self._unchecked
                else "kept"
            )
        return result

    def _check_late(
        self, frame: LiveFrame, image, pose: CameraPose, result: TrackResult
    ) -> TrackResult:
        """An ``init_bbox`` taken unchecked (its frame had no camera pose to size the vehicle), checked from the
        first frame tracked with a pose as it would have been from its own: the tracked box kept, snapped onto the
        vehicle's outline, or refused (awaiting a target). Without this, a box drawn on open water would be tracked
        as the seafloor and every fix once the telemetry arrives would be wrong."""
        self._unchecked = False
        checking = self.session.select(
            image,
            pose,
            box=result.box,
            verify=True,
            keep_drawn=True,
            steady=True,
            chroma=frame.colour(),
        )
        if (
            self.session.check != "confirming"
        ):  # the box's pixel not on the water: nothing to size the vehicle
            self.init_bbox = f"kept: checked on frame {frame.index}, the first with a camera pose"
            return checking
        self._checking = _Checking(frame.index, result.box, init=True, late=True)
        self.init_bbox = (
            f"confirming: checked over the frames of {STEADY_S:g} s from frame {frame.index}, the first with a "
            "camera pose"
        )
        return checking

    def _checked(self, frame: LiveFrame, result: TrackResult) -> None:
        """A box checked over frames taken or refused on this frame: said (init_bbox's status) and logged."""
        checking, self._checking = self._checking, None
        verdict = self.session.check
        if verdict is None:  # a command came first
            return
        if verdict != "kept":
            self.centre.restart()  # the steer's outline was of the box as drawn
        if not checking.init:
            if verdict.startswith("refused"):
                log.warning("selection on frame %d %s; awaiting a target", checking.frame, verdict)
            return
        first = f"on frame {checking.frame}, the first with a camera pose" if checking.late else ""
        box = list(checking.box)
        if verdict == "kept":
            self.init_bbox = f"kept: checked {first}" if first else "kept"
            return
        if verdict == "snapped":
            self.init_bbox = (
                f"snapped {first}: the tracked box {box} is off the vehicle; its outline {list(result.box)} taken"
                if first
                else f"snapped: {box} is off the vehicle; its outline {list(result.box)} taken"
            )
        else:
            self.init_bbox = (
                f"{verdict.replace('refused', f'refused {first}', 1)}" if first else verdict
            )
        awaiting = "; awaiting a target" if verdict.startswith("refused") else ""
        if first:
            log.warning("tracker.init_bbox: %s%s", self.init_bbox, awaiting)
        else:
            log.warning(
                "tracker.init_bbox on frame %d: %s%s",
                checking.frame,
                self.init_bbox.removeprefix("refused: "),
                awaiting,
            )

    def _steered(self, held: Tracked, result: TrackResult) -> TrackResult:
        """A held frame's ``result`` (a selection, a catch-up) steered as :meth:`_step`'s."""
        return self.centre.after(self.session, self._seen(held.frame), result, held.frame.t_unix)

    async def _locate_frames(self) -> None:
        loop = asyncio.get_running_loop()
        while True:
            if not self._tracked:
                self._tracked_ready.clear()
                await self._tracked_ready.wait()
                continue
            item = self._tracked[0]
            if item.early and item.result.ok:
                left = item.frame.t_recv + self.telemetry_wait_s - time.time()
                if left > 0 and self._early(item.frame):
                    if self._holding != item.frame.index:
                        self._holding = item.frame.index
                        self.held += 1
                    self._telemetry.clear()
                    t0 = loop.time()
                    try:
                        await asyncio.wait_for(self._telemetry.wait(), timeout=left)
                    except TimeoutError:
                        pass
                    self.waited_s += loop.time() - t0
                    continue
                item.pose, item.early = self._pose(item.frame, again=True), False
            self._tracked.popleft()
            if item.result.ok:
                for listener in self.on_tracked:
                    listener(item.frame.image, item.pose, item.result.u, item.result.v)
            self._emit(item.frame, self._locate(item), item.result.box, item.window, item.lock)

    def _emit(self, frame: LiveFrame, fix: Fix, box=None, window=None, lock: int = 0) -> None:
        for notice in take_notices(self.tel):  # height sources that disagree
            log.warning("%s", notice)
        info = FrameInfo(
            frame.index,
            frame.t_recv,
            time.time(),
            tuple(box) if box is not None else None,
            window,
            frame.t_recv_mono,
            lock,
        )
        self.processed += 1
        self.statuses[fix.status] += 1
        if fix.status != self.last_status:
            log.info("frame %d: status %s", frame.index, fix.status)
        self.last_status = fix.status
        for sink in self.sinks:
            sink.on_fix(fix, info)

    async def process(self, frame: LiveFrame) -> Fix:
        """The fix of one frame with the telemetry there is now (status says why when there is none)."""
        item = await self._track(frame)
        if item.early:
            item.pose = self._pose(frame, again=True)
        return self._locate(item)

    def _locate(self, item: Tracked) -> Fix:
        """A tracked frame's fix, with its pose."""
        frame, result = item.frame, item.result
        doubt = (
            self.vet(frame.index, tuple(result.box) if result.ok else None) if self.vet else None
        )
        if not result.ok:
            fix = Fix(frame.t_unix, result.status)
        elif doubt:
            fix = Fix(frame.t_unix, doubt, result.u, result.v)
        elif not frame.aligned:
            fix = Fix(frame.t_unix, "latency_unsettled", result.u, result.v)
        else:
            fix = locate(self.cal, item.pose, result.u, result.v, sigma_px=result.sigma_px)[0]
            if self.correct is not None:
                fix = self.correct(fix, item.pose)
            if fix.ok and fix.time_source == "unknown" and not self._told_unknown:
                self._told_unknown = True
                log.warning(
                    "frame %d: the UAV link's delay is unknown (no [timing] mavlink_latency_s, no TIMESYNC "
                    "reply yet): taken as 0, h_acc includes ±%.0f ms of it ([timing] "
                    "unknown_latency_sigma_s) × the camera's motion",
                    frame.index,
                    self.tel.latency_sigma_s * 1000,
                )
        fix.frame = frame.index
        fix.confidence = result.confidence
        return fix

    def status(self) -> dict:
        return {
            "processed": self.processed,
            "dropped": self.dropped,
            "queued": len(self._queue),
            "waiting_for_telemetry": len(self._tracked),
            "held_for_telemetry": self.held,
            "waited_s": round(self.waited_s, 3),
            "held_frames": len(self._held),
            "last_status": self.last_status,
            "statuses": dict(self.statuses),
        }

"""The camera's height over the water from the UUV's size in the video: measured frame by frame, estimated over a
window, checked against the configured height and (``auto``) handed to the height's fusion.

``--height-from-size`` (``skyfix run``, ``process``, ``evaluate``):

- ``off``: nothing is measured;
- ``check`` (the default): frames whose tracker status is ``ok`` are measured (at most
  :data:`MEASURE_HZ` a second, :data:`SURE_HZ` while the estimate is sure:
  :func:`localizer.tracking.silhouette.measure`, the vehicle's size from ``[uuv]``), the bias of the configured height against them estimated over a sliding window
  (:class:`localizer.size_range.HeightBias`) and shown (the status's ``height_from_size``, the web
  page); once the estimate is sure, one warning line when the configured height is off by more than
  twice both uncertainties together (again only when the bias has changed by half that since);
- ``auto``: also, while the estimate is sure, each measurement that agrees with it (3 sigmas) is
  handed to the height's fusion as an absolute measurement: ``Telemetry.add_height("size", ...)``
  with its 1-sigma (its own and the error every measurement shares); those of the window before it
  became sure too. A single frame, an outline locked on the vehicle's inner structure, never is.

The UUVs of one video (``skyfix process --uuv all``) share one estimate (:func:`shared_sizes`,
:class:`SharedEstimate`): the camera's height above the water is the same for all, so the frames measured a second
are one UUV's, taken in turn, and each UUV's heights are checked against the others'.

:class:`HeightFromSize` is the work, the same offline (in the tracker's pass over the video,
:mod:`groundstation.offline.track`) and live; :class:`OnlineHeightFromSize` runs it in ``skyfix run``
like the video latency's estimate: frames handed from the pipeline, on the event loop, to a thread
(skipped while it is busy: never stalling decoding or tracking) that has each measured in a
low-priority process of its own, the frame handed over through shared memory (:class:`SharedFrame`: pickling a
1080p frame into the process's pipe held the interpreter's lock for 3-15 ms, five times a second, against
decoding and tracking; a copy into shared memory releases it) (:func:`measure_frame`: a measurement was 60 ms of Python and
NumPy at 720p, 120 ms at 1080p, ~20 ms at 1080p since its corners' rays meet the water by Newton's
method and its support scan samples less, ~12 ms since the scan samples along rows of points and further
out only where an edge is near (issue 18: 28.8 → 17.1 ms of CPU, medians over the 195 measurements of
``bench/offline_speed.py``'s 1080p session on a busy machine, the same results); in a thread it held the
interpreter's lock against decoding and tracking — measured with ``bench/live_latency.py``),
the results handed back to the loop, where the telemetry is written.
"""

from __future__ import annotations

import asyncio
import ctypes
import dataclasses
import importlib
import logging
import math
import os
import queue
import signal
import sys
import threading
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from multiprocessing.shared_memory import SharedMemory

import numpy as np

from groundstation.runtime.threads import (
    OUTSIDE_REALTIME,
    Supervised,
    background_nice,
    in_thread,
)
from localizer.calibration import Calibration
from localizer.pose import CameraPose
from localizer.size_range import (
    MIN_BLOCKS,
    BiasEstimate,
    HeightBias,
    SizeHeight,
    size_height,
)
from localizer.telemetry import Telemetry
from localizer.tracking.silhouette import measure

log = logging.getLogger("skyfix.size")

MODES = ("auto", "check", "off")
SOURCE = "size"  # the height source's word (Telemetry.add_height)
MEASURE_HZ = 5.0  # frames measured a second, at most ...
#: ... and while the estimate is sure. Its 1-sigma is then the error every measurement shares (the vehicle's size,
#: the edges' bias, the depth), which more frames do not reduce: on ``bench/offline_speed.py``'s 1080p session
#: (40 s) measuring at 5, 2 and 1 Hz throughout gave +0.03, +0.02, +0.02 ± 0.09 m from 141, 56 and 29 frames. Once
#: sure, a frame a second keeps the window watching at a fifth of the CPU (offline, the measurements were a fifth
#: of ``skyfix process``'s CPU at 1080p; live, they compete with decoding for the cores).
SURE_HZ = 1.0
#: With several UUVs sharing one estimate, a UUV's turn is put off this many of the schedule's periods for each of
#: its measurements in a row without a height (at most MAX_FAILED of them: its view may change).
FAILED_TURNS = 1.0
MAX_FAILED = 8
STOP_WAIT_S = 1.0  # a stop waits this long for the measuring thread
PR_SET_PDEATHSIG = 1  # prctl(2): the signal a process gets when its parent dies


def measure_frame(
    cal: Calibration, image: np.ndarray, pose: CameraPose, i: int, u: float, v: float
) -> SizeHeight | str:
    """:meth:`HeightFromSize.measure`, a function of its arguments alone (run in the live service's measuring
    process)."""
    if pose.status[i] != "ok":
        return "no_pose"
    n = cal.water.refractive_index
    m = measure(
        image,
        cal.camera,
        pose.R_ned_from_cv[i],
        u,
        v,
        cal.uuv,
        float(pose.height_m[i]),
        float(pose.depth_m[i]),
        n,
    )
    if isinstance(m, str):
        return m
    return size_height(
        float(pose.t_unix[i]),
        m.camera_height_m,
        m.sigma_m,
        m.size_px,
        float(pose.cam_offset_ned_m[i, 2]),
        float(pose.uav_height_m[i]),
        float(pose.sigma_height_m[i]),
        float(pose.depth_m[i]),
        float(pose.sigma_depth_m[i]),
        n,
    )


class SharedFrame:
    """One frame at a time in shared memory, from the service to its measuring process (see the module doc): the
    block is made for the first frame (again for a larger one) and unlinked by :meth:`close`."""

    def __init__(self):
        self.block: SharedMemory | None = None

    def put(self, image: np.ndarray) -> tuple[str, tuple[int, ...], str]:
        """Copy ``image`` in (the interpreter's lock released: numpy's copy of a large array); what
        :func:`measure_shared` reads it by: (the block's name, the shape, the dtype)."""
        if self.block is None or self.block.size < image.nbytes:
            self.close()
            self.block = SharedMemory(create=True, size=image.nbytes)
        view = np.ndarray(image.shape, image.dtype, buffer=self.block.buf)
        np.copyto(view, image)
        del view  # no view may outlive the block's close
        return self.block.name, image.shape, image.dtype.str

    def close(self) -> None:
        if self.block is not None:
            self.block.close()
            self.block.unlink()
            self.block = None


#: The measuring process's view of the service's shared frame: its block, by name (a new name: a new block).
_attached: dict[str, SharedMemory] = {}


def measure_shared(
    cal: Calibration,
    frame: tuple[str, tuple[int, ...], str],
    pose: CameraPose,
    i: int,
    u: float,
    v: float,
) -> SizeHeight | str:
    """:func:`measure_frame` of the frame :meth:`SharedFrame.put` put into shared memory (the measuring process)."""
    return measure_frame(cal, shared_image(frame), pose, i, u, v)


def shared_image(frame: tuple[str, tuple[int, ...], str]) -> np.ndarray:
    """The frame :meth:`SharedFrame.put` put into shared memory, as an array over it (a measuring process)."""
    name, shape, dtype = frame
    if name not in _attached:
        for old in _attached.values():  # the service made a new block
            old.close()
        _attached.clear()
        _attached[name] = SharedMemory(name=name)
    return np.ndarray(shape, np.dtype(dtype), buffer=_attached[name].buf)


def start_measuring_process() -> None:
    """The measuring process yields the CPU (10 nice levels below the service,
    :func:`~groundstation.runtime.threads.background_nice`; it starts outside the realtime policy and at the normal
    nice value at most, :data:`~groundstation.runtime.threads.OUTSIDE_REALTIME`), and ends with the service even
    when the service is killed (Linux's parent-death signal): a ``kill -9`` of ``skyfix run`` leaves no process
    behind."""
    os.setpriority(os.PRIO_PROCESS, 0, background_nice())
    if sys.platform == "linux":
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
        if os.getppid() == 1:  # the service died before the signal was asked for
            os._exit(0)


class HeightFromSize:
    """Measurements of one run and their estimate (see the module doc); :meth:`measure` is pure (any thread),
    :meth:`take` and :meth:`due` change the state (one thread: the event loop live).

    ``shared``: the estimate of another UUV of the same video, which this one's measurements join
    (:func:`shared_sizes`, :class:`SharedEstimate`); by default one of its own."""

    def __init__(
        self,
        cal: Calibration,
        tel: Telemetry,
        mode: str,
        measure_hz: float = MEASURE_HZ,
        sure_hz: float = SURE_HZ,
        shared: HeightFromSize | None = None,
        name: str = "",
    ):
        if mode not in MODES[:2]:
            raise ValueError(
                f"height_from_size = {mode!r}: expected one of {', '.join(MODES[:2])} to measure"
            )
        self.cal, self.tel, self.mode, self.name = cal, tel, mode, name
        self.shared = shared.shared if shared is not None else SharedEstimate(measure_hz, sure_hz)
        self.shared.members.append(self)
        self.last: SizeHeight | None = None
        self.measured = 0
        self.rejected: Counter[str] = Counter()
        self.applied = 0
        self.warnings: list[str] = []
        # the estimate its heights were left out of (they disagree with the other UUVs'), or None
        self.left_from: SharedEstimate | None = None
        self._applied_t = -math.inf

    @property
    def left_out(self) -> bool:
        return self.left_from is not None

    @property
    def estimate(self) -> BiasEstimate | None:
        return self.shared.estimate

    @property
    def window(self) -> HeightBias:
        return self.shared.window

    def due(self, t_unix: float) -> bool:
        """Whether the frame at ``t_unix`` is to be measured (at most ``measure_hz`` a second, ``sure_hz`` while the
        estimate is sure, for all the UUVs sharing it together: :meth:`SharedEstimate.due`); counts it if so."""
        return self.shared.due(self, t_unix)

    def asks_estimate(self, t_unix: float) -> bool:
        """Whether :meth:`due` at ``t_unix`` depends on the measurements taken so far (on whether their estimate is
        sure, and with several UUVs which of them failed lately). False while the frame is too soon after the last
        one counted however sure the estimate is: the measurements still being made elsewhere need not have been
        taken yet (``skyfix process``'s measuring process, :class:`groundstation.offline.uuv_workers.SizeWorker`)."""
        return self.shared.asks_estimate(t_unix)

    def measure(
        self, image: np.ndarray, pose: CameraPose, i: int, u: float, v: float
    ) -> SizeHeight | str:
        """The UAV's height above the water at the pose's frame ``i`` from the UUV's outline around its tracked pixel
        (u, v), or why not (a word of :data:`localizer.tracking.silhouette.REJECTIONS`, or ``no_pose``)."""
        return measure_frame(self.cal, image, pose, i, u, v)

    def take(self, result: SizeHeight | str) -> None:
        """A measurement (or why there is none): into the window; the estimate, the warning and, with ``auto``,
        the measurements handed to the height's fusion."""
        if isinstance(result, str):
            self.rejected[result] += 1
            self.shared.failed(self)
            return
        self.measured += 1
        self.last = result
        self.shared.take(self, result)

    def warn(self, text: str) -> None:
        log.warning("%s", text)
        self.warnings.append(text)

    def hand_over(self, e: BiasEstimate) -> None:
        """``auto``: the window's measurements not handed over yet that agree with the sure estimate ``e``, to the
        height's fusion."""
        for h in self.window.heights:
            if h.t_unix > self._applied_t and e.agrees(h):
                if self.tel.add_height(
                    SOURCE, float(self.tel.uav_time(h.t_unix)), h.uav_height_m, h.sigma_total_m
                ):
                    self.applied += 1
                self._applied_t = h.t_unix

    def summary(self) -> str:
        """One line: the estimate, or why there is none."""
        e = self.estimate
        shared = self.shared.described(self)
        if e is None:
            why = (
                ", ".join(f"{k} {n}" for k, n in self.rejected.most_common())
                or "no frame with the UUV tracked"
            )
            return f"height from the UUV's size: no measurement ({why}){shared}"
        return (
            f"height from the UUV's size: configured - measured {e.bias_m:+.2f} ± {e.sigma_m:.2f} m over "
            f"{e.frames} frames ({e.blocks} s, {e.at_surface:.0%} at the surface, {e.outliers} outliers left out, "
            f"{sum(self.rejected.values())} frames without a measurement), {'sure' if e.sure else 'not sure'}"
            + (f"; {self.applied} measurements applied" if self.mode == "auto" else "")
            + shared
        )

    def status(self) -> dict:
        def num(x, digits=3):
            return None if x is None or not math.isfinite(x) else round(float(x), digits)

        e, last = self.estimate, self.last
        return {
            "mode": self.mode,
            "measured": self.measured,
            "rejected": dict(self.rejected),
            "applied": self.applied,
            "bias_m": num(e and e.bias_m),
            "sigma_m": num(e and e.sigma_m),
            "sigma_common_m": num(e and e.sigma_common_m),
            "frames": e.frames if e else 0,
            "outliers": e.outliers if e else 0,
            "seconds": e.blocks if e else 0,
            "sure": bool(e and e.sure),
            "at_surface_share": num(e and e.at_surface, 2),
            "last_t": num(last and last.t_unix),
            "last_height_m": num(last and last.uav_height_m),
            "last_sigma_m": num(last and last.sigma_total_m),
        }


def shared_sizes(
    sessions, mode: str, measure_hz: float = MEASURE_HZ, sure_hz: float = SURE_HZ
) -> list[HeightFromSize]:
    """One :class:`HeightFromSize` per UUV of one video (``sessions``: the session read as each UUV's), all sharing
    one estimate (:class:`SharedEstimate`): the camera's height above the water is the same for every UUV."""
    sizes: list[HeightFromSize] = []
    for s in sessions:
        sizes.append(
            HeightFromSize(
                s.calibration,
                s.telemetry,
                mode,
                measure_hz,
                sure_hz,
                shared=sizes[0] if sizes else None,
                name=s.uuv_id,
            )
        )
    return sizes


class SharedEstimate:
    """The camera's height above the water from the size of every UUV of one video (their :class:`HeightFromSize`,
    ``members``): one window, one estimate, one measuring schedule for them all (``skyfix process --uuv all``,
    issue 30: each UUV measured at the rate of one, its CPU divided by the UUVs').

    - The schedule (:meth:`due`): a frame is due at most ``measure_hz`` a second (``sure_hz`` while sure) for all
      the UUVs together; it goes to the UUV asking whose turn is oldest: its last measurement's time, put off by
      :data:`FAILED_TURNS` of the schedule's period times its measurements in a row that gave no height (a UUV whose
      outline cannot be measured in this view takes fewer turns, not the others' share). A UUV counts as asking
      while it asked within ``1 / measure_hz`` (one not tracked lately leaves its turn to the others). With one UUV
      this is :class:`HeightFromSize`'s own schedule, unchanged.
    - A measurement that fails adds nothing (no height: nothing to bias the estimate).
    - A UUV whose heights disagree with the others' (its depth or ``[uuv]`` size wrong: its heights are all off by
      the same) must not shift theirs silently (:meth:`_check`, at every height taken): each UUV whose heights in
      the window span :data:`~localizer.size_range.MIN_BLOCKS` seconds has an estimate of its own; two more than 3
      sigmas apart (each with the error its heights share) disagree. A UUV that disagrees with two or more others
      that agree with each other is left out: a warning names it, its heights leave the window, and it goes on
      with an estimate of its own from them, as a UUV alone (the range from its size is right for its own fixes
      even where its depth is wrong: the error moves into the height); the shared heights handed to its fusion
      before that, ``auto``, stay there. Two that disagree with no other to tell which is right: a warning names
      both, and the estimate is not sure (nothing handed over, no warning on the configured height) while they do.
      With heights of several UUVs in the window, the estimate is sure only once two of them can be checked so (a
      UUV alone with heights is checked by nothing, as with one UUV).
    - ``auto``: a measurement taken hands every member's telemetry the window's heights that agree with the sure
      estimate (the UAV's height is the same for all).
    """

    def __init__(self, measure_hz: float, sure_hz: float):
        self.period_s = 1.0 / measure_hz
        self.sure_period_s = 1.0 / sure_hz
        self.window = HeightBias()
        self.estimate: BiasEstimate | None = None
        self.members: list[HeightFromSize] = []
        self._last_t = -math.inf
        self._warned: float | None = None
        self._asked: dict[int, float] = {}  # member's index -> the time it last asked
        self._turn: dict[int, float] = {}  # member's index -> its turn's time (oldest goes first)
        # member's index -> its measurements in a row without a height
        self._fails: dict[int, int] = {}
        self._whose: dict[float, int] = {}  # t_unix of a height in the window -> its member's index
        # not sure for the UUVs' sake: two UUVs' heights disagree (none other tells which is right), or of several
        # UUVs with heights in the window fewer than two can be checked against each other yet
        self.doubt = False
        self._doubted: set[tuple[int, int]] = set()  # the pairs warned about

    def due(self, member: HeightFromSize, t_unix: float) -> bool:
        """See the class doc."""
        me = self.members.index(member)
        self._asked[me] = t_unix
        period = self._period()
        if t_unix - self._last_t < period - 0.005:
            return False
        if len(self.members) > 1:
            asking = [k for k, at in self._asked.items() if t_unix - at < self.period_s + 0.005]
            if min(asking, key=lambda k: (self._turn.get(k, -math.inf), k)) != me:
                return False
            self._turn[me] = t_unix
        self._last_t = t_unix
        return True

    def asks_estimate(self, t_unix: float) -> bool:
        """:meth:`HeightFromSize.asks_estimate`."""
        return t_unix - self._last_t >= min(self.period_s, self.sure_period_s) - 0.005

    def failed(self, member: HeightFromSize) -> None:
        """A measurement of ``member``'s gave no height: its next turns put off (see the class doc)."""
        me = self.members.index(member)
        fails = self._fails[me] = min(self._fails.get(me, 0) + 1, MAX_FAILED)
        self._turn[me] = self._turn.get(me, -math.inf) + fails * FAILED_TURNS * self._period()

    def take(self, member: HeightFromSize, h: SizeHeight) -> None:
        """A height of ``member``'s: into the window (unless left out); the estimate, the warning, the checks of
        the UUVs against each other and (``auto``) the heights handed to the fusion."""
        me = self.members.index(member)
        self._fails[me] = 0
        self.window.add(h)
        if len(self.members) > 1:
            self._whose[h.t_unix] = me
            self._whose = {x.t_unix: self._whose[x.t_unix] for x in self.window.heights}
            self._check()
        self._estimated()

    def _estimated(self) -> None:
        """The window's estimate; once sure, the warning and (``auto``) the heights handed to the fusion."""
        e = self.estimate = self.window.estimate()
        if e is not None and self.doubt:
            e = self.estimate = dataclasses.replace(e, sure=False)
        if e is None or not e.sure:
            return
        limit = 2.0 * math.hypot(e.sigma_m, e.configured_sigma_m)
        if abs(e.bias_m) > limit and (
            self._warned is None or abs(e.bias_m - self._warned) > limit / 2.0
        ):
            self._warned = e.bias_m
            self.members[0].warn(
                f"height from the UUV's size: the configured height above the water is {abs(e.bias_m):.2f} m "
                f"{'above' if e.bias_m > 0 else 'below'} what the UUV's size in the image says (± {e.sigma_m:.2f} m, "
                f"{e.frames} frames over {e.blocks} s, {e.at_surface:.0%} with the UUV at the surface; the "
                f"configured height's own 1-sigma {e.configured_sigma_m:.2f} m): check [water] "
                "takeoff_height_above_surface_m or surface_amsl_m, the barometer, and [uuv] (the vehicle's size)"
            )
        for m in self.members:
            if m.mode == "auto" and m.shared is self:
                m.hand_over(e)

    def _check(self) -> None:
        """The UUVs' heights in the window against each other (see the class doc)."""
        own = {}  # member's index -> the estimate of its own heights, where they span MIN_BLOCKS seconds
        for k, m in enumerate(self.members):
            mine = HeightBias()
            mine.heights = [h for h in self.window.heights if self._whose[h.t_unix] == k]
            e = mine.estimate() if m.shared is self else None
            if e is not None and e.blocks >= MIN_BLOCKS:
                own[k] = e

        def apart(i: int, j: int) -> bool:
            return abs(own[i].bias_m - own[j].bias_m) > 3.0 * math.hypot(
                own[i].sigma_m, own[j].sigma_m
            )

        for k in own:
            others = [j for j in own if j != k]
            if (
                len(others) >= 2
                and all(apart(k, j) for j in others)
                and not any(apart(i, j) for i in others for j in others if i < j)
            ):
                self._leave_out(k, own)
                self._check()
                return
        pairs = [(i, j) for i in own for j in own if i < j and apart(i, j)]
        having = {self._whose[h.t_unix] for h in self.window.heights}
        self.doubt = bool(pairs) or (len(having) > 1 and len(own) < 2)
        for i, j in pairs:
            if (i, j) not in self._doubted:
                self._doubted.add((i, j))
                a, b = own[i], own[j]
                first, second = self.members[i], self.members[j]
                first.warn(
                    f"height from the UUV's size: {first.name}'s and {second.name}'s heights disagree by "
                    f"{abs(a.bias_m - b.bias_m):.2f} m (± {math.hypot(a.sigma_m, b.sigma_m):.2f} m, {a.frames} and "
                    f"{b.frames} frames): the depth or [uuv] (the vehicle's size) of one of them is wrong; the "
                    "estimate is not sure until another UUV's heights tell which"
                )

    def _leave_out(self, k: int, own: dict) -> None:
        """The ``k``-th member's heights disagree with all the others', which agree: out of the estimate."""
        member = self.members[k]
        alone = member.shared = SharedEstimate(1.0 / self.period_s, 1.0 / self.sure_period_s)
        alone.members.append(member)
        alone.window.heights = [h for h in self.window.heights if self._whose[h.t_unix] == k]
        # its next frame a period after the last measured: the frames measured do not depend on when the result
        # that left it out was taken (SizeWorker takes them later, before the next frame that may be due)
        alone._last_t = self._last_t
        member.left_from = self
        self.window.heights = [h for h in self.window.heights if self._whose[h.t_unix] != k]
        self._asked.pop(k, None)
        rest = [j for j in own if j != k]
        others = HeightBias()
        others.heights = self.window.heights
        b, a = others.estimate(), own[k]
        apart = a.bias_m - b.bias_m
        member.warn(
            f"height from the UUV's size: {member.name}'s heights are {abs(apart):.2f} m "
            f"{'below' if apart > 0 else 'above'} those of {', '.join(self.members[j].name for j in rest)} "
            f"(± {math.hypot(a.sigma_m, b.sigma_m):.2f} m, {a.frames} and {b.frames} frames), which agree: check "
            f"{member.name}'s depth and [uuv] (the vehicle's size); its heights are left out of theirs, an estimate of "
            "its own serves its fixes"
        )
        alone._estimated()

    def described(self, member: HeightFromSize) -> str:
        """What a summary adds with several UUVs: the share, ``member``'s own part."""
        if member.left_from is not None:
            names = ", ".join(m.name for m in member.left_from.members if m.shared is not self)
            return f" ({member.name}'s own: its heights disagree with those of {names})"
        if len(self.members) < 2:
            return ""
        names = ", ".join(m.name for m in self.members if m.shared is self)
        return f" (one estimate for {names}; {member.name}'s heights: {member.measured} of them)"

    def _period(self) -> float:
        return (
            self.sure_period_s
            if self.estimate is not None and self.estimate.sure
            else self.period_s
        )


class OnlineHeightFromSize:
    """The live worker (see the module doc): ``on_tracked`` on the loop, the measuring in its own thread."""

    def __init__(self, work: HeightFromSize):
        self.work = work
        self.skipped = 0
        self._frames: queue.Queue = queue.Queue(maxsize=1)
        self._loop: asyncio.AbstractEventLoop | None = None
        self.worker = Supervised("height-from-size", self._run)

    def on_tracked(self, image: np.ndarray, pose: CameraPose, u: float, v: float) -> None:
        """A located frame whose tracker status is ok, with its final one-frame pose (event loop)."""
        if pose.status[0] != "ok" or not self.work.due(float(pose.t_unix[0])):
            return
        try:
            self._frames.put_nowait((image, pose, u, v))
        except queue.Full:
            self.skipped += 1

    async def run(self) -> None:
        self._loop = asyncio.get_running_loop()
        self.worker.start()
        try:
            await asyncio.Event().wait()
        finally:
            await in_thread(self.worker.join, STOP_WAIT_S, name="height-from-size stop")

    def _run(self, stop: threading.Event) -> None:
        """Hands each frame to the measuring process (started here: a restart after a failure starts a new one)."""
        pool = ProcessPoolExecutor(
            1, mp_context=OUTSIDE_REALTIME, initializer=start_measuring_process
        )
        # the process starts and imports now, not at the first frame
        pool.submit(importlib.import_module, __name__)
        shared = SharedFrame()
        try:
            while not stop.is_set():
                try:
                    image, pose, u, v = self._frames.get(timeout=0.2)
                except queue.Empty:
                    continue
                frame = shared.put(image)
                result = pool.submit(measure_shared, self.work.cal, frame, pose, 0, u, v).result()
                try:
                    self._loop.call_soon_threadsafe(self.work.take, result)
                except RuntimeError:  # the loop is closed: stopped
                    return
        finally:
            pool.shutdown(wait=False, cancel_futures=True)
            shared.close()

    def status(self) -> dict:
        return self.work.status() | {"frames_skipped": self.skipped, **self.worker.status()}

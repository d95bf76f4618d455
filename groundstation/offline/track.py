"""Tracking the UUV through a session's video, steered by the session's telemetry.

:func:`track_session` decodes the video (in a background thread; for a tracker of grey levels,
:data:`~localizer.tracking.GREY_TRACKERS`, to the frames' luma planes, converting to BGR only the frames
the height is measured in), selects the UUV
with ``[tracker] init_bbox`` on the frame of ``init_t`` (the first frame without
it), tracks it with a :class:`~localizer.tracking.session.TrackingSession` (the
same as the live service's) and returns per-frame pixels with a status word for
every row of ``video_frames.csv``; through waves each pixel is held to the vehicle's silhouette after the tracking
step and filtered in time (:class:`~localizer.tracking.centroid.CentroidSteer`: what is reported, never what is
tracked; the pixels before the filter kept beside them, ``u_unfiltered``, for the smoothed track):

``ok``; ``lost`` (the tracker has lost the UUV); ``before_init`` (a frame before
the one ``init_bbox`` belongs to); ``no_video`` (the frame is listed but could not
be decoded: truncated or corrupt video).

Forward and backward (``both_ways``; offline, the whole video is there): the frames the forward, causal pass
reports without the UUV just before a re-acquisition (hidden a moment by the waves, searched for, the candidate
being confirmed) are traced back from it once the frames after it confirm it (the forward pass keeps it
:data:`CONFIRM_BACK_S` without a loss; one lost again sooner, e.g. water that passed for the UUV while it was
hidden, is not traced): a second tracker starts on the re-acquired UUV and steps back through them (up to
:data:`BACKWARD_S` of them, kept decoded meanwhile) until it loses it; the frames it finds the UUV in are ``ok``
too (``bridged``). An occlusion stops it as it stops the forward pass: a hidden UUV is not bridged. Through waves
the frames without the UUV are traced back too from a frame soon after them (:data:`SURE_WITHIN_S`) that the forward
pass follows the UUV in standing out of the seafloor (:data:`SURE_DISTINCT`), by a copy of the forward tracker
(:meth:`~localizer.tracking.session.TrackingSession.back_from`): there a re-acquisition is soon followed by a frame
the waves hide the UUV in, and the waves lose it without an occlusion. Traced back from a restart by colour the
colour may still refute (:meth:`~localizer.tracking.session.TrackingSession.unproven`), the frames are bridged only
once the restart is proven: one on a place of the seafloor that showed the vehicle's colour for a few frames was
traced back through the frames the UUV was hidden in, and the colour refuted it three frames later.

Several UUVs of one session (:func:`track_sessions`) are tracked in one pass over the video: each frame is
decoded once and handed to every UUV's :class:`UuvTrack`; the UAV's pose of every frame and the video's motion are
computed once for all of them. Each UUV's result is the same as :func:`track_session` of that UUV alone.

The camera poses of all frames are computed at once and shared with the session
(which projects its predictions for many frames at a time). With ``measure_motion``
the camera's rotation between frames is measured too (every frame of a short recording, 10 a second of a
long one: :func:`~groundstation.latency.video_motion.measured_every`), in a thread beside the tracking
(:class:`~groundstation.latency.video_motion.MotionThread`; ``timings_s["motion"]``: the time waiting for it), for
the frames' offset to the
telemetry (:func:`groundstation.latency.estimate.offset_from_rotations`). With a
:class:`~groundstation.height_from_size.HeightFromSize`, frames the UUV is tracked in are
also measured for the camera's height from its size, in the same pass (``timings_s["size"]``), with
``size_process`` in a process beside it (:class:`~groundstation.offline.uuv_workers.SizeWorker`;
``timings_s["size_wait"]``: the time waiting for its last results): the same measurements, the same estimate.
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from groundstation.height_from_size import HeightFromSize
from groundstation.latency.video_motion import MotionThread, measured_every
from groundstation.offline.progress import progress as progress_bar
from groundstation.offline.uuv_workers import SizeWorker, TrackWorkers, available
from groundstation.session.read import Session, SessionError
from groundstation.video.frames import VideoError
from localizer.height import share as share_height_filter
from localizer.pose import uav_pose, with_depth
from localizer.tracking import GREY_TRACKERS
from localizer.tracking.centroid import CentroidSteer
from localizer.tracking.colour import Chroma
from localizer.tracking.session import SelectionError, TrackingSession
from localizer.tracking.target import TargetState

#: Offline, frames without the UUV are traced back from a re-acquisition through at most this many seconds of them.
BACKWARD_S = 3.0
#: ... once the forward pass has kept the re-acquired UUV this long (s) without a loss.
CONFIRM_BACK_S = 1.0
#: Through waves, also from a frame the forward pass follows the UUV in standing out of the seafloor this much (the
#: template matcher's ``distinct``: its vehicle-sized square over 9 in 10 of the seafloor's squares about it) ...
SURE_DISTINCT = 1.5
#: ... within this many seconds after the frames without it.
SURE_WITHIN_S = 0.5
#: What stepping a :class:`UuvTrack` changes (:meth:`UuvTrack.state`).
STEPPED = (
    "status",
    "u",
    "v",
    "conf",
    "sigma",
    "timings",
    "bridged",
    "u_unfiltered",
    "v_unfiltered",
    "causal_words",
    "started",
    "size_taken",
)


@dataclass
class TrackedVideo:
    """Per-frame results, one entry per row of ``video_frames.csv``."""

    frame: np.ndarray  # frame index
    t: np.ndarray  # UNIX seconds
    u: np.ndarray  # distorted pixels, NaN without a track
    v: np.ndarray
    status: np.ndarray  # object array of str
    confidence: np.ndarray  # tracker's 0..1, NaN when it has none
    sigma_px: np.ndarray  # tracker's 1-sigma of each of u and v (pixels), NaN without a track
    timings_s: dict = field(default_factory=dict)  # seconds spent per stage
    warnings: list = field(default_factory=list)
    # video_motion.Rotation between consecutive frames (measure_motion)
    rotations: list = field(default_factory=list)
    # bool: frames found by tracing a re-acquisition back (``both_ways``); else the causal pass's
    bridged: np.ndarray | None = None
    causal_status: np.ndarray | None = None  # the causal pass's words (status but where bridged)
    # the pixels before the motion filter through waves (CentroidSteer.unfiltered; u, v where it did not act)
    u_unfiltered: np.ndarray | None = None
    v_unfiltered: np.ndarray | None = None


def _init_row(session: Session, t: np.ndarray) -> int:
    cal = session.calibration
    if cal.init_t is None:
        return 0
    i = int(np.argmin(np.abs(t - cal.init_t)))
    period = float(np.median(np.diff(t))) if len(t) > 1 else math.inf
    if abs(t[i] - cal.init_t) > 0.5 * period:
        raise SessionError(
            f"{session.path / 'session.toml'}: tracker.init_t = {cal.init_t!r} matches no frame of video_frames.csv "
            f"({t[0]:.3f} … {t[-1]:.3f})"
        )
    return i


def track_session(
    session: Session,
    tracker_name: str = "default",
    progress: bool = False,
    measure_motion: bool = False,
    size: HeightFromSize | None = None,
    both_ways: bool = False,
) -> TrackedVideo:
    """Track the UUV through the session's video (see the module doc for statuses); ``size`` measures the camera's
    height from the UUV's size in the frames it is tracked in; ``both_ways``: re-acquisitions traced back too (see
    the module doc).

    Raises :class:`SessionError` for what makes tracking impossible: no video, no
    ``init_bbox``, an unknown tracker, a video that cannot be opened or whose frame
    size differs from the calibration, an init frame that cannot be decoded.
    """
    return track_sessions([session], tracker_name, progress, measure_motion, [size], both_ways)[0]


def track_sessions(
    sessions: list[Session],
    tracker_name: str = "default",
    progress: bool = False,
    measure_motion: bool = False,
    sizes: list[HeightFromSize | None] | None = None,
    both_ways: bool = False,
    workers: bool = False,
    size_process: bool = False,
) -> list[TrackedVideo]:
    """:func:`track_session` of several UUVs of one session (``sessions``: the session read as each UUV's,
    :func:`~groundstation.session.read.load_session` ``uuv``; ``sizes``: one each or None) in one pass over the
    video: each frame is decoded once, the UAV's pose of every frame computed once
    (:func:`~localizer.pose.uav_pose`, each UUV's depth added by :func:`~localizer.pose.with_depth`), the video's
    motion measured once (the same ``rotations`` in every result), and every UUV's :class:`UuvTrack` stepped on
    each frame. One result per session, each the same as :func:`track_session` of that session alone.

    ``workers``: each UUV's track stepped in a process of its own where the platform forks, the frames shared
    (:class:`~groundstation.offline.uuv_workers.TrackWorkers`; ``skyfix process --track-workers``), else in this
    process; the same results either way. Off by default: on a busy 2-core machine the workers cost CPU and time
    (``bench/offline_speed.py --uuvs``, ``docs/explanation/performance.md``). ``size_process``: without ``workers``,
    the heights from size measured in a process beside this one where the platform forks
    (:class:`~groundstation.offline.uuv_workers.SizeWorker`; ``skyfix process --beside``), else here; the same
    results either way, off by default for the same reason."""
    first = sessions[0]
    if first.video_path is None or first.frames is None:
        raise SessionError(f"{first.path}: no video.* with video_frames.csv to track")
    tracks = [
        UuvTrack(s, tracker_name, size, both_ways)
        for s, size in zip(sessions, sizes or [None] * len(sessions), strict=True)
    ]
    frame_idx = first.frames["frame"].astype(int)
    t = first.frames["t"]
    n = len(t)
    row_of = {int(f): i for i, f in enumerate(frame_idx)}
    timings = {"decode_wait": 0.0, "motion": 0.0, "hand_on": 0.0}
    period_s = float(np.median(np.diff(t))) if n > 1 else math.inf
    rotations = []
    read_warnings: list[str] = []

    t0 = time.perf_counter()
    uav = uav_pose(first.calibration, first.telemetry, t)
    for track in tracks:
        track.pose = with_depth(track.session.calibration, uav, track.session.telemetry.depth)
        # the UAV's height filter the pose ran, for each UUV's geometry after the pass (its telemetry a copy)
        share_height_filter(track.session.telemetry, first.telemetry)
    timings["pose"] = time.perf_counter() - t0

    cam = first.calibration.camera
    # forked before any thread of this pass starts (the motion meter's, the decoder's, the progress bar's)
    pool = TrackWorkers(tracks, 3 * cam.width * cam.height) if workers and available() else None
    measurer = (
        SizeWorker(tracks, 3 * cam.width * cam.height)
        if size_process and pool is None and available() and any(t.size is not None for t in tracks)
        else None
    )
    for track in tracks:
        track.measurer = measurer
    meter = MotionThread(cam, every=measured_every(n, period_s)) if measure_motion else None
    first_row = min(track.init_row for track in tracks)
    bar = progress_bar(n - first_row, f"{first.path.name}: tracking", progress)
    extra = 0
    try:
        with first.open_video(grey=tracker_name in GREY_TRACKERS) as video:
            frames = video.prefetch()
            while True:
                t0 = time.perf_counter()
                frame = next(frames, None)
                timings["decode_wait"] += time.perf_counter() - t0
                if frame is None:
                    break
                row = row_of.get(frame.index)
                if row is None:
                    extra += 1
                    continue
                if meter is not None:
                    t0 = time.perf_counter()
                    meter.feed(float(t[row]), frame.image)
                    timings["motion"] += time.perf_counter() - t0
                if pool is not None:
                    t0 = time.perf_counter()
                    pool.step(row, frame)
                    timings["hand_on"] += time.perf_counter() - t0
                else:
                    # one copy of a frame however many UUVs keep it
                    kept = Kept(frame)
                    for track in tracks:
                        track.step(row, frame, kept)
                if row >= first_row:
                    bar.update()
            if pool is not None:
                t0 = time.perf_counter()
                pool.finish()
                timings["hand_on"] += time.perf_counter() - t0
            if measurer is not None:
                t0 = time.perf_counter()
                measurer.finish()
                timings["size_wait"] = time.perf_counter() - t0
            if meter is not None:
                t0 = time.perf_counter()
                rotations = meter.finish()
                timings["motion"] += time.perf_counter() - t0
            if video.bad_reads:
                read_warnings.append(
                    f"{first.video_path}: {video.bad_reads} unreadable frames skipped"
                )
    except VideoError as e:
        raise SessionError(str(e)) from None
    finally:
        bar.close()
        if meter is not None:
            meter.close()
        if pool is not None:
            pool.close()
        if measurer is not None:
            measurer.close()
    extra_warnings = (
        [f"{first.video_path}: {extra} frames beyond video_frames.csv ignored"] if extra else []
    )
    return [
        track.result(frame_idx, timings, read_warnings, extra_warnings, rotations)
        for track in tracks
    ]


class UuvTrack:
    """One UUV's tracking through a session's video (its tracker, its per-frame results, its frames kept for
    tracing back), stepped frame by frame by :func:`track_sessions`; ``pose``: its camera pose of every frame, set
    before the first step."""

    def __init__(
        self,
        session: Session,
        tracker_name: str,
        size: HeightFromSize | None,
        both_ways: bool,
    ) -> None:
        cal = session.calibration
        if cal.init_bbox is None:
            raise SessionError(
                f"{session.path / 'session.toml'}: tracker.init_bbox missing (needed to track the video)"
            )
        try:
            self.tracking = TrackingSession(cal, tracker_name)
        except ValueError as e:
            raise SessionError(str(e)) from None
        # the reported pixel held to the vehicle's silhouette through waves (the tracking's own is untouched)
        self.centre = CentroidSteer()
        self.session, self.size, self.both_ways, self.pose = session, size, both_ways, None
        # where the heights from size are measured: in another process (a SizeWorker), or here (None)
        self.measurer = None
        self.t = t = session.frames["t"]
        n = len(t)
        self.init_row = _init_row(session, t)
        self.status = np.full(n, "no_video", dtype=object)
        self.status[: self.init_row] = "before_init"
        self.u, self.v, self.conf, self.sigma = (np.full(n, np.nan) for _ in range(4))
        self.u_unfiltered, self.v_unfiltered = np.full(n, np.nan), np.full(n, np.nan)
        self.timings = {"track": 0.0, "size": 0.0, "backward": 0.0}
        self.bridged = np.zeros(n, dtype=bool)
        self.causal_words: dict[
            int, str
        ] = {}  # row -> the causal pass's word a bridged "ok" replaced
        period_s = float(np.median(np.diff(t))) if n > 1 else math.inf
        self.gap: deque = deque(maxlen=max(1, round(BACKWARD_S / period_s)) if period_s > 0 else 1)
        # through waves: (row, image) of the frames since the first one without the UUV not yet traced back, and
        # the latest such frame's time
        self.behind: deque = deque(maxlen=self.gap.maxlen)
        self.missed_t = -math.inf
        # traced back from a restart by colour not yet proven: (the session's restarts undone then, [(row, result)])
        self.unproven: tuple[int, list] | None = None
        # (row, image, TrackResult): a re-acquisition after the gap, to be confirmed
        self.pending = None
        self.started = False
        # (t_unix, measurement or why not) of each frame the height from size was measured in, in order
        self.size_taken: list[tuple[float, object]] = []

    def step(self, row: int, frame, kept: Kept | None = None) -> None:
        """Track the UUV in the decoded ``frame``, row ``row`` of ``video_frames.csv`` (nothing before its
        ``init_t``); ``kept``: the frame's copy to keep for tracing back, shared by the UUVs stepped on it (default:
        one of its own)."""
        if row < self.init_row:
            return
        session, pose, timings = self.session, self.pose, self.timings
        t0 = time.perf_counter()
        if not self.started:
            if row != self.init_row:
                raise SessionError(
                    f"{session.video_path}: frame {int(session.frames['frame'][self.init_row])} "
                    f"(t = {self.t[self.init_row]:.3f}), the one tracker.init_bbox belongs to, could not be decoded"
                )
            try:
                result = self.tracking.select(
                    frame.image, pose, row, box=session.calibration.init_bbox, chroma=frame.chroma()
                )
            except SelectionError as e:
                raise SessionError(
                    f"{session.path / 'session.toml'}: tracker.init_bbox: {e}"
                ) from None
            self.started = True
        else:
            result = self.tracking.step(frame.image, pose, row, chroma=frame.chroma())
        tracked = result  # what the tracking decided, for tracing back from it
        result = self.centre.after(self.tracking, frame.image, result, float(self.t[row]))
        timings["track"] += time.perf_counter() - t0
        self.status[row], self.u[row], self.v[row], self.conf[row] = (
            result.status,
            result.u,
            result.v,
            result.confidence,
        )
        self.sigma[row] = result.sigma_px
        self.u_unfiltered[row], self.v_unfiltered[row] = (
            self.centre.unfiltered.u,
            self.centre.unfiltered.v,
        )
        if self.both_ways:
            kept = kept or Kept(frame)
            # the frame kept for tracing back: one copy for both traces and every UUV that keeps it
            image = kept() if not tracked.ok or self.gap or self.behind else None
            self._trace_when_confirmed(row, image, tracked)
            self._trace_when_sure(row, image, tracked)
        size, measurer = self.size, self.measurer
        if size is None or not result.ok:
            return
        t0 = time.perf_counter()
        t_unix = float(self.t[row])
        if measurer is not None and size.asks_estimate(t_unix):
            measurer.settle(self)
        if size.due(t_unix):
            if measurer is not None:
                measurer.submit(self, row, frame, result.u, result.v)
            else:
                self.took(t_unix, size.measure(frame.bgr_regions(), pose, row, result.u, result.v))
        timings["size"] += time.perf_counter() - t0

    def took(self, t_unix: float, measured) -> None:
        """The height from size measured in the frame at ``t_unix`` (or why not) taken into the estimate."""
        self.size.take(measured)
        self.size_taken.append((t_unix, measured))

    def state(self) -> dict:
        """What stepping changed (the per-frame results, the timings, the heights from size taken), for
        :meth:`adopt` in another process."""
        return {key: getattr(self, key) for key in STEPPED}

    def adopt(self, state: dict) -> None:
        """The :meth:`state` of this UUV's track stepped in another process, as if stepped here: the heights from
        size it took are taken by this track's ``size`` in the same order (see
        :mod:`groundstation.offline.uuv_workers`)."""
        for key in STEPPED:
            if key != "size_taken":
                setattr(self, key, state[key])
        for t_unix, measured in state["size_taken"]:
            self.size.due(t_unix)
            self.took(t_unix, measured)

    def _trace_when_confirmed(self, row: int, image, result) -> None:
        """``both_ways``: keep the frames without the UUV; once a re-acquisition after them is confirmed, the ones
        a tracker stepping back from it finds the UUV in become ``ok`` (bridged)."""
        if not result.ok:
            if self.pending is not None:  # lost again before the frames after it confirmed it
                self.pending = None
                self.gap.clear()
            self.gap.append((row, image))
        elif self.gap:
            self.pending = self.pending or (row, image, result)
            if self.t[row] - self.t[self.pending[0]] >= CONFIRM_BACK_S:
                t0 = time.perf_counter()
                self._bridge(_trace_back(self.tracking, self.pose, *self.pending, self.gap))
                self.gap.clear()
                self.pending = None
                self.timings["backward"] += time.perf_counter() - t0

    def _trace_when_sure(self, row: int, image, result) -> None:
        """``both_ways``, through waves: the frames without the UUV are traced back too from a frame the forward pass
        follows it in standing out of the seafloor (:data:`SURE_DISTINCT`), within :data:`SURE_WITHIN_S` after them,
        by a copy of the forward tracker (what it learnt of the UUV's wave-distorted appearance and of the sea
        state), through the frames since, until it loses the UUV. The waves hide the UUV for a moment or slide the
        follow off it without an occlusion, and a re-acquisition is then soon followed by a held frame. Traced back
        from a restart by colour not yet proven, the frames are bridged once it is (:meth:`_bridge_proven`)."""
        t = self.t[row]
        self._bridge_proven(t)
        if not result.ok:
            self.behind.append((row, image))
            self.missed_t = t
            return
        if not self.behind:
            return
        if t - self.missed_t > SURE_WITHIN_S:
            self.behind.clear()
            return
        if not self.tracking.target.distinct >= SURE_DISTINCT:
            self.behind.append((row, image))
            return
        t0 = time.perf_counter()
        try:
            back = self.tracking.back_from(image[0], self.pose, row)
        except SelectionError:  # its box reaches beyond the frame
            self.behind.clear()
            return
        traced = [
            (r, found)
            for r, found in _stepped_back(back, self.pose, self.behind)
            if self.status[r] != "ok"
        ]
        if self.tracking.unproven(t):  # bridged once the restart stands (:meth:`_bridge_proven`)
            refuted, held = self.unproven or (self.tracking.refuted, [])
            self.unproven = (refuted, held + traced)
        else:
            self._bridge(traced)
        self.behind.clear()
        self.timings["backward"] += time.perf_counter() - t0

    def _bridge_proven(self, t: float) -> None:
        """The frames traced back from a restart by colour (``unproven``) bridged once the restart is proven at
        ``t``, dropped when the colour refuted it meanwhile: the trace then followed a place of the seafloor."""
        if self.unproven is None:
            return
        refuted, traced = self.unproven
        if self.tracking.refuted != refuted:
            self.unproven = None
        elif not self.tracking.unproven(t):
            self._bridge(traced)
            self.unproven = None

    def _bridge(self, traced) -> None:
        """The frames a tracker stepping back found the UUV in (``(row, TrackResult)``) reported ``ok``."""
        status = self.status
        for r, back in traced:
            if self.bridged[r]:  # traced already, from another frame
                continue
            self.causal_words[r] = status[r]
            status[r], self.u[r], self.v[r], self.conf[r] = "ok", back.u, back.v, back.confidence
            self.u_unfiltered[r], self.v_unfiltered[r] = back.u, back.v
            self.sigma[r], self.bridged[r] = back.sigma_px, True

    def result(
        self, frame_idx, timings: dict, read_warnings: list, extra_warnings: list, rotations
    ) -> TrackedVideo:
        """The :class:`TrackedVideo` once every frame was stepped (``timings``, warnings and ``rotations``: the
        pass's, shared by its UUVs)."""
        session, status = self.session, self.status
        if not self.started:
            raise SessionError(
                f"{session.video_path}: no frame of video_frames.csv could be decoded"
            )
        warnings = list(read_warnings)
        missing = int(np.sum(status == "no_video"))
        if missing:
            warnings.append(
                f"{session.video_path}: {missing} frames of video_frames.csv not in the video (status no_video)"
            )
        warnings.extend(extra_warnings)
        u, v, sigma = self.u, self.v, self.sigma
        not_ok = status != "ok"
        for a in (u, v, sigma, self.u_unfiltered, self.v_unfiltered):
            a[not_ok] = np.nan
        causal_status = status.copy()
        for r, word in self.causal_words.items():
            causal_status[r] = word
        tracked = (frame_idx, self.t, u, v, status, self.conf, sigma)
        return TrackedVideo(
            *tracked,
            {**timings, **self.timings},
            warnings,
            rotations,
            self.bridged,
            causal_status,
            self.u_unfiltered,
            self.v_unfiltered,
        )


class Kept:
    """A frame's image and colour copied to be kept beyond the decoder's buffer (the frames a UUV was lost in, for
    tracing back): ``(image, chroma)``, copied on the first call only: the UUVs lost in the same frame keep the same
    copy (read-only), not one each."""

    def __init__(self, frame) -> None:
        self.frame, self._copy = frame, None

    def __call__(self) -> tuple[np.ndarray, Chroma | None]:
        if self._copy is None:
            image, chroma = self.frame.image.copy(), self.frame.chroma()
            image.flags.writeable = False
            self._copy = (image, None if chroma is None else chroma.copy())
        return self._copy


def _trace_back(forward: TrackingSession, pose, row: int, kept, found, gap) -> list:
    """``(row, TrackResult)`` of the frames in ``gap`` ((row, (image, chroma)), the frames just before ``row`` without
    the UUV, oldest first) a tracker started on the UUV ``found`` in frame ``row`` (``kept``: its image and chroma)
    finds it in, stepping back until it loses it; the vehicle's colour the forward tracker's."""
    back = TrackingSession(forward.cal, forward.tracker)
    try:
        back.start_at(kept[0], pose, row, found.box, (found.u, found.v))
    except SelectionError:  # its box reaches beyond the frame
        return []
    back.take_colour(forward)
    return _stepped_back(back, pose, gap)


def _stepped_back(back: TrackingSession, pose, frames) -> list:
    """``(row, TrackResult)`` of the frames ``frames`` ((row, (image, chroma)), oldest first) the tracker ``back`` finds
    the UUV in, stepping back from the newest until it loses it."""
    traced = []
    for r, (earlier, chroma) in reversed(frames):
        result = back.step(earlier, pose, r, chroma=chroma)
        if back.state is not TargetState.TRACKING:
            break
        if result.ok:
            traced.append((r, result))
    return traced

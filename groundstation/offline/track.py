"""Tracking the UUV through a session's video, steered by the session's telemetry.

:func:`track_session` decodes the video (in a background thread; for a tracker of grey levels,
:data:`~localizer.tracking.GREY_TRACKERS`, to the frames' luma planes, converting to BGR only the frames
the height is measured in), selects the UUV
with ``[tracker] init_bbox`` on the frame of ``init_t`` (the first frame without
it), tracks it with a :class:`~localizer.tracking.session.TrackingSession` (the
same as the live service's) and returns per-frame pixels with a status word for
every row of ``video_frames.csv``:

``ok``; ``lost`` (the tracker has lost the UUV); ``before_init`` (a frame before
the one ``init_bbox`` belongs to); ``no_video`` (the frame is listed but could not
be decoded: truncated or corrupt video).

Forward and backward (``both_ways``; offline, the whole video is there): the frames the forward, causal pass
reports without the UUV just before a re-acquisition (hidden a moment by the waves, searched for, the candidate
being confirmed) are traced back from it once the frames after it confirm it (the forward pass keeps it
:data:`CONFIRM_BACK_S` without a loss; one lost again sooner, e.g. water that passed for the UUV while it was
hidden, is not traced): a second tracker starts on the re-acquired UUV and steps back through them (up to
:data:`BACKWARD_S` of them, kept decoded meanwhile) until it loses it; the frames it finds the UUV in are ``ok``
too (``bridged``). An occlusion stops it as it stops the forward pass: a hidden UUV is not bridged.

The camera poses of all frames are computed at once and shared with the session
(which projects its predictions for many frames at a time). With ``measure_motion``
the camera's rotation between frames is measured too (every frame of a short recording, 10 a second of a
long one: :func:`~groundstation.latency.video_motion.measured_every`), in a thread beside the tracking
(:class:`~groundstation.latency.video_motion.MotionThread`; ``timings_s["motion"]``: the time waiting for it), for
the frames' offset to the
telemetry (:func:`groundstation.latency.estimate.offset_from_rotations`). With a
:class:`~groundstation.height_from_size.HeightFromSize`, frames the UUV is tracked in are
also measured for the camera's height from its size, in the same pass (``timings_s["size"]``).
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from groundstation.height_from_size import HeightFromSize
from groundstation.latency.video_motion import MotionThread, measured_every
from groundstation.progress import progress as progress_bar
from groundstation.session.read import Session, SessionError
from groundstation.video.frames import VideoError
from localizer.pose import camera_pose
from localizer.tracking import GREY_TRACKERS
from localizer.tracking.session import SelectionError, TrackingSession
from localizer.tracking.target import TargetState

#: Offline, frames without the UUV are traced back from a re-acquisition through at most this many seconds of them.
BACKWARD_S = 3.0
#: ... once the forward pass has kept the re-acquired UUV this long (s) without a loss.
CONFIRM_BACK_S = 1.0


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
    rotations: list = field(
        default_factory=list
    )  # video_motion.Rotation between consecutive frames (measure_motion)
    bridged: np.ndarray | None = (
        None  # bool: frames found by tracing a re-acquisition back (``both_ways``); else the causal pass's
    )
    causal_status: np.ndarray | None = None  # the causal pass's words (status but where bridged)


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
    cal = session.calibration
    if session.video_path is None or session.frames is None:
        raise SessionError(f"{session.path}: no video.* with video_frames.csv to track")
    if cal.init_bbox is None:
        raise SessionError(
            f"{session.path / 'session.toml'}: tracker.init_bbox missing (needed to track the video)"
        )
    try:
        tracking = TrackingSession(cal, tracker_name)
    except ValueError as e:
        raise SessionError(str(e)) from None

    frame_idx = session.frames["frame"].astype(int)
    t = session.frames["t"]
    n = len(t)
    row_of = {int(f): i for i, f in enumerate(frame_idx)}
    init_row = _init_row(session, t)
    status = np.full(n, "no_video", dtype=object)
    status[:init_row] = "before_init"
    u, v, conf, sigma = (
        np.full(n, np.nan),
        np.full(n, np.nan),
        np.full(n, np.nan),
        np.full(n, np.nan),
    )
    timings = {"decode_wait": 0.0, "track": 0.0, "motion": 0.0, "size": 0.0, "backward": 0.0}
    bridged = np.zeros(n, dtype=bool)
    causal_words: dict[int, str] = {}  # row -> the causal pass's word a bridged "ok" replaced
    period_s = float(np.median(np.diff(t))) if n > 1 else math.inf
    gap: deque = deque(maxlen=max(1, round(BACKWARD_S / period_s)) if period_s > 0 else 1)
    pending = None  # (row, image, TrackResult): a re-acquisition after the gap, to be confirmed
    warnings: list[str] = []
    meter = MotionThread(cal.camera, every=measured_every(n, period_s)) if measure_motion else None
    rotations = []

    t0 = time.perf_counter()
    pose = camera_pose(cal, session.telemetry, t)
    timings["pose"] = time.perf_counter() - t0

    bar = progress_bar(n - init_row, f"{session.path.name}: tracking", progress)
    extra = 0
    done = 0
    started = False
    try:
        with session.open_video(grey=tracker_name in GREY_TRACKERS) as video:
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
                if row < init_row:
                    continue
                t0 = time.perf_counter()
                if not started:
                    if row != init_row:
                        raise SessionError(
                            f"{session.video_path}: frame {frame_idx[init_row]} (t = {t[init_row]:.3f}), the one "
                            "tracker.init_bbox belongs to, could not be decoded"
                        )
                    try:
                        result = tracking.select(frame.image, pose, row, box=cal.init_bbox)
                    except SelectionError as e:
                        raise SessionError(
                            f"{session.path / 'session.toml'}: tracker.init_bbox: {e}"
                        ) from None
                    started = True
                else:
                    result = tracking.step(frame.image, pose, row)
                timings["track"] += time.perf_counter() - t0
                status[row], u[row], v[row], conf[row] = (
                    result.status,
                    result.u,
                    result.v,
                    result.confidence,
                )
                sigma[row] = result.sigma_px
                if both_ways and not result.ok:
                    if pending is not None:  # lost again before the frames after it confirmed it
                        pending = None
                        gap.clear()
                    gap.append((row, frame.image.copy()))
                elif both_ways and gap:
                    pending = pending or (row, frame.image.copy(), result)
                    if t[row] - t[pending[0]] >= CONFIRM_BACK_S:
                        t0 = time.perf_counter()
                        for r, back in _trace_back(tracking, pose, *pending, gap):
                            causal_words[r] = status[r]
                            status[r], u[r], v[r], conf[r] = "ok", back.u, back.v, back.confidence
                            sigma[r], bridged[r] = back.sigma_px, True
                        gap.clear()
                        pending = None
                        timings["backward"] += time.perf_counter() - t0
                if size is not None and result.ok and size.due(float(t[row])):
                    t0 = time.perf_counter()
                    size.take(size.measure(frame.bgr(), pose, row, result.u, result.v))
                    timings["size"] += time.perf_counter() - t0
                done += 1
                bar.update()
            if meter is not None:
                t0 = time.perf_counter()
                rotations = meter.finish()
                timings["motion"] += time.perf_counter() - t0
            if video.bad_reads:
                warnings.append(
                    f"{session.video_path}: {video.bad_reads} unreadable frames skipped"
                )
    except VideoError as e:
        raise SessionError(str(e)) from None
    finally:
        bar.close()
        if meter is not None:
            meter.close()
    if not started:
        raise SessionError(f"{session.video_path}: no frame of video_frames.csv could be decoded")
    missing = int(np.sum(status == "no_video"))
    if missing:
        warnings.append(
            f"{session.video_path}: {missing} frames of video_frames.csv not in the video (status no_video)"
        )
    if extra:
        warnings.append(f"{session.video_path}: {extra} frames beyond video_frames.csv ignored")
    not_ok = status != "ok"
    u[not_ok], v[not_ok], sigma[not_ok] = np.nan, np.nan, np.nan
    causal_status = status.copy()
    for r, word in causal_words.items():
        causal_status[r] = word
    tracked = (frame_idx, t, u, v, status, conf, sigma)
    return TrackedVideo(*tracked, timings, warnings, rotations, bridged, causal_status)


def _trace_back(forward: TrackingSession, pose, row: int, image, found, gap) -> list:
    """``(row, TrackResult)`` of the frames in ``gap`` ((row, image), the frames just before ``row`` without the UUV,
    oldest first) a tracker started on the UUV ``found`` in frame ``row`` finds it in, stepping back until it
    loses it."""
    back = TrackingSession(forward.cal, forward.tracker)
    try:
        back.start_at(image, pose, row, found.box, (found.u, found.v))
    except SelectionError:  # its box reaches beyond the frame
        return []
    traced = []
    for r, earlier in reversed(gap):
        result = back.step(earlier, pose, r)
        if back.state is not TargetState.TRACKING:
            break
        if result.ok:
            traced.append((r, result))
    return traced

"""Tracking the UUV through a session's video, steered by the session's telemetry.

:func:`track_session` decodes the video (in a background thread), tracks the UUV
from ``[tracker] init_bbox`` on, and returns per-frame pixels with a status word
for every row of ``video_frames.csv``:

``ok``; ``lost`` (the tracker has lost the UUV); ``before_init`` (a frame before
the one ``init_bbox`` belongs to); ``no_video`` (the frame is listed but could not
be decoded: truncated or corrupt video).

Each frame's :class:`~localizer.tracking.Prediction` comes from the UUV's last
located position projected through the frame's camera pose. Projections are
computed in batches of ``BATCH`` frames from one anchor position (re-located at
the start of each batch from the latest confident pixel); within a batch the
residual between the latest tracked pixel and the projection at its frame is
carried forward, so the prediction is "the last pixel moved by what the camera
did since".
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, fields

import numpy as np

from localizer.fix import locate
from localizer.pose import CameraPose, camera_pose
from localizer.tracking import TrackResult, make_tracker
from localizer.tracking.predict import follow, init_target, project_uuv

from .progress import progress as progress_bar
from .session import Session, SessionError
from .video import VideoError, open_video

BATCH = 64  # frames projected per telemetry batch


@dataclass
class TrackedVideo:
    """Per-frame results, one entry per row of ``video_frames.csv``."""

    frame: np.ndarray  # frame index
    t: np.ndarray  # UNIX seconds
    u: np.ndarray  # distorted pixels, NaN without a track
    v: np.ndarray
    status: np.ndarray  # object array of str
    confidence: np.ndarray  # tracker's 0..1, NaN when it has none
    timings_s: dict = field(default_factory=dict)  # seconds spent per stage
    warnings: list = field(default_factory=list)


def take(pose: CameraPose, idx) -> CameraPose:
    """The poses of some frames (index array or slice)."""
    return CameraPose(**{f.name: getattr(pose, f.name)[idx] for f in fields(CameraPose)})


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


class _Predictor:
    """Telemetry predictions for the frames, from the UUV's last located position (see module doc)."""

    def __init__(self, session: Session, pose: CameraPose):
        self.cal = session.calibration
        self.pose = pose
        self.n = len(pose.t_unix)
        self.proj = np.full((self.n, 3), np.nan)  # u, v, px_per_m of the anchor position
        self.batch_end = 0
        self.anchor = None  # (lat, lon)
        self.last_ok = None  # (row, u, v) of the latest confident pixel

    def start(self, row: int, box):
        """The pixel to track for the init box and its prediction (see :func:`init_target`)."""
        point, prediction = init_target(self.cal, take(self.pose, [row]), box)
        self.last_ok = (row, *point)
        return point, prediction

    def observe(self, row: int, result: TrackResult) -> None:
        if result.ok:
            self.last_ok = (row, result.u, result.v)

    def _reanchor(self, row: int) -> None:
        """Locate the latest pixel and project it into the next batch of frames (and its own frame)."""
        self.batch_end = min(row + BATCH, self.n)
        if self.last_ok is None:
            return
        j, u, v = self.last_ok
        fix = locate(self.cal, take(self.pose, [j]), [u], [v])
        if fix.status[0] == "ok":
            self.anchor = (fix.lat[0], fix.lon[0])
        if self.anchor is None:
            return
        rows = np.r_[j, row : self.batch_end]
        u_p, v_p, k = project_uuv(self.cal, take(self.pose, rows), *self.anchor)
        self.proj[rows] = np.stack([u_p, v_p, k], axis=-1)

    def __call__(self, row: int):
        if row >= self.batch_end:
            self._reanchor(row)
        if self.last_ok is None or self.anchor is None:
            return None
        j, u, v = self.last_ok
        return follow(self.proj[row], self.proj[j], (u, v), self.pose.t_unix[row] - self.pose.t_unix[j])


def track_session(session: Session, tracker_name: str = "default", progress: bool = False) -> TrackedVideo:
    """Track the UUV through the session's video (see the module doc for statuses).

    Raises :class:`SessionError` for what makes tracking impossible: no video, no
    ``init_bbox``, an unknown tracker, a video that cannot be opened or whose frame
    size differs from the calibration, an init frame that cannot be decoded.
    """
    cal = session.calibration
    if session.video_path is None or session.frames is None:
        raise SessionError(f"{session.path}: no video.* with video_frames.csv to track")
    if cal.init_bbox is None:
        raise SessionError(f"{session.path / 'session.toml'}: tracker.init_bbox missing (needed to track the video)")
    try:
        tracker = make_tracker(tracker_name, cal)
    except ValueError as e:
        raise SessionError(str(e)) from None

    frame_idx = session.frames["frame"].astype(int)
    t = session.frames["t"]
    n = len(t)
    row_of = {int(f): i for i, f in enumerate(frame_idx)}
    init_row = _init_row(session, t)
    status = np.full(n, "no_video", dtype=object)
    status[:init_row] = "before_init"
    u, v, conf = np.full(n, np.nan), np.full(n, np.nan), np.full(n, np.nan)
    timings = {"decode_wait": 0.0, "predict": 0.0, "track": 0.0}
    warnings: list[str] = []

    t0 = time.perf_counter()
    pose = camera_pose(cal, session.telemetry, t)
    predictor = _Predictor(session, pose)
    timings["pose"] = time.perf_counter() - t0

    bar = progress_bar(n - init_row, f"{session.path.name}: tracking", progress)
    extra = 0
    done = 0
    started = False
    try:
        with open_video(session.video_path, expected_size=(cal.camera.width, cal.camera.height)) as video:
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
                if row < init_row:
                    continue
                t0 = time.perf_counter()
                if not started:
                    if row != init_row:
                        raise SessionError(
                            f"{session.video_path}: frame {frame_idx[init_row]} (t = {t[init_row]:.3f}), the one "
                            "tracker.init_bbox belongs to, could not be decoded"
                        )
                    point, prediction = predictor.start(row, cal.init_bbox)
                    try:
                        tracker.init(frame.image, cal.init_bbox, prediction, point)
                    except ValueError as e:
                        raise SessionError(f"{session.path / 'session.toml'}: tracker.init_bbox: {e}") from None
                    result = TrackResult("ok", point[0], point[1], cal.init_bbox, 1.0)
                    started = True
                else:
                    prediction = predictor(row)
                    t1 = time.perf_counter()
                    timings["predict"] += t1 - t0
                    result = tracker.update(frame.image, prediction)
                    timings["track"] += time.perf_counter() - t1
                predictor.observe(row, result)
                status[row], u[row], v[row], conf[row] = result.status, result.u, result.v, result.confidence
                done += 1
                bar.update()
            if video.bad_reads:
                warnings.append(f"{session.video_path}: {video.bad_reads} unreadable frames skipped")
    except VideoError as e:
        raise SessionError(str(e)) from None
    finally:
        bar.close()
    if not started:
        raise SessionError(f"{session.video_path}: no frame of video_frames.csv could be decoded")
    missing = int(np.sum(status == "no_video"))
    if missing:
        warnings.append(f"{session.video_path}: {missing} frames of video_frames.csv not in the video (status no_video)")
    if extra:
        warnings.append(f"{session.video_path}: {extra} frames beyond video_frames.csv ignored")
    not_ok = status != "ok"
    u[not_ok], v[not_ok] = np.nan, np.nan
    return TrackedVideo(frame_idx, t, u, v, status, conf, timings, warnings)

"""The video's time offset to the telemetry, estimated from the image's motion.

The camera's rotation between consecutive frames is measured in the image
(:mod:`groundstation.latency.video_motion`) and predicted from the telemetry
(:func:`localizer.pose.camera_pose`, sampled every :data:`TRACK_STEP_S` and
interpolated) for the frames' times shifted by each candidate offset; the offset
whose predictions match best (least squares, refined on a parabola; pairs the fit
explains worst left out) is the estimate, its 1-sigma from the residuals (and
their correlation from pair to pair) and how fast the predictions change with
the offset: the changes of the camera's turn rate about its optical axis carry
the information, so a slow, steady turn says little and a camera held on a
heading (a gimbal locked to North) nothing (σ large).

- :func:`estimate_offset`: one estimate from measured rotations and an
  :class:`AttitudeTrack`.
- **Settled** (:func:`settled`), the one rule for using an estimate: :data:`STEADY_COUNT`
  estimates, each *sure* (1-sigma at most :data:`APPLY_SIGMA_S` from at least
  :data:`APPLY_PAIRS` frame pairs), within :data:`STEADY_S` of each other. Live they
  are the last estimates (one a second, over the last 20 s), each with a frame pair newer than the one
  before's (repeats from the same pairs, a busy machine's, agree by themselves), the applied 1-sigma
  widened by their spread; offline the estimates
  from consecutive thirds of the session (:func:`offset_from_rotations`), whose whole
  estimate is then the one used.
- ``skyfix estimate-latency SESSION``: for a recording: by how much the frames'
  times in ``video_frames.csv`` are off.
- ``skyfix process``/``evaluate`` of a session with video whose link delay is neither
  stated nor measured (:attr:`~localizer.telemetry.Telemetry.latency_source` "unknown"):
  the rotations are measured while the video is tracked and a settled estimate is
  applied as the link's delay (time source "motion").
- :class:`OnlineLatency`: in ``skyfix run``, the glass-to-first-packet latency
  (frames timed by their stream slots), in the status; once settled, a
  warning when it differs from ``--video-latency-ms`` by more than
  :data:`WARN_S`, and applied to the video with ``--video-latency-ms auto``.
"""

from __future__ import annotations

import argparse
import asyncio
import copy
import itertools
import logging
import math
import queue
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass

import numpy as np

from groundstation.height_from_size import SharedFrame, shared_image, start_measuring_process
from groundstation.latency.video_motion import Rotation, RotationMeter
from groundstation.runtime.threads import OUTSIDE_REALTIME, Supervised, in_thread
from groundstation.session.read import SessionError, load_session
from groundstation.video.file import open_video
from groundstation.video.frames import VideoError
from localizer.calibration import Calibration
from localizer.pose import camera_pose
from localizer.telemetry import Telemetry

log = logging.getLogger("skyfix.latency")

TRACK_STEP_S = 0.005  # the camera attitude is sampled this often for the predictions
OFFSET_STEP_S = 0.005  # candidate offsets are this far apart (then refined)
MEASURE_HZ = 10.0  # frames measured live, at most (every third at 30 fps: a third of the CPU)
STOP_WAIT_S = 1.0  # a stop waits this long for the measuring thread
WARN_S = 0.030  # an estimate this far from the configured latency is worth a warning
APPLY_SIGMA_S = 0.005  # an estimate is sure with this 1-sigma at most ...
APPLY_PAIRS = 60  # ... from at least this many frame pairs (6 s at MEASURE_HZ; fewer when the machine is busy);
STEADY_COUNT, STEADY_S = 3, 0.005  # settled: this many sure estimates, within 5 ms of each other
# an axis's residual is taken as at least this (the image measures no better)
NOISE_FLOOR_RAD = 1e-5


@dataclass(frozen=True)
class OffsetEstimate:
    """The true exposure of a frame is its time + ``offset_s`` (± ``sigma_s``, 1-sigma)."""

    offset_s: float
    sigma_s: float
    pairs: int  # frame pairs used
    rms_mrad: float  # residual per rotation component
    t_to: float = math.nan  # the newest frame of the pairs (their clock, s)


def sure(e: OffsetEstimate | None) -> bool:
    """Whether one estimate is sure: 1-sigma at most :data:`APPLY_SIGMA_S` from :data:`APPLY_PAIRS` pairs or more."""
    return e is not None and e.sigma_s <= APPLY_SIGMA_S and e.pairs >= APPLY_PAIRS


def settled(estimates: Sequence[OffsetEstimate | None]) -> bool:
    """Whether :data:`STEADY_COUNT` estimates (or more) are all sure and within :data:`STEADY_S` of each other."""
    if len(estimates) < STEADY_COUNT or not all(sure(e) for e in estimates):
        return False
    offsets = [e.offset_s for e in estimates]
    return max(offsets) - min(offsets) <= STEADY_S


@dataclass(frozen=True)
class SessionOffset:
    """A recording's estimate from all its frame pairs, and from each of :data:`STEADY_COUNT` consecutive parts."""

    estimate: OffsetEstimate | None
    parts: tuple[OffsetEstimate | None, ...]

    @property
    def settled(self) -> bool:
        """The whole estimate is sure and the parts' estimates settled (:func:`settled`): it may be applied."""
        return sure(self.estimate) and settled(self.parts)

    @property
    def sigma_s(self) -> float:
        """The whole estimate's 1-sigma covering what its parts disagree on: ``hypot(σ of the whole, the sample
        standard deviation of the parts' offsets)`` (waves, a heading estimate still settling, a delay that
        changed: the parts' spread beyond their own σ is an error the whole's σ does not see). Infinite without
        a whole estimate from :data:`APPLY_PAIRS` pairs or more, or with fewer than two parts' estimates."""
        offsets = [p.offset_s for p in self.parts if p is not None]
        if self.estimate is None or self.estimate.pairs < APPLY_PAIRS or len(offsets) < 2:
            return math.inf
        return float(math.hypot(self.estimate.sigma_s, np.std(offsets, ddof=1)))

    def better_than(self, unknown_sigma_s: float) -> bool:
        """Offline, with the whole recording: whether the estimate with :attr:`sigma_s` may be applied in place of
        an unknown delay taken as 0 ± ``unknown_sigma_s``: settled, or at least surer than that."""
        return self.settled or self.sigma_s < unknown_sigma_s

    def describe(self) -> str:
        """One line: the estimate, its sigma, the pairs, the parts', and whether it is settled."""
        e = self.estimate
        if e is None:
            return "no estimate (the image's motion could not be measured or the telemetry does not cover the video)"
        parts = ", ".join(
            "—" if p is None else f"{p.offset_s * 1000:+.1f} ± {p.sigma_s * 1000:.1f}"
            for p in self.parts
        )
        verdict = (
            "settled"
            if self.settled
            else f"not settled: needs ± {APPLY_SIGMA_S * 1000:.0f} ms or better from {APPLY_PAIRS}+ pairs in each "
            f"third, the thirds within {STEADY_S * 1000:.0f} ms"
        )
        spread = (
            f", ± {self.sigma_s * 1000:.1f} ms with the thirds' spread"
            if math.isfinite(self.sigma_s)
            else ""
        )
        return (
            f"{e.offset_s * 1000:+.1f} ± {e.sigma_s * 1000:.1f} ms (1-sigma) from {e.pairs} frame pairs "
            f"(thirds: {parts} ms{spread}): {verdict}"
        )


class AttitudeTrack:
    """The camera's attitude (``R_ned_from_cv``) sampled every :data:`TRACK_STEP_S` from ``t_from`` to ``t_to``
    where the telemetry gives a pose; rotations between any two times inside by interpolation.

    Plain numpy on quaternions (scalar last), not scipy's ``Slerp``: an estimate asks for some
    20 000 relative rotations a second, and scipy's rotation objects hold the GIL for tens of
    milliseconds doing it, stalling the decoder and the tracker behind them.
    """

    def __init__(self, t: np.ndarray, R_ned_from_cv: np.ndarray):
        """Samples at increasing times ``t`` (s) of the camera's attitude, rotation matrices (N, 3, 3)."""
        from scipy.spatial.transform import Rotation as Rot  # here: scipy takes ~0.3 s to import

        self.t = np.asarray(t, dtype=float)
        q = Rot.from_matrix(R_ned_from_cv).as_quat() if len(self.t) else np.empty((0, 4))
        # each sample in the hemisphere of the one before, so that neighbours interpolate the short way
        sign = np.cumprod(np.where(np.sum(q[1:] * q[:-1], axis=1) < 0.0, -1.0, 1.0))
        self._q = q * np.concatenate([[1.0], sign])[:, None]

    @classmethod
    def from_telemetry(
        cls, cal: Calibration, tel: Telemetry, t_from: float, t_to: float
    ) -> AttitudeTrack:
        """Sampled every :data:`TRACK_STEP_S` from ``t_from`` to ``t_to`` (s) where the telemetry gives a pose."""
        times = np.arange(t_from, t_to, TRACK_STEP_S)
        pose = camera_pose(cal, tel, times) if len(times) else None
        if pose is None:
            return cls(times[:0], np.empty((0, 3, 3)))
        ok = (pose.status == "ok") & np.all(np.isfinite(pose.R_ned_from_cv), axis=(1, 2))
        return cls(times[ok], pose.R_ned_from_cv[ok])

    @property
    def ready(self) -> bool:
        return len(self.t) >= 2

    def _at(self, t: np.ndarray) -> np.ndarray:
        """Unit quaternions at times inside the track: normalised linear interpolation between the
        neighbouring samples (:data:`TRACK_STEP_S` apart, where it is slerp to far below a microradian)."""
        i = np.clip(np.searchsorted(self.t, t, side="right") - 1, 0, len(self.t) - 2)
        w = ((t - self.t[i]) / (self.t[i + 1] - self.t[i]))[:, None]
        q = self._q[i] * (1.0 - w) + self._q[i + 1] * w
        return q / np.linalg.norm(q, axis=1, keepdims=True)

    def relative(self, t0: np.ndarray, t1: np.ndarray) -> np.ndarray:
        """Rotation vectors of ``R_cv1_from_cv0`` = R(t1)ᵀ R(t0), for arrays of times inside the track."""
        a, b = self._at(t1), self._at(t0)
        av, aw, bv, bw = -a[:, :3], a[:, 3:], b[:, :3], b[:, 3:]  # conj(a) ⊗ b, Hamilton product
        v = aw * bv + bw * av + np.cross(av, bv)
        w = aw * bw - np.sum(av * bv, axis=1, keepdims=True)
        v = np.where(w < 0.0, -v, v)  # the same rotation, by the shorter way
        n = np.linalg.norm(v, axis=1, keepdims=True)
        angle_per_n = np.where(
            n > 1e-12,
            2.0 * np.arctan2(n, np.abs(w)) / np.maximum(n, 1e-300),
            2.0 / np.maximum(np.abs(w), 1e-300),
        )
        return v * angle_per_n


def estimate_offset(
    rotations: Sequence[Rotation], track: AttitudeTrack, offsets: np.ndarray
) -> OffsetEstimate | None:
    """The offset (one of ``offsets``, refined) that best predicts the measured rotations; None without enough."""
    if not track.ready:
        return None
    t0 = np.array([r.t0 for r in rotations])
    t1 = np.array([r.t1 for r in rotations])
    inside = (t0 + offsets.min() >= track.t[0]) & (t1 + offsets.max() <= track.t[-1])
    if inside.sum() < 10:
        return None
    t0, t1 = t0[inside], t1[inside]
    meas = np.array([r.rotvec for r, i in zip(rotations, inside) if i])
    k, j = len(t0), len(offsets)
    pred = track.relative(
        (t0[None, :] + offsets[:, None]).ravel(), (t1[None, :] + offsets[:, None]).ravel()
    ).reshape(j, k, 3)
    weights = axis_weights(pred - meas[None])
    sq = np.sum(((pred - meas[None]) * weights) ** 2, axis=2)  # (J, K)
    use = np.ones(k, bool)
    for _ in range(2):  # fit, then again without the pairs it explains worst
        best = int(np.argmin(sq[:, use].sum(axis=1)))
        resid = sq[best]
        use = resid <= max(9.0 * np.median(resid), 1e-18)
    cost = sq[:, use].sum(axis=1)
    best = int(np.argmin(cost))
    offset = float(offsets[best])
    if 0 < best < j - 1:
        c0, c1, c2 = cost[best - 1], cost[best], cost[best + 1]
        curvature = c0 - 2.0 * c1 + c2
        if curvature > 0:
            offset += OFFSET_STEP_S * 0.5 * (c0 - c2) / curvature
    lo, hi = max(best - 1, 0), min(best + 1, j - 1)
    slope = (pred[hi, use] - pred[lo, use]) * weights / ((hi - lo) * OFFSET_STEP_S)
    n = int(use.sum())
    s2 = cost[best] / max(3 * n - 1, 1)
    info = float(np.sum(slope**2))
    sigma = float(np.sqrt(s2 / info)) if info > 0 else float("inf")
    resid = meas[use] - pred[best, use]
    sigma *= float(np.sqrt(_correlation_factor(np.sum(slope * resid * weights, axis=1))))
    return OffsetEstimate(
        float(offset), sigma, n, float(np.sqrt(np.mean(resid**2))) * 1000.0, float(t1.max())
    )


def axis_weights(residuals: np.ndarray) -> np.ndarray:
    """Weights (3,) of the rotation's components (camera x right, y down, z optical axis): one over each
    component's own residual spread (robust: 1.4826 × MAD), at the candidate offset where it is least.

    The image's turning about x and y is also the UAV's drift seen as a rotation (a few tenths of a mrad
    a frame at 10 m); about the optical axis it is not. Under a gimbal that holds the camera steady the
    drift is most of what x and y show: their residuals are large and they weigh little. A camera fixed
    to a wobbling airframe turns about x and y far more than about its optical axis: there they carry the
    information, and their residuals are small beside it. ``residuals``: (offsets, pairs, 3), radians.
    """
    med = np.median(residuals, axis=1, keepdims=True)
    spread = 1.4826 * np.median(np.abs(residuals - med), axis=1)  # (offsets, 3)
    return 1.0 / np.maximum(spread.min(axis=0), NOISE_FLOOR_RAD)


def _correlation_factor(g: np.ndarray, max_lag: int = 60) -> float:
    """How much more a sum of the series ``g`` varies than if its terms were independent (≥ 1).

    Residuals of neighbouring frame pairs can be alike (waves, texture moving with the light): the
    offset's σ from independent residuals would then be too small. Sums the autocorrelation up to
    its first negative lag.
    """
    g = g - g.mean()
    var = float(np.dot(g, g))
    if var <= 0 or len(g) < 8:
        return 1.0
    total = 1.0
    for lag in range(1, min(max_lag, len(g) // 4)):
        rho = float(np.dot(g[:-lag], g[lag:])) / var
        if rho <= 0:
            break
        total += 2.0 * rho
    return total


def offset_from_rotations(
    cal: Calibration, tel: Telemetry, rotations: Sequence[Rotation], search_s: float = 0.3
) -> SessionOffset:
    """A recording's frames' offset to its telemetry (within ± ``search_s``), from the rotations measured between
    its frames (in order), as a whole and in :data:`STEADY_COUNT` consecutive parts."""
    if not rotations:
        return SessionOffset(None, (None,) * STEADY_COUNT)
    track = AttitudeTrack.from_telemetry(
        cal, tel, rotations[0].t0 - search_s - 0.1, rotations[-1].t1 + search_s + 0.1
    )
    offsets = np.arange(-search_s, search_s + OFFSET_STEP_S / 2, OFFSET_STEP_S)
    n = len(rotations)
    bounds = [round(i * n / STEADY_COUNT) for i in range(STEADY_COUNT + 1)]
    parts = tuple(
        estimate_offset(rotations[a:b], track, offsets) for a, b in itertools.pairwise(bounds)
    )
    return SessionOffset(estimate_offset(rotations, track, offsets), parts)


@dataclass(frozen=True)
class VideoStart:
    """Where a video with no station times starts on the telemetry's clock, found from its motion."""

    start_s: float  # the first frame's exposure
    sigma_s: float  # 1-sigma, covering what the video's thirds disagree on (:attr:`SessionOffset.sigma_s`)
    pairs: int
    rms_mrad: float
    contrast: float  # the best start's misfit over the best elsewhere (beyond :data:`START_APART_S`): < 1, the lower the surer
    thirds_s: tuple[float | None, ...] = ()  # each third's start (None: no estimate from it)


START_STEP_S = 0.02  # the coarse search's grid
START_PAIRS = 80  # frame pairs the coarse search compares (spread over the video)
START_APART_S = 0.5  # a rival start this far from the best ...
START_CONTRAST = 0.7  # ... must misfit by at least 1 / this as much, or the start is ambiguous
START_FLAT = 1.5  # the refinement searches every coarse start within this factor of the best's misfit next to it ...
START_REFINE_S = 0.1  # ... and at least this far either side


def find_video_start(
    cal: Calibration, tel: Telemetry, rotations: Sequence[Rotation], span: tuple[float, float]
) -> VideoStart:
    """The exposure of a video's first frame on the telemetry's clock, within ``span`` (where the telemetry gives a
    pose), from the rotations between its frames (their times relative to the first frame, s).

    Coarse: every start :data:`START_STEP_S` apart across ``span`` is scored by how well the camera's
    attitude then predicts :data:`START_PAIRS` of the rotations (the same misfit as
    :func:`estimate_offset`); then :func:`estimate_offset` refines it with all of them across the flat part of the
    coarse misfit around the best (every start next to it within :data:`START_FLAT` of its misfit, at least
    ± :data:`START_REFINE_S`: an attitude estimate still settling leaves a wide, flat valley with several minima),
    and the video's thirds are refined alone: the start's 1-sigma covers what they disagree on
    (:attr:`SessionOffset.sigma_s`). :class:`ValueError` (one line naming both spans) when the video does not fit in
    ``span``, the image's motion says too little, or another start fits nearly as well."""
    if len(rotations) < 10:
        raise ValueError(
            f"the image's motion was measured between {len(rotations)} frame pairs: too few to place "
            "the video on the log's clock"
        )
    length = rotations[-1].t1
    lo, hi = span[0], span[1] - length
    if hi <= lo:
        raise ValueError(
            f"the video ({length:.1f} s) is longer than the telemetry's span {span[0]:.3f}–{span[1]:.3f}"
        )
    track = AttitudeTrack.from_telemetry(cal, tel, span[0], span[1])
    pick = np.unique(
        np.linspace(0, len(rotations) - 1, min(START_PAIRS, len(rotations))).round().astype(int)
    )
    t0 = np.array([rotations[i].t0 for i in pick])
    t1 = np.array([rotations[i].t1 for i in pick])
    meas = np.array([rotations[i].rotvec for i in pick])
    starts = np.arange(lo, hi, START_STEP_S)
    cost = np.empty(len(starts))
    for a in range(0, len(starts), 2000):  # in chunks: 2000 starts × the pairs at once
        s_ = starts[a : a + 2000]
        pred = track.relative(
            (t0[None, :] + s_[:, None]).ravel(), (t1[None, :] + s_[:, None]).ravel()
        )
        r = pred.reshape(len(s_), len(pick), 3) - meas[None]
        sq = np.sum(r**2, axis=2)
        # robust
        cost[a : a + 2000] = np.sum(
            np.minimum(sq, 9.0 * np.median(sq, axis=1, keepdims=True)), axis=1
        )
    best = int(np.argmin(cost))
    rivals = np.abs(starts - starts[best]) > START_APART_S
    contrast = float(cost[best] / cost[rivals].min()) if rivals.any() else 0.0
    if contrast > START_CONTRAST:
        raise ValueError(
            f"the video's start is ambiguous: {starts[best]:.3f} and "
            f"{starts[rivals][np.argmin(cost[rivals])]:.3f} fit nearly as well (the camera's motion "
            "repeats or says too little); give the start"
        )
    flat = cost <= START_FLAT * cost[best]
    a = b = best
    while a > 0 and flat[a - 1]:
        a -= 1
    while b < len(starts) - 1 and flat[b + 1]:
        b += 1
    reach = max(
        START_REFINE_S,
        starts[best] - starts[a] + START_STEP_S,
        starts[b] - starts[best] + START_STEP_S,
    )
    offsets = np.arange(-reach, reach + OFFSET_STEP_S / 2, OFFSET_STEP_S)
    shifted = [
        Rotation(r.t0 + starts[best], r.t1 + starts[best], r.rotvec, r.tracks) for r in rotations
    ]
    bounds = [round(i * len(shifted) / STEADY_COUNT) for i in range(STEADY_COUNT + 1)]
    found = SessionOffset(
        estimate_offset(shifted, track, offsets),
        tuple(estimate_offset(shifted[i:j], track, offsets) for i, j in itertools.pairwise(bounds)),
    )
    fine = found.estimate
    if fine is None:
        raise ValueError(
            "the video's start could not be refined (the telemetry does not cover its frames)"
        )
    sigma = found.sigma_s if math.isfinite(found.sigma_s) else fine.sigma_s
    thirds = tuple(None if p is None else float(starts[best] + p.offset_s) for p in found.parts)
    return VideoStart(
        float(starts[best] + fine.offset_s), sigma, fine.pairs, fine.rms_mrad, contrast, thirds
    )


def measure_rotations(
    path, cal: Calibration, times_s: np.ndarray, indices=None, until_s: float = math.inf, bar=None
) -> list[Rotation]:
    """The camera's rotation between consecutive frames of a video file, at the frames' times ``times_s`` (by
    frame index), up to the first frame after ``until_s``; ``bar``: a progress bar updated per frame. The frames are
    read grey (the meter follows grey levels: no conversion to colour, the faster decoding of
    :mod:`groundstation.video.file`). :class:`SessionError` for a video FFmpeg cannot read."""
    meter = RotationMeter(cal.camera)
    rotations = []
    try:
        with open_video(
            path, expected_size=(cal.camera.width, cal.camera.height), indices=indices, grey=True
        ) as video:
            for frame in video.prefetch():
                if frame.index >= len(times_s):
                    continue
                t = float(times_s[frame.index])
                if (r := meter.measure(t, frame.image)) is not None:
                    rotations.append(r)
                if bar is not None:
                    bar.update()
                if t > until_s:
                    break
    except VideoError as e:
        raise SessionError(str(e)) from None
    return rotations


def session_offset(session_dir: str, search_s: float = 0.3) -> tuple[SessionOffset, int]:
    """The offset of a recorded session's frame times (``video_frames.csv``) to its telemetry; and frames read."""
    session = load_session(session_dir)
    cal = session.calibration
    if session.video_path is None or session.frames is None:
        raise SessionError(f"{session_dir}: no video.* with video_frames.csv")
    rotations = measure_rotations(
        session.video_path, cal, session.frames["t"], session.frames["frame"]
    )
    return offset_from_rotations(cal, session.telemetry, rotations, search_s), len(rotations) + 1


class MotionEstimator:
    """The live estimate's work, in :class:`OnlineLatency`'s measuring process: the rotation of each frame handed
    over, kept for ``window_s``, and an estimate over them from a telemetry snapshot."""

    def __init__(self, cal: Calibration, window_s: float, offsets: np.ndarray):
        self.cal, self.window_s, self.offsets = cal, window_s, offsets
        self.meter = RotationMeter(cal.camera)
        self.rotations: deque[Rotation] = deque()

    def measure(self, t_slot: float, image: np.ndarray) -> None:
        if (r := self.meter.measure(t_slot, image)) is not None:
            self.rotations.append(r)

    def estimate(self, tel: Telemetry, now: float) -> OffsetEstimate | None:
        """Over the rotations of the last ``window_s`` before ``now`` (station s); None without enough."""
        while self.rotations and self.rotations[0].t0 < now - self.window_s:
            self.rotations.popleft()
        if not self.rotations:
            return None
        # sampled anew each time: the telemetry's alignment to the station clock sharpens as it comes
        track = AttitudeTrack.from_telemetry(
            self.cal, tel, self.rotations[0].t0 + self.offsets.min() - 0.1, now - 0.3
        )
        return estimate_offset(list(self.rotations), track, self.offsets)


#: The measuring process's one :class:`MotionEstimator` (:func:`start_estimator`).
_estimator: list[MotionEstimator] = []


def start_estimator(cal: Calibration, window_s: float, offsets: np.ndarray) -> None:
    """The measuring process: its estimator, and the imports it needs, now (before the first frame)."""
    _estimator[:] = [MotionEstimator(cal, window_s, offsets)]


def measure_shared(t_slot: float, frame: tuple[str, tuple[int, ...], str]) -> None:
    """The measuring process: :meth:`MotionEstimator.measure` of the frame :class:`SharedFrame` put in."""
    _estimator[0].measure(t_slot, shared_image(frame))


def estimate_now(tel: Telemetry, now: float) -> OffsetEstimate | None:
    """The measuring process: :meth:`MotionEstimator.estimate`."""
    return _estimator[0].estimate(tel, now)


class OnlineLatency:
    """Worker estimating the glass-to-first-packet latency of the live video (see the module doc).

    ``on_frame`` (event loop) hands frames, at most :data:`MEASURE_HZ` a second, to a
    thread (frames arriving while it is busy are skipped) that has their rotation measured by a
    :class:`MotionEstimator` in a low-priority process of its own, each frame through shared memory
    (:class:`~groundstation.height_from_size.SharedFrame`; the process as the height from size's:
    :func:`~groundstation.height_from_size.start_measuring_process`); once a second the telemetry is
    copied on the loop and the process extends the attitude track and estimates. Not a low-priority
    thread of the service: the estimate is some 80 ms of Python and NumPy a second holding the
    interpreter's lock, and such a thread, preempted while it held the lock beside busy programs, kept
    the frames' threads waiting until it got a core again (``bench/gil_inversion.py``).
    ``apply(latency_s)``, when given (``auto``), is called on the loop with each
    settled estimate (:func:`settled`) that moved by more than 2 ms; :attr:`applied_s` and
    :attr:`applied_sigma_s` are what is in use (None before the first).
    """

    def __init__(
        self,
        cal: Calibration,
        tel: Telemetry,
        configured_s: float | None,
        apply: Callable[[float], None] | None = None,
        window_s: float = 20.0,
        max_latency_s: float = 0.5,
    ):
        self.cal, self.tel = cal, tel
        self.configured_s = configured_s
        self.apply = apply
        self.window_s = window_s
        self.offsets = np.arange(-max_latency_s, 0.05 + OFFSET_STEP_S / 2, OFFSET_STEP_S)
        self.estimate: OffsetEstimate | None = None
        self.applied_s: float | None = None
        self.applied_sigma_s: float | None = None
        self.settled = False  # the last STEADY_COUNT estimates are settled
        self.skipped = 0
        self._warned: float | None = None
        self._recent: deque[OffsetEstimate | None] = deque(maxlen=STEADY_COUNT)
        self._frames: queue.Queue = queue.Queue(maxsize=2)
        self._tel: tuple[Telemetry, float] | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self.worker = Supervised("video-latency", self._work)
        self._last_slot: float | None = None

    def on_frame(self, frame) -> None:
        if (
            self._last_slot is not None
            and frame.t_slot - self._last_slot < 1.0 / MEASURE_HZ - 0.005
        ):
            return
        self._last_slot = frame.t_slot
        try:
            self._frames.put_nowait((frame.t_slot, frame.image))
        except queue.Full:
            self.skipped += 1

    async def run(self) -> None:
        self._loop = asyncio.get_running_loop()
        self.worker.start()
        try:
            while True:
                await asyncio.sleep(1.0)
                self._tel = (copy.deepcopy(self.tel), time.time())
        finally:
            await in_thread(self.worker.join, STOP_WAIT_S, name="video-latency stop")

    def _work(self, stop: threading.Event) -> None:
        """Hands the frames and the telemetry to the measuring process (started here: a restart after a failure
        starts a new one) and the estimates back to the loop."""
        loop = self._loop
        pool = ProcessPoolExecutor(
            1, mp_context=OUTSIDE_REALTIME, initializer=start_measuring_process
        )
        # the process starts and imports now, not at the first frame
        pool.submit(start_estimator, self.cal, self.window_s, self.offsets)
        shared = SharedFrame()
        try:
            while not stop.is_set():
                try:
                    t_slot, image = self._frames.get(timeout=0.2)
                    pool.submit(measure_shared, t_slot, shared.put(image)).result()
                except queue.Empty:
                    pass
                snapshot, self._tel = self._tel, None
                if snapshot is None:
                    continue
                estimate = pool.submit(estimate_now, *snapshot).result()
                if estimate is not None:
                    self.estimate = estimate
                    try:
                        loop.call_soon_threadsafe(self._judge, estimate)
                    except RuntimeError:  # the loop is closed: stopped
                        return
        finally:
            pool.shutdown(wait=False, cancel_futures=True)
            shared.close()

    def _judge(self, e: OffsetEstimate) -> None:
        """One estimate: towards settling only when it has a frame pair newer than the last one judged (a starved
        measuring process or decoder gives estimates from the same pairs again, which agree by themselves)."""
        if self._recent and e.t_to <= self._recent[-1].t_to:
            return
        latency = -e.offset_s
        self._recent.append(e)
        self.settled = settled(self._recent)
        if not self.settled:
            return
        off = self.configured_s is not None and abs(latency - self.configured_s) > WARN_S
        news = self._warned is None or abs(latency - self._warned) > WARN_S / 3
        if off and news:
            self._warned = latency
            log.warning(
                "video: the image's motion puts the glass-to-first-packet latency at %.0f ± %.0f ms, "
                "not the configured %.0f ms (--video-latency-ms)",
                latency * 1000,
                e.sigma_s * 1000,
                self.configured_s * 1000,
            )
        if self.apply is None:
            return
        # the claim covers what the settled estimates disagree on, as offline the thirds' spread
        spread_s = float(np.std([r.offset_s for r in self._recent], ddof=1))
        self.applied_sigma_s = math.hypot(e.sigma_s, spread_s)
        if self.applied_s is not None and abs(latency - self.applied_s) <= 0.002:
            return
        log.info(
            "video: latency %.1f ± %.1f ms from the image's motion, applied%s (%d frame pairs)",
            latency * 1000,
            self.applied_sigma_s * 1000,
            ": fixes from here on"
            if self.applied_s is None
            else f" in place of {self.applied_s * 1000:.1f} ms",
            e.pairs,
        )
        self.applied_s = latency
        self.apply(latency)

    @property
    def state(self) -> str:
        """``none`` (no estimate yet), ``unsettled`` or ``settled`` (the last estimates, :func:`settled`)."""
        return "none" if self.estimate is None else "settled" if self.settled else "unsettled"

    def status(self) -> dict:
        e = self.estimate
        out = {
            "configured_ms": None
            if self.configured_s is None
            else round(self.configured_s * 1000, 1),
            "applied_ms": None if self.applied_s is None else round(self.applied_s * 1000, 1),
            "applied_sigma_ms": None
            if self.applied_sigma_s is None
            else round(self.applied_sigma_s * 1000, 2),
            "state": self.state,
            "frames_skipped": self.skipped,
            **self.worker.status(),
        }
        if e is not None:
            out.update(
                estimate_ms=round(-e.offset_s * 1000, 1),
                sigma_ms=round(e.sigma_s * 1000, 2),
                pairs=e.pairs,
                rms_mrad=round(e.rms_mrad, 3),
            )
        return out


def estimate_latency(args: argparse.Namespace) -> int:
    found, frames = session_offset(args.session, args.search_ms / 1000.0)
    estimate = found.estimate
    if estimate is None:
        print(
            f"skyfix estimate-latency: {args.session}: no estimate ({frames} frames; the image's motion could not "
            "be measured or the telemetry does not cover the video)"
        )
        return 1
    print(
        f"{args.session}: the telemetry matches the video best with each frame's time moved by "
        f"{estimate.offset_s * 1000:+.1f} ms (1-sigma {estimate.sigma_s * 1000:.1f} ms, {estimate.pairs} frame pairs, "
        f"residual {estimate.rms_mrad:.3f} mrad): the frames were exposed that much "
        f"{'later' if estimate.offset_s > 0 else 'earlier'} than video_frames.csv says"
    )
    print(f"estimate {found.describe()}")
    print(
        f"for a live run: --video-latency-ms {-estimate.offset_s * 1000:+.1f} relative to the one recorded with"
    )
    return 0


def register(subparsers, name: str, help: str | None = None) -> None:
    """Adds the subcommand ``name`` with its one-line ``help`` (both from :data:`groundstation.cli.COMMANDS`)."""
    p = subparsers.add_parser(name, help=help, description=__doc__.split("\n\n")[0])
    p.add_argument("session", help="session directory (format v1) with video")
    p.add_argument(
        "--search-ms", type=float, default=300.0, help="largest offset looked for, either way"
    )
    p.set_defaults(func=estimate_latency)

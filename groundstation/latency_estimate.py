"""The video's time offset to the telemetry, estimated from the image's motion.

The camera's rotation between consecutive frames is measured in the image
(:mod:`groundstation.video_motion`) and predicted from the telemetry
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
- ``skyfix estimate-latency SESSION``: for a recording: by how much the frames'
  times in ``video_frames.csv`` are off.
- :class:`OnlineLatency`: in ``skyfix run``, the glass-to-first-packet latency
  (frames timed by their stream slots), in the status; once sure and steady, a
  warning when it differs from ``--video-latency-ms`` by more than
  :data:`WARN_S`, and applied to the video with ``--video-latency-ms auto``.
"""

from __future__ import annotations

import argparse
import asyncio
import copy
import logging
import os
import queue
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation as Rot

from localizer.calibration import Calibration
from localizer.pose import camera_pose
from localizer.telemetry import Telemetry

from .session import SessionError, load_session
from .threads import Supervised, in_thread
from .video import VideoError, open_video
from .video_motion import Rotation, RotationMeter

log = logging.getLogger("skyfix.latency")

TRACK_STEP_S = 0.005  # the camera attitude is sampled this often for the predictions
OFFSET_STEP_S = 0.005  # candidate offsets are this far apart (then refined)
MEASURE_HZ = 10.0  # frames measured live, at most (every third at 30 fps: a third of the CPU)
STOP_WAIT_S = 1.0  # a stop waits this long for the measuring thread
NICE = 10  # the measuring thread yields the CPU to decoding and tracking
WARN_S = 0.030  # an estimate this far from the configured latency is worth a warning
APPLY_SIGMA_S = 0.005  # --video-latency-ms auto applies an estimate this sure ...
APPLY_PAIRS = 60  # ... from at least this many frame pairs (6 s at MEASURE_HZ; fewer when the machine is busy) ...
STEADY_COUNT, STEADY_S = 3, 0.005  # ... when the last estimates (one a second) all were, within 5 ms
#: Weights of the rotation's components (camera x right, y down, z optical axis). The UAV's drift looks
#: like a rotation about x and y (a few tenths of a mrad a frame at 10 m, as much as a gimbal's wobble),
#: and would pull the estimate; about the optical axis it does not. So only the image's turning counts.
AXIS_WEIGHTS = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class OffsetEstimate:
    """The true exposure of a frame is its time + ``offset_s`` (± ``sigma_s``, 1-sigma)."""

    offset_s: float
    sigma_s: float
    pairs: int  # frame pairs used
    rms_mrad: float  # residual per rotation component


class AttitudeTrack:
    """The camera's attitude (``R_ned_from_cv``) sampled every :data:`TRACK_STEP_S` from ``t_from`` to ``t_to``
    where the telemetry gives a pose; rotations between any two times inside by interpolation.

    Plain numpy on quaternions (scalar last), not scipy's ``Slerp``: an estimate asks for some
    20 000 relative rotations a second, and scipy's rotation objects hold the GIL for tens of
    milliseconds doing it, stalling the decoder and the tracker behind them.
    """

    def __init__(self, t: np.ndarray, R_ned_from_cv: np.ndarray):
        """Samples at increasing times ``t`` (s) of the camera's attitude, rotation matrices (N, 3, 3)."""
        self.t = np.asarray(t, dtype=float)
        q = Rot.from_matrix(R_ned_from_cv).as_quat() if len(self.t) else np.empty((0, 4))
        # each sample in the hemisphere of the one before, so that neighbours interpolate the short way
        sign = np.cumprod(np.where(np.sum(q[1:] * q[:-1], axis=1) < 0.0, -1.0, 1.0))
        self._q = q * np.concatenate([[1.0], sign])[:, None]

    @classmethod
    def from_telemetry(cls, cal: Calibration, tel: Telemetry, t_from: float, t_to: float) -> AttitudeTrack:
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
        angle_per_n = np.where(n > 1e-12, 2.0 * np.arctan2(n, np.abs(w)) / np.maximum(n, 1e-300),
                               2.0 / np.maximum(np.abs(w), 1e-300))
        return v * angle_per_n


def estimate_offset(rotations: Sequence[Rotation], track: AttitudeTrack, offsets: np.ndarray) -> OffsetEstimate | None:
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
    pred = track.relative((t0[None, :] + offsets[:, None]).ravel(),
                          (t1[None, :] + offsets[:, None]).ravel()).reshape(j, k, 3)
    sq = np.sum(((pred - meas[None]) * AXIS_WEIGHTS) ** 2, axis=2)  # (J, K)
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
    slope = (pred[hi, use] - pred[lo, use]) * AXIS_WEIGHTS / ((hi - lo) * OFFSET_STEP_S)
    n = int(use.sum())
    s2 = cost[best] / max(3 * n - 1, 1)
    info = float(np.sum(slope ** 2))
    sigma = float(np.sqrt(s2 / info)) if info > 0 else float("inf")
    resid = (meas[use] - pred[best, use]) * AXIS_WEIGHTS
    sigma *= np.sqrt(_correlation_factor(np.sum(slope * resid, axis=1)))
    return OffsetEstimate(offset, sigma, n, float(np.sqrt(s2)) * 1000.0)


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


def session_offset(session_dir: str, search_s: float = 0.3) -> tuple[OffsetEstimate | None, int]:
    """The offset of a recorded session's frame times (``video_frames.csv``) to its telemetry; and frames read."""
    session = load_session(session_dir)
    cal = session.calibration
    if session.video_path is None or session.frames is None:
        raise SessionError(f"{session_dir}: no video.* with video_frames.csv")
    t = session.frames["t"]
    meter = RotationMeter(cal.camera)
    rotations = []
    try:
        with open_video(session.video_path, expected_size=(cal.camera.width, cal.camera.height),
                        indices=session.frames["frame"]) as video:
            for frame in video.prefetch():
                if frame.index < len(t) and (r := meter.measure(float(t[frame.index]), frame.image)) is not None:
                    rotations.append(r)
    except VideoError as e:
        raise SessionError(str(e)) from None
    track = AttitudeTrack.from_telemetry(cal, session.telemetry, float(t[0]) - search_s - 0.1, float(t[-1]) + search_s + 0.1)
    offsets = np.arange(-search_s, search_s + OFFSET_STEP_S / 2, OFFSET_STEP_S)
    return estimate_offset(rotations, track, offsets), len(rotations) + 1


class OnlineLatency:
    """Worker estimating the glass-to-first-packet latency of the live video (see the module doc).

    ``on_frame`` (event loop) hands frames, at most :data:`MEASURE_HZ` a second, to a
    low-priority thread that measures their rotation (frames arriving while it is busy
    are skipped); once a second the telemetry is
    copied on the loop and the thread extends the attitude track and estimates.
    ``apply(latency_s)``, when given (``auto``), is called on the loop with each
    estimate sure enough to use.
    """

    def __init__(self, cal: Calibration, tel: Telemetry, configured_s: float | None,
                 apply: Callable[[float], None] | None = None, window_s: float = 20.0, max_latency_s: float = 0.5):
        self.cal, self.tel = cal, tel
        self.configured_s = configured_s
        self.apply = apply
        self.window_s = window_s
        self.offsets = np.arange(-max_latency_s, 0.05 + OFFSET_STEP_S / 2, OFFSET_STEP_S)
        self.estimate: OffsetEstimate | None = None
        self.applied_s: float | None = None
        self.skipped = 0
        self._warned: float | None = None
        self._recent: deque[OffsetEstimate | None] = deque(maxlen=STEADY_COUNT)
        self._frames: queue.Queue = queue.Queue(maxsize=2)
        self._tel: tuple[Telemetry, float] | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self.worker = Supervised("video-latency", self._work)
        self._rotations: deque[Rotation] = deque()
        self._last_slot: float | None = None

    def on_frame(self, frame) -> None:
        if self._last_slot is not None and frame.t_slot - self._last_slot < 1.0 / MEASURE_HZ - 0.005:
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
            # waited for (within a measurement): a thread left inside OpenCV when the process exits aborts it
            await in_thread(self.worker.join, STOP_WAIT_S, name="video-latency stop")

    def _work(self, stop: threading.Event) -> None:
        loop = self._loop
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), NICE)  # Linux: this thread only
        meter = RotationMeter(self.cal.camera)
        while not stop.is_set():
            try:
                t_slot, image = self._frames.get(timeout=0.2)
                if (r := meter.measure(t_slot, image)) is not None:
                    self._rotations.append(r)
            except queue.Empty:
                pass
            snapshot, self._tel = self._tel, None
            if snapshot is None:
                continue
            tel, now = snapshot
            while self._rotations and self._rotations[0].t0 < now - self.window_s:
                self._rotations.popleft()
            if not self._rotations:
                continue
            # sampled anew each time: the telemetry's alignment to the station clock sharpens as it comes
            track = AttitudeTrack.from_telemetry(self.cal, tel, self._rotations[0].t0 + self.offsets.min() - 0.1, now - 0.3)
            estimate = estimate_offset(list(self._rotations), track, self.offsets)
            if estimate is not None:
                self.estimate = estimate
                try:
                    loop.call_soon_threadsafe(self._judge, estimate)
                except RuntimeError:  # the loop is closed: stopped
                    return

    def _judge(self, e: OffsetEstimate) -> None:
        latency = -e.offset_s
        self._recent.append(e if e.sigma_s <= APPLY_SIGMA_S and e.pairs >= APPLY_PAIRS else None)
        recent = [r.offset_s for r in self._recent if r is not None]
        if len(recent) < self._recent.maxlen or max(recent) - min(recent) > STEADY_S:
            return  # not sure yet, or not steady
        off = self.configured_s is not None and abs(latency - self.configured_s) > WARN_S
        news = self._warned is None or abs(latency - self._warned) > WARN_S / 3
        if off and news:
            self._warned = latency
            log.warning("video: the image's motion puts the glass-to-first-packet latency at %.0f ± %.0f ms, "
                        "not the configured %.0f ms (--video-latency-ms)", latency * 1000, e.sigma_s * 1000,
                        self.configured_s * 1000)
        if self.apply is None or (self.applied_s is not None and abs(latency - self.applied_s) <= 0.002):
            return
        if self.applied_s is None:
            log.info("video: latency %.1f ± %.1f ms from the image's motion, applied", latency * 1000, e.sigma_s * 1000)
        self.applied_s = latency
        self.apply(latency)

    def status(self) -> dict:
        e = self.estimate
        out = {"configured_ms": None if self.configured_s is None else round(self.configured_s * 1000, 1),
               "applied_ms": None if self.applied_s is None else round(self.applied_s * 1000, 1),
               "frames_skipped": self.skipped, **self.worker.status()}
        if e is not None:
            out.update(estimate_ms=round(-e.offset_s * 1000, 1), sigma_ms=round(e.sigma_s * 1000, 2), pairs=e.pairs,
                       rms_mrad=round(e.rms_mrad, 3))
        return out


def estimate_latency(args: argparse.Namespace) -> int:
    estimate, frames = session_offset(args.session, args.search_ms / 1000.0)
    if estimate is None:
        print(f"skyfix estimate-latency: {args.session}: no estimate ({frames} frames; the image's motion could not "
              "be measured or the telemetry does not cover the video)")
        return 1
    print(f"{args.session}: the telemetry matches the video best with each frame's time moved by "
          f"{estimate.offset_s * 1000:+.1f} ms (1-sigma {estimate.sigma_s * 1000:.1f} ms, {estimate.pairs} frame pairs, "
          f"residual {estimate.rms_mrad:.3f} mrad): the frames were exposed that much "
          f"{'later' if estimate.offset_s > 0 else 'earlier'} than video_frames.csv says")
    print(f"for a live run: --video-latency-ms {-estimate.offset_s * 1000:+.1f} relative to the one recorded with")
    return 0


def register(subparsers) -> None:
    p = subparsers.add_parser("estimate-latency", help="a recording's video-to-telemetry time offset, from image motion",
                              description=__doc__.split("\n\n")[0])
    p.add_argument("session", help="session directory (format v1) with video")
    p.add_argument("--search-ms", type=float, default=300.0, help="largest offset looked for, either way")
    p.set_defaults(func=estimate_latency)

"""The drone's pose biases from the static bottom, live (``pose_from_bottom = true``, ``bottom_every_s``,
``bottom_window_s``): ``skyfix process --pose-from-bottom auto``'s estimate (:mod:`groundstation.offline.bottom`,
:mod:`localizer.bottom`) made causally, over a sliding window of the last frames, as live cannot see the future.

Every ``bottom_every_s`` seconds of video an aligned frame is taken with its camera pose
(:class:`groundstation.live.every_frame.EveryFrame`, as the reference's search) and its floor features tracked on
from the frame taken before (:class:`groundstation.offline.bottom.FloorTracker`: the floor's dark marks, away from
the UUV's last tracked pixel) in the tracking process, which holds the window (:func:`add_now`); a frame due while
the tracker is still busy is skipped and counted (a skip breaks the tracks: new ones start). Every :data:`REFIT_S`
seconds of video the estimate is made again in a second process (:func:`fit_window`:
:func:`groundstation.offline.bottom.fit`, the offline estimate's own priors, parts and refusals) from the frames of
the last ``bottom_window_s`` seconds; while it works, frames go on being tracked and a due fit waits for it. Both
are low-priority processes of their own (:class:`groundstation.live.side_process.SideProcess`, the frame handed over
in shared memory): in low-priority threads of the service their Python held the interpreter's lock while they
waited for a core, the frames' threads waiting with them. A tracking process that ends is started again with an
empty window (one log line).

Each fix (:meth:`LiveBottom.correct`, called by the pipeline with the fix's pose) is made again with the latest
estimate's correction (:meth:`groundstation.offline.bottom.PoseCorrection.apply`: the attitude turned back by the
tilt and heading applied, the position moved by the walk at the window's end about the window's GNSS mean, the
tilt and heading sigmas the estimate's) when that estimate's newest frame is at most :data:`HOLD_WINDOWS` windows
before the fix (else it has lapsed), and taken only where its claim (h_acc) is smaller than the fix's own (as the
reference's, :func:`localizer.reference.applied`; else counted ``kept_own``). The fix says what was applied
(:data:`localizer.fix.POSE_COLUMNS`: ``pose_source`` ``bottom``, the attitude error, its sigmas, the walk).

With a reference in view too (``reference``), the bottom's correction comes first and the reference's offset is
added to what it gives (:meth:`LiveBottom.then`): the bottom removes what differs from frame to frame (the biases'
effect changes with the view; the walk within the window), the reference the absolute offset no bottom can see.
The reference's sightings are made through the same corrected pose (:meth:`LiveBottom.corrected_pose`), so its
offset is what is left after the bottom's correction.

Station-clock seconds, radians inside, degrees and metres in the status.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections import deque
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from groundstation.live.every_frame import EveryFrame
from groundstation.live.side_process import ProcessLost, SideProcess
from groundstation.offline.bottom import (
    FloorTracker,
    PoseCorrection,
    bias_headings,
    body_yaw,
    fit,
    floor_marks,
    frame_poses,
    grey_of,
    tilt_frame,
    uuv_radius_px,
    web_kernel_px,
)
from localizer.fix import Fix, locate
from localizer.pose import CameraPose

log = logging.getLogger("skyfix.bottom")

#: seconds of video between the estimate's fits
REFIT_S = 2.0
#: an estimate holds this many windows after its newest frame, then lapses (a fit takes seconds on a busy machine)
HOLD_WINDOWS = 2.0
#: the UUV's tracked pixel is kept out of the floor features when it is at most this old at a taken frame (s)
PIXEL_AGE_S = 0.5


@dataclasses.dataclass(frozen=True)
class Platform:
    """What :mod:`groundstation.offline.bottom`'s functions take of a session: its calibration and telemetry."""

    calibration: object
    telemetry: object


def concatenated(poses: list[CameraPose]) -> CameraPose:
    """Poses of one frame each as one :class:`~localizer.pose.CameraPose`."""
    return CameraPose(
        **{
            f.name: np.concatenate([getattr(p, f.name) for p in poses])
            for f in dataclasses.fields(CameraPose)
        }
    )


class BottomWindow:
    """The causal estimator: :meth:`add` each taken frame in turn (its floor features tracked on), :meth:`fit` the
    estimate over the frames of the last ``window_s`` seconds. Not thread-safe: live, the tracking process's one
    thread holds it (:func:`add_now`)."""

    def __init__(self, platform: Platform, window_s: float, frame_tilt: str):
        self.platform, self.window_s = platform, window_s
        cam = platform.calibration.camera
        self.tracker = FloorTracker(cam.width, cam.height)
        self.frame_tilt = (
            frame_tilt  # the tilt's bias frame (groundstation.offline.bottom.tilt_frame)
        )
        self.taken = 0  # frames added
        # per frame in the window: its number, pose (one frame) and bias-frame heading (rad)
        self._frames: deque[tuple[int, CameraPose, float]] = deque()

    def add(self, image: np.ndarray, pose: CameraPose, heading_rad: float, uuv_u, uuv_v) -> None:
        """Track the floor into a frame (``pose`` of one frame, its bias frame's ``heading_rad``; the UUV at pixel
        ``uuv_u``, ``uuv_v``, NaN: unknown) and let go of the frames older than the window."""
        cal = self.platform.calibration
        grey = floor_marks(grey_of(image), web_kernel_px(cal, pose))
        k = self.taken
        self.tracker.step(k, grey, uuv_u, uuv_v, float(uuv_radius_px(cal, pose)[0]))
        self._frames.append((k, pose, heading_rad))
        self.taken += 1
        t = float(pose.t_unix[0])
        while self._frames and self._frames[0][1].t_unix[0] < t - self.window_s:
            self._frames.popleft()
        self.tracker.forget(self._frames[0][0])

    def snapshot(self):
        """The window's frames as the estimate takes them: (:class:`~localizer.bottom.FramePoses`, their
        :class:`~localizer.bottom.Observations` numbered by position in the window, the GNSS's median 1-sigma)."""
        first = self._frames[0][0]
        pose = concatenated([p for _, p, _ in self._frames])
        poses = frame_poses(
            self.platform,
            pose,
            np.arange(len(self._frames)),
            self.frame_tilt,
            headings=[h for _, _, h in self._frames],
        )
        obs = self.tracker.observations()
        obs = dataclasses.replace(obs, frame=obs.frame - first)
        return poses, obs, float(np.nanmedian(pose.sigma_uav_m))

    def fit(self, snapshot) -> PoseCorrection | str:
        """The estimate from a :meth:`snapshot` (any thread), or why there is none."""
        return fit_window(self.platform, snapshot, self.frame_tilt)

    def frames(self) -> int:
        return len(self._frames)


def fit_window(platform: Platform, snapshot, frame_tilt: str) -> PoseCorrection | str:
    """The estimate from a window's :meth:`~BottomWindow.snapshot` (its tilt's bias frame ``frame_tilt``), or why
    there is none."""
    poses, obs, sigma_uav_m = snapshot
    if len(poses.t_s) < 3:
        return "fewer than 3 frames in the window"
    return fit(platform, poses, obs, sigma_uav_m, frame_tilt)


#: A bottom process's state (:func:`start_bottom`): the platform (the calibration: the telemetry is the service's),
#: the window's length (s) and, in the tracking process, its window (made at the first frame).
_process: dict = {}


def start_bottom(cal, window_s: float) -> None:
    """A bottom process (tracking or fitting): what its work takes besides the frames, and its imports, now."""
    _process.update(platform=Platform(cal, None), window_s=window_s, window=None)


def add_now(image, pose, heading_rad, uuv_u, uuv_v, frame_tilt: str, snapshot: bool):
    """The tracking process: :meth:`BottomWindow.add` to its window (a new one when the tilt's bias frame
    ``frame_tilt`` is not the window's: the mount became known); the window's frames, frames taken, and its
    :meth:`~BottomWindow.snapshot` when ``snapshot`` (else None)."""
    window = _process["window"]
    if window is None or window.frame_tilt != frame_tilt:
        window = _process["window"] = BottomWindow(
            _process["platform"], _process["window_s"], frame_tilt
        )
    window.add(image, pose, heading_rad, uuv_u, uuv_v)
    return window.frames(), window.taken, window.snapshot() if snapshot else None


def fit_now(snapshot, frame_tilt: str) -> PoseCorrection | str:
    """The fitting process: :func:`fit_window`."""
    return fit_window(_process["platform"], snapshot, frame_tilt)


@dataclasses.dataclass(frozen=True)
class Estimate:
    """A fit's outcome: the correction (None: refused, ``why``), the newest frame's time in its window."""

    correction: PoseCorrection | None
    why: str
    t_newest: float


def corrected(
    platform: Platform, correction: PoseCorrection, fix: Fix, pose: CameraPose
) -> Fix | None:
    """``fix`` (ok, made with ``pose`` of one frame) made again with ``correction`` and saying so
    (:data:`localizer.fix.POSE_COLUMNS`), or None where its claim (h_acc) is not smaller than the fix's own."""
    moved, cal = correction.apply(platform, pose)
    again = locate(cal, moved, [fix.u], [fix.v], sigma_px=[fix.sigma_pixel_px])
    if not again.h_acc_m[0] < fix.h_acc_m:
        return None
    for name, values in correction.values(platform, pose).items():
        setattr(again, name, values)
    return dataclasses.replace(again[0], frame=fix.frame, confidence=fix.confidence)


class LiveBottom:
    """The bottom's estimate live (see the module doc): :meth:`on_frame` (a frame listener, on the event loop),
    :meth:`on_tracked` (the pipeline's, the UUV's pixel), :meth:`correct` (each fix), :meth:`status` the ``bottom``
    section."""

    def __init__(self, cal, tel, every_s: float, window_s: float):
        self.platform = Platform(cal, tel)
        self.every_s, self.window_s = every_s, window_s
        self.frames = 0  # frames in the tracking process's window
        self.taken = 0  # frames added to it
        self.fits = 0  # estimates made
        self.refused = 0  # fits that gave none
        self.corrected = 0  # fixes made again with the estimate
        self.kept_own = 0  # fixes whose own claim was smaller than the corrected one's
        self._estimate: Estimate | None = None
        self._pixel = (-math.inf, math.nan, math.nan)  # the UUV's last tracked pixel: (t, u, v)
        self._headings: deque[tuple[float, str, float]] = deque(
            maxlen=64
        )  # (t, bias heading) of due frames
        self._fitting = False
        self._last_why = ""  # why the last fit gave none
        self._last_fit_t = (
            math.nan
        )  # the frame the last fit was started at (the first: the first frame's)
        self._applying = False
        self._tracking = SideProcess("bottom", start_bottom, cal, window_s)
        self._fitting_process = SideProcess("bottom-fit", start_bottom, cal, window_s)
        # its thread only hands the window to the fitting process and waits (see EveryFrame)
        self._fitter = ThreadPoolExecutor(1, thread_name_prefix="bottom-fit")
        self._track = EveryFrame(cal, tel, every_s, self.look, "bottom")

    # -- the frames (event loop, then the tracking thread) --------------------------------------------------------
    def on_frame(self, frame) -> None:
        if not frame.aligned:  # a frame stamped before the video's latency settled is not taken
            return
        # the tilt's bias frame and the airframe's heading, read on the loop where the telemetry is written (a servo
        # mount is known once its gimbal's messages came)
        frame_tilt = tilt_frame(self.platform)
        yaw = float(body_yaw(self.platform, [frame.t_unix])[0]) if frame_tilt == "body" else 0.0
        self._headings.append((frame.t_unix, frame_tilt, yaw))
        self._track.on_frame(frame)

    def on_tracked(self, image, pose: CameraPose, u: float, v: float) -> None:
        """The UUV's tracked pixel (a pipeline's listener): kept out of the floor features."""
        self._pixel = (float(pose.t_unix[0]), float(u), float(v))

    def look(self, image: np.ndarray, pose: CameraPose) -> None:
        """Track one frame (the tracking thread) and start a fit when one is due."""
        t = float(pose.t_unix[0])
        t_px, u, v = self._pixel
        if not abs(t - t_px) <= PIXEL_AGE_S:
            u = v = math.nan
        seen = next((h for h in reversed(self._headings) if h[0] == t), None)
        if seen is None:
            return
        _, frame_tilt, yaw = seen
        heading = (
            yaw
            if frame_tilt == "body"
            else float(bias_headings(self.platform, pose, frame_tilt)[0])
        )
        if not math.isfinite(heading):
            return
        if math.isnan(self._last_fit_t):  # the first fit once the window has REFIT_S of frames
            self._last_fit_t = t
        due = t - self._last_fit_t >= REFIT_S and not self._fitting
        if due:
            self._fitting, self._last_fit_t = True, t
        try:
            self.frames, self.taken, snapshot = self._tracking.call_on(
                add_now, image, pose, heading, u, v, frame_tilt, due
            )
        except ProcessLost:
            self._fitting = False
            raise
        if due:
            self._fitter.submit(self._fit, snapshot, frame_tilt, t).add_done_callback(self._fitted)

    def _fit(self, snapshot, frame_tilt: str, t_newest: float) -> Estimate:
        found = self._fitting_process.call(fit_now, snapshot, frame_tilt)
        if isinstance(found, str):
            return Estimate(None, found, t_newest)
        return Estimate(found, "", t_newest)

    def _fitted(self, done) -> None:
        self._fitting = False
        if done.exception() is not None:
            if not isinstance(done.exception(), ProcessLost):  # logged where it is started again
                log.error("bottom: the estimate failed: %s", done.exception())
            return
        est = done.result()
        self.fits += 1
        if est.correction is None:
            self.refused += 1
            log.debug("bottom: no estimate: %s", est.why)
            self._last_why = est.why
            return
        self.adopt(est)

    def adopt(self, est: Estimate) -> None:
        """Take a fit's estimate as the latest (the fitter's callback)."""
        self._last_why = ""
        self._estimate = est

    # -- the fixes (event loop) -------------------------------------------------------------------------------------
    def current(self, t_unix: float) -> Estimate | None:
        """The latest estimate when its newest frame is at most :data:`HOLD_WINDOWS` windows before ``t_unix`` (not
        after it: causal)."""
        est = self._estimate
        if est is None or not 0.0 <= t_unix - est.t_newest <= HOLD_WINDOWS * self.window_s:
            return None
        return est

    def corrected_pose(self, pose: CameraPose) -> tuple[CameraPose, object]:
        """``pose`` (one frame) and the calibration as the latest estimate corrects them (unchanged when there is
        none at its time)."""
        est = self.current(float(pose.t_unix[0]))
        if est is None:
            return pose, self.platform.calibration
        return est.correction.apply(self.platform, pose)

    def pose_only(self, pose: CameraPose) -> CameraPose:
        """:meth:`corrected_pose`'s pose (on the loop): what a reference's search sees the frame through."""
        return self.corrected_pose(pose)[0]

    def correct(self, fix: Fix, pose: CameraPose) -> Fix:
        """``fix`` (made with ``pose``) made again with the estimate's correction where its claim is smaller."""
        if not fix.ok:
            return fix
        est = self.current(fix.t_unix)
        applying = est is not None
        if applying != self._applying:
            self._applying = applying
            log.info(
                "%s",
                est.correction.describe()
                if applying
                else "pose from the bottom: lapsed (no estimate within the window)",
            )
        if not applying:
            return fix
        better = corrected(self.platform, est.correction, fix, pose)
        if better is None:
            self.kept_own += 1
            return fix
        self.corrected += 1
        return better

    def then(self, after):
        """A fix corrector: this one, then ``after(fix, pose)`` (a reference's) with the corrected pose."""

        def both(fix: Fix, pose: CameraPose) -> Fix:
            first = self.correct(fix, pose)
            if first.pose_source == "bottom":
                pose = self.corrected_pose(pose)[0]
            return after(first, pose)

        return both

    def status(self, now: float) -> dict:
        est = self._estimate
        current = self.current(now) if est is not None else None
        state = "applied" if current is not None else "lapsed" if est is not None else "estimating"
        out = {
            "state": state,
            "every_s": self.every_s,
            "window_s": self.window_s,
            "frames": self.frames,
            "taken": self.taken,
            "skipped": self._track.skipped,
            "no_pose": self._track.no_pose,
            "fits": self.fits,
            "refused": self.refused,
            "last_refusal": self._last_why or None,
            "age_s": round(now - est.t_newest, 3) if est is not None else None,
            "corrected": self.corrected,
            "kept_own": self.kept_own,
        }
        if est is None:
            return out | dict.fromkeys(ESTIMATE_KEYS)
        c = est.correction
        e = c.estimate
        walk = e.walk_at(est.t_newest)
        return out | {
            "tilt_frame": c.tilt_frame,
            "tilt_applied": bool(c.tilt_applied),
            "heading_applied": bool(c.yaw_applied),
            "tilt_fwd_deg": round(float(np.degrees(e.tilt_rad[0])), 4),
            "tilt_right_deg": round(float(np.degrees(e.tilt_rad[1])), 4),
            "sigma_tilt_deg": round(float(np.degrees(e.sigma_tilt_rad)), 4),
            "heading_deg": round(float(np.degrees(e.yaw_rad)), 4),
            "sigma_heading_deg": round(float(np.degrees(e.sigma_yaw_rad)), 4),
            "per_height_deg_per_m": [round(float(x), 4) for x in np.degrees(e.bias_per_height_rad)],
            "walk_n_m": round(float(walk[0]), 4),
            "walk_e_m": round(float(walk[1]), 4),
            "sigma_walk_m": round(float(np.hypot(*e.sigma_walk_at(est.t_newest))), 4),
            "floor_depth_m": round(e.floor_depth_m, 3),
            "features": e.n_features,
            "observations": e.n_observations,
            "rms_px": round(e.rms_px, 3),
        }

    def close(self) -> None:
        self._tracking.close()
        self._fitting_process.close()
        self._track.close()
        self._fitter.shutdown(wait=True, cancel_futures=True)


#: the status's keys of an estimate (None before the first)
ESTIMATE_KEYS = (
    "tilt_frame",
    "tilt_applied",
    "heading_applied",
    "tilt_fwd_deg",
    "tilt_right_deg",
    "sigma_tilt_deg",
    "heading_deg",
    "sigma_heading_deg",
    "per_height_deg_per_m",
    "walk_n_m",
    "walk_e_m",
    "sigma_walk_m",
    "floor_depth_m",
    "features",
    "observations",
    "rms_px",
)

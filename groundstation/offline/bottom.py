"""``skyfix process --pose-from-bottom auto``: the drone's pose biases from the static seafloor in its video.

Floor features (:func:`cv2.goodFeaturesToTrack`) are tracked through the video at about :data:`RATE_HZ`
(pyramidal Lucas–Kanade, kept only where the backward track returns within :data:`BACK_PX`), away from the
UUV (a disc around its tracked pixel, :func:`uuv_radius_px`); :func:`localizer.bottom.estimate` then finds the
camera's attitude error, the floor's depth and the position's walk (see there for what is observable).

Sunlit shallow water lays caustics over the floor: a web of thin bright lines, focused by the waves, that
drifts over the floor (centimetres to decimetres a second) and outshines its texture. Tracked as they come, the
floor points follow the web a little (the simulator's: 0.07 m/s, 2.8 px RMS against the true pose, heading and
tilt wrong by 0.7° and 0.3°). So the tracker sees the floor's small dark marks only (:func:`floor_marks`: caustics
only add light, so a grey opening wider than the web removes it and the black top-hat keeps what is darker than
its surroundings), and each point is matched again against the frame it was found in (:data:`ANCHOR_PX`): a chain
of frame-to-frame matches adds up any pull of what remains of the web, a match against the first sight does not
(0.6 px RMS, 0.007 m/s).

What separates a heading bias from the GNSS's walk is the reported velocity (a compass bias turns the floor's
slide, the velocity does not turn): the walk's prior is about what the velocity says, at a rate the recording
chooses. A first fit on :data:`VELOCITY_RATE_M` is linearized, and of the rates from :data:`MIN_WALK_RATE_M` to the
GNSS's own (:func:`walk_rates_m`) the estimate is made again at the one of the largest marginal likelihood
(:func:`localizer.bottom.walk_rate_log_evidence`): an exact velocity gets a tight prior (a survey line's walk is then
told by its velocity), one that the floor shows drifting a looser one; no fixed rate or floor suits both.

Where the tilt is the AHRS's (a servo mount or a fixed camera, :func:`tilt_frame` ``body``), it may wander about its
bias within the AHRS's wander (:data:`MIN_TILT_DEG`, :data:`TILT_WANDER_S`:
:attr:`localizer.bottom.Priors.tilt_wander_rad`); the correction turns each frame back by the tilt at its time.

The estimate is also made on each third of the recording alone (:data:`PARTS`), and its sigmas widened by
the thirds' spread (:func:`localizer.bottom.with_parts`). A fit whose residuals exceed :data:`MAX_RMS_PX` is not
applied (a warning says why); the tilt and the heading are applied each where the bottom told it
(:attr:`~localizer.bottom.BottomEstimate.tilt_estimated`) and its widened sigma is within what the calibration
states for it (``[uncertainty] tilt_deg``, ``yaw_deg``: else the bottom does not know it better than the platform).
The correction (:class:`PoseCorrection`) turns every frame's reported attitude back by the estimated error
(only the parts applied: a hovering drone's are left alone) and moves the reported position by the
walk and each frame's own remainder about what the velocity says between the walk's knots (the position's white
noise: :meth:`PoseCorrection.position_ne_m`); each fix's accuracy then takes the estimate's 1-sigmas (floored at :data:`MIN_TILT_DEG`,
:data:`MIN_YAW_DEG`: the AHRS's wander) instead of ``[uncertainty] tilt_deg``, ``yaw_deg``, and its height term the
height's error together with the tilt and heading it moves in the estimate
(:meth:`PoseCorrection.rotation_per_height_ned`: the floor does not tell the height), and its time term the camera's
motion relative to the UUV's own (:func:`locate_on_track`: a constant frame time error moves the camera and the UUV
alike, which the floor does not see). The walk is
relative to the GNSS's mean over the recording: its absolute offset stays the GNSS's, and the position's sigma in
h_acc is the GNSS's and the walk's own together (:meth:`PoseCorrection.sigma_position_m`); the walk's sigma takes
what the biases' error beyond the fit's moves it (the parts' spread; a bias not applied, held at 0 in the walk
fitted again, by the calibration's sigma, and how far that walk is from the free fit's: :func:`held_walk_error_m`). Each fix says what was estimated (:data:`localizer.fix.POSE_COLUMNS`, also in the
Zenoh fix message, :class:`groundstation.messages.FixMessage`), and positions.csv gets them per frame (columns after
skyfix's own, :func:`pose_cells`): ``pose_source`` (``bottom`` or empty), the estimated camera attitude error
``cam_err_n_deg``, ``cam_err_e_deg``, ``cam_err_d_deg`` (reported − true, a rotation vector in NED, as
``truth_errors.csv``), its 1-sigmas ``sigma_tilt_deg``, ``sigma_yaw_deg`` (empty where not applied), the position
correction applied ``walk_n_m``, ``walk_e_m`` (true = reported + walk) and its horizontal 1-sigma ``sigma_walk_m``
about the GNSS's mean. :func:`summary` is the same as one JSON object (``pose_from_bottom.json`` beside
positions.csv).
"""

from __future__ import annotations

import csv
import dataclasses
import json
import os
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from groundstation.offline.progress import progress as progress_bar
from groundstation.session.read import Session
from localizer import bottom, gnss
from localizer.calibration import Calibration
from localizer.fix import POSE_COLUMNS, Fixes, locate
from localizer.geodesy import geodetic_to_ned, ned_to_geodetic
from localizer.height import GNSS_TAU_S, GNSS_WHITE
from localizer.pose import CameraPose, servo_mount

MODES = ("auto", "off")
NAME = "pose_from_bottom.json"  # beside positions.csv: :func:`summary`
RATE_HZ = 5.0  # frames used per second of video
MAX_FEATURES = 250  # corners tracked at once
MIN_DISTANCE_PX = 12  # between corners
BACK_PX = 0.5  # forward-backward track disagreement that drops a corner
# a point matched against its first sight this far from the chain's match is dropped
ANCHOR_PX = 2.0
#: bright lines on the floor narrower than this are taken for caustics and removed (:func:`floor_marks`), and the
#: floor's dark marks smaller than it are what is tracked (m, at the camera's slant range)
CAUSTIC_WEB_M = 0.2
BORDER_PX = 8
MIN_OBSERVATIONS = 3  # a feature seen fewer times says nothing
MIN_FEATURES = 20  # fewer features: no estimate
PARTS = 3  # the estimate is also made on each of this many consecutive stretches alone; its sigmas take their spread
#: a fit worse than this (RMS of the inlying residuals, pixels) is not applied: the floor's image does not stay put
#: (the simulator's caustics drifting over it: 0.85-1.0 px, against 0.41 without them), and the sigmas, which take
#: the residuals as white, would claim far more than the estimate knows
MAX_RMS_PX = 0.6
#: m/√s: the integrated EKF velocity's error, the walk's prior of the first fit (at most the GNSS's own), before the
#: recording chose its rate (:func:`walk_rates_m`)
VELOCITY_RATE_M = 0.05
#: m/√s: the tightest walk rate the recording may choose (an EKF velocity good to 0.5 mm/s over a second)
MIN_WALK_RATE_M = 0.0005
#: the candidate rates' density (their marginal likelihood is cheap: no fit each)
WALK_RATES_PER_DECADE = 8
MIN_WHITE_M = 0.003  # the reported position's white noise (localizer.bottom.white_noise_m) taken at least this
# the GNSS error's correlation time assumed: its rate is sigma_uav / √(this) per √s
GNSS_WALK_S = 60.0
# the estimate's sigmas in h_acc are floored here (the attitude's wander is not a bias)
MIN_TILT_DEG = 0.05
MIN_YAW_DEG = 0.1
#: s: the AHRS wander's correlation time (a first-order Gauss-Markov of 1-sigma MIN_TILT_DEG): the tilt's prior
#: between the walk's knots (:attr:`localizer.bottom.Priors.tilt_wander_rad`)
TILT_WANDER_S = 60.0
#: s: the UUV's velocity for the fixes' time term is the slope of its fixes over this long about each frame
#: (:func:`track_velocity_ne_mps`): long enough that the fixes' scatter (waves, pixel) makes millimetres a second of
#: it, short against the UUV's turns
TRACK_VELOCITY_S = 1.0
_LK = {
    "winSize": (31, 31),
    "maxLevel": 4,
    "criteria": (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 0.01),
}


def uuv_radius_px(cal: Calibration, pose: CameraPose) -> np.ndarray:
    """The radius (pixels) of the disc around the UUV's pixel where no floor feature is taken: twice its longest
    side (the diagonal of length and width) at its slant range, at least 20 px."""
    side_m = np.hypot(cal.uuv.length_m, cal.uuv.width_m)
    axis_down = np.clip(pose.R_ned_from_cv[:, 2, 2], 0.2, 1.0)  # the optical axis's down component
    slant_m = (pose.height_m + np.nan_to_num(pose.depth_m)) / axis_down
    return np.maximum(20.0, 2.0 * cal.camera.fx * side_m / slant_m)


def web_kernel_px(cal: Calibration, pose: CameraPose) -> int:
    """:data:`CAUSTIC_WEB_M` in pixels (odd, at least 3) at the median slant range of the optical axis to the water."""
    axis_down = np.clip(pose.R_ned_from_cv[:, 2, 2], 0.2, 1.0)
    slant_m = float(np.nanmedian(pose.height_m / axis_down))
    return max(3, 2 * round(0.5 * cal.camera.fx * CAUSTIC_WEB_M / slant_m) + 1)


def floor_marks(grey: np.ndarray, kernel_px: int) -> np.ndarray:
    """The floor's small dark marks, the caustics taken off (8 bits): a grey opening (the minimum, then the maximum,
    over a disc ``kernel_px`` across) removes bright structures narrower than the disc (the caustic web: caustics only
    add light); the black top-hat of that (its closing less itself) keeps what is darker than its surroundings and
    smaller than the disc (stones, shells, pits; not the broad shading); smoothed (σ 1 px) and stretched (its 99.5th
    percentile to 255)."""
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (kernel_px, kernel_px))
    opened = cv2.morphologyEx(grey, cv2.MORPH_OPEN, disc)
    marks = cv2.GaussianBlur(
        cv2.morphologyEx(opened, cv2.MORPH_BLACKHAT, disc).astype(np.float32), (0, 0), 1.0
    )
    top = max(float(np.percentile(marks, 99.5)), 1e-3)
    return np.clip(marks * (255.0 / top), 0, 255).astype(np.uint8)


class FloorTracker:
    """Floor feature tracks frame by frame (pyramidal Lucas–Kanade in :func:`floor_marks` images, each point matched
    again against its first sight, away from the UUV's disc; new corners where fewer than 70 % of
    :data:`MAX_FEATURES` are left): :meth:`step` with each frame in turn, :meth:`observations` the tracks so far.
    ``width``, ``height``: the image's (pixels)."""

    def __init__(self, width: int, height: int):
        self.width, self.height = width, height
        self.frame: list[int] = []  # per observation: the frame's number as given to step ...
        self.feature: list[int] = []  # ... the feature's, and its pixel
        self.us: list[float] = []
        self.vs: list[float] = []
        self.next_id = 0
        self._prev = None
        self._points, self._ids = np.zeros((0, 1, 2), np.float32), np.zeros(0, int)
        # each point's first sight: its frame, pixel, and the frames' images
        self._first_k, self._first_xy, self._images = (
            np.zeros(0, int),
            np.zeros((0, 1, 2), np.float32),
            {},
        )

    def step(self, k: int, grey: np.ndarray, uuv_u: float, uuv_v: float, radius_px: float) -> None:
        """Track into frame number ``k`` (increasing), ``grey`` its :func:`floor_marks`; the UUV at pixel ``uuv_u``,
        ``uuv_v`` (NaN: not known) with no feature within ``radius_px`` of it."""
        self._images[k] = grey
        points, ids, first_k, first_xy = self._points, self._ids, self._first_k, self._first_xy
        if self._prev is not None and len(points):
            p1, ok1, _ = cv2.calcOpticalFlowPyrLK(self._prev, grey, points, None, **_LK)
            back, ok2, _ = cv2.calcOpticalFlowPyrLK(grey, self._prev, p1, None, **_LK)
            good = (
                (ok1.ravel() == 1)
                & (ok2.ravel() == 1)
                & (np.linalg.norm((back - points).reshape(-1, 2), axis=1) < BACK_PX)
            )
            p1, anchored = _match_first_sight(self._images, first_k, first_xy, grey, p1)
            good &= anchored
            points, ids, first_k, first_xy = p1[good], ids[good], first_k[good], first_xy[good]
        keep = _away(points.reshape(-1, 2), self.width, self.height, uuv_u, uuv_v, radius_px)
        points, ids, first_k, first_xy = points[keep], ids[keep], first_k[keep], first_xy[keep]
        if len(points) < 0.7 * MAX_FEATURES:
            new = _corners(grey, points.reshape(-1, 2), uuv_u, uuv_v, radius_px)
            new = new.reshape(-1, 1, 2).astype(np.float32)
            points, first_xy = np.concatenate([points, new]), np.concatenate([first_xy, new])
            first_k = np.concatenate([first_k, np.full(len(new), k)])
            ids = np.concatenate([ids, np.arange(self.next_id, self.next_id + len(new))])
            self.next_id += len(new)
        self._images = {j: self._images[j] for j in set(first_k.tolist())}
        xy = points.reshape(-1, 2)
        self.frame += [k] * len(xy)
        self.feature += list(ids)
        self.us += list(xy[:, 0])
        self.vs += list(xy[:, 1])
        self._prev = grey
        self._points, self._ids, self._first_k, self._first_xy = points, ids, first_k, first_xy

    def forget(self, before_k: int) -> None:
        """Let go of the observations in frames numbered below ``before_k`` (the tracks go on)."""
        keep = [i for i, k in enumerate(self.frame) if k >= before_k]
        self.frame = [self.frame[i] for i in keep]
        self.feature = [self.feature[i] for i in keep]
        self.us = [self.us[i] for i in keep]
        self.vs = [self.vs[i] for i in keep]

    def observations(self) -> bottom.Observations:
        """The tracks so far: :class:`localizer.bottom.Observations` (``frame`` the numbers given to :meth:`step`) of the
        features seen at least :data:`MIN_OBSERVATIONS` times, numbered 0..F-1."""
        frame, feature = np.asarray(self.frame, int), np.asarray(self.feature, int)
        counts = np.bincount(feature, minlength=self.next_id) if self.next_id else np.zeros(0, int)
        seen = counts[feature] >= MIN_OBSERVATIONS if len(feature) else np.zeros(0, bool)
        _, renumbered = np.unique(feature[seen], return_inverse=True)
        return bottom.Observations(
            frame[seen], renumbered, np.asarray(self.us)[seen], np.asarray(self.vs)[seen]
        )


def track_bottom(
    session: Session,
    rows: np.ndarray,
    uuv_u,
    uuv_v,
    radius_px,
    kernel_px: int,
    progress: bool = False,
):
    """Floor feature tracks through the frames at ``rows`` of video_frames.csv (:class:`FloorTracker`):
    :class:`localizer.bottom.Observations` with ``frame`` indexing ``rows``. ``uuv_u``, ``uuv_v``, ``radius_px`` per
    row (NaN: the UUV not known there); tracked in :func:`floor_marks` of ``kernel_px`` (:func:`web_kernel_px`)."""
    cal = session.calibration
    wanted = {int(session.frames["frame"][r]): k for k, r in enumerate(rows)}
    tracker = FloorTracker(cal.camera.width, cal.camera.height)
    bar = progress_bar(len(rows), f"{session.path.name}: bottom features", progress)
    try:
        with session.open_video(grey=True) as video:
            for vf in video.prefetch():
                k = wanted.get(vf.index)
                if k is None:
                    continue
                r = rows[k]
                tracker.step(
                    k, floor_marks(grey_of(vf.image), kernel_px), uuv_u[r], uuv_v[r], radius_px[r]
                )
                bar.update()
    finally:
        bar.close()
    return tracker.observations()


def grey_of(image: np.ndarray) -> np.ndarray:
    """An image as 8-bit grey (a grey one as it is)."""
    return image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)


def _match_first_sight(images, first_k, first_xy, grey, predicted):
    """The points (n, 1, 2) matched again in ``grey`` against their first sight (``images[first_k]`` at
    ``first_xy``), starting from the chain's ``predicted``, and whether each held (found within :data:`ANCHOR_PX`)."""
    matched, held = predicted.copy(), np.zeros(len(predicted), bool)
    for k in np.unique(first_k):
        i = np.flatnonzero(first_k == k)
        p, ok, _ = cv2.calcOpticalFlowPyrLK(
            images[k],
            grey,
            first_xy[i],
            predicted[i].copy(),
            **{**_LK, "maxLevel": 1},
            flags=cv2.OPTFLOW_USE_INITIAL_FLOW,
        )
        held[i] = (ok.ravel() == 1) & (
            np.linalg.norm((p - predicted[i]).reshape(-1, 2), axis=1) < ANCHOR_PX
        )
        matched[i] = p
    return matched, held


def _away(xy, width, height, u, v, radius):
    """Points inside the image (by :data:`BORDER_PX`) and outside the UUV's disc."""
    inside = (
        (xy[:, 0] >= BORDER_PX)
        & (xy[:, 0] <= width - 1 - BORDER_PX)
        & (xy[:, 1] >= BORDER_PX)
        & (xy[:, 1] <= height - 1 - BORDER_PX)
    )
    if np.isfinite(u) and np.isfinite(v):
        inside &= np.hypot(xy[:, 0] - u, xy[:, 1] - v) > radius
    return inside


def _corners(grey, existing, u, v, radius):
    """New corners away from the existing ones, the UUV and the border."""
    mask = np.zeros(grey.shape, np.uint8)
    mask[BORDER_PX:-BORDER_PX, BORDER_PX:-BORDER_PX] = 255
    for x, y in existing:
        cv2.circle(mask, (round(float(x)), round(float(y))), MIN_DISTANCE_PX, 0, -1)
    if np.isfinite(u) and np.isfinite(v):
        cv2.circle(mask, (round(float(u)), round(float(v))), int(np.ceil(radius)), 0, -1)
    want = MAX_FEATURES - len(existing)
    found = cv2.goodFeaturesToTrack(
        grey,
        maxCorners=int(want),
        qualityLevel=0.01,
        minDistance=MIN_DISTANCE_PX,
        blockSize=7,
        mask=mask,
    )
    return np.zeros((0, 2), np.float32) if found is None else found.reshape(-1, 2)


@dataclass
class PoseCorrection:
    """An estimate and how it is applied to the frames (see the module doc)."""

    estimate: bottom.BottomEstimate
    tilt_applied: bool
    yaw_applied: bool
    tilt_frame: str  # "camera" (a stabilised gimbal's own heading) or "body" (the airframe's)

    def headings(self, session: Session, pose: CameraPose) -> np.ndarray:
        """The bias frame's heading per frame of ``pose``."""
        return bias_headings(session, pose, self.tilt_frame)

    def error_rotvec(self, session: Session, pose: CameraPose) -> np.ndarray:
        """The attitude error applied (reported − true, NED rotation vector) per frame: the told parts only."""
        e = self.estimate
        tilt = e.tilt_at(pose.t_unix) if self.tilt_applied else np.zeros(2)
        return bottom.bias_rotvec(
            tilt, e.yaw_rad if self.yaw_applied else 0.0, self.headings(session, pose)
        )

    def apply(self, session: Session, pose: CameraPose) -> tuple[CameraPose, Calibration]:
        """The poses with the attitude turned back and the position moved by the walk, and the calibration whose
        tilt and heading sigmas are the estimate's (where applied)."""
        R = bottom.rodrigues(-self.error_rotvec(session, pose)) @ pose.R_ned_from_cv
        walk = self.position_ne_m(pose)
        lat, lon, _ = ned_to_geodetic(
            walk[:, 0], walk[:, 1], 0.0, pose.lat_deg, pose.lon_deg, pose.alt_amsl_m
        )
        corrected = dataclasses.replace(
            pose,
            R_ned_from_cv=R,
            lat_deg=np.asarray(lat),
            lon_deg=np.asarray(lon),
            sigma_uav_m=self.sigma_position_m(pose),
            rotation_per_height_ned=self.rotation_per_height_ned(session, pose),
        )
        cal = session.calibration
        claimed = {k: v for k, v in self.claimed_deg().items() if v is not None}
        return corrected, dataclasses.replace(
            cal, sigmas=dataclasses.replace(cal.sigmas, **claimed)
        )

    def sigma_position_m(self, pose: CameraPose) -> np.ndarray:
        """The corrected position's horizontal 1-sigma per frame of ``pose`` (a DRMS, as ``sigma_uav_m``): the
        GNSS's (its offset, which the walk about its mean does not see) and the walk's own error together. The
        walk replaces the GNSS's wander about its mean with its own error: the GNSS's sigma, which held both the
        offset and that wander, is kept whole (never surer)."""
        e = self.estimate
        return np.hypot(pose.sigma_uav_m, np.hypot(*e.sigma_walk_at(pose.t_unix).T))

    def rotation_per_height_ned(self, session: Session, pose: CameraPose) -> np.ndarray:
        """The attitude error applied that comes with each metre the heights read high (rad per metre, NED rotation
        vector per frame of ``pose``: :attr:`localizer.bottom.BottomEstimate.bias_per_height_rad`, the parts applied
        only): a fix's height term in h_acc is the height's error and this together."""
        e = self.estimate
        per_m = e.bias_per_height_rad
        return bottom.bias_rotvec(
            per_m[:2] if self.tilt_applied else np.zeros(2),
            per_m[2] if self.yaw_applied else 0.0,
            self.headings(session, pose),
        )

    def claimed_deg(self) -> dict[str, float | None]:
        """The tilt's and the heading's 1-sigmas (degrees) each fix's accuracy takes instead of ``[uncertainty]
        tilt_deg``, ``yaw_deg``: the estimate's (with the parts' spread), floored at :data:`MIN_TILT_DEG`,
        :data:`MIN_YAW_DEG` (the AHRS's wander); None where that part is not applied (the calibration's stays)."""
        e = self.estimate
        return {
            "tilt_deg": max(MIN_TILT_DEG, float(np.degrees(e.sigma_tilt_rad)))
            if self.tilt_applied
            else None,
            "yaw_deg": max(MIN_YAW_DEG, float(np.degrees(e.sigma_yaw_rad)))
            if self.yaw_applied
            else None,
        }

    def position_ne_m(self, pose: CameraPose) -> np.ndarray:
        """The position correction (K, 2) per frame of ``pose`` (true = reported + it): the walk, and where the
        frames have a velocity each one's own remainder about what the velocity says between the walk's knots
        (:func:`localizer.bottom.velocity_drift`: the reported position's white noise, which the knots cannot
        follow; 0 where unknown). The remainder is about the velocity's curve that the fit's walk followed
        (:attr:`localizer.bottom.BottomEstimate.velocity_walk_ne_m`, fitted on the fit's frames), not one fitted
        again to these frames: the two differ by the white noise's share in the knots (a plain receiver's
        centimetres of it put millimetres into every knot), which the walk would not carry."""
        e = self.estimate
        walk = e.walk_at(pose.t_unix)
        if len(pose.t_unix) < 3:
            return walk
        _, remainder = bottom.velocity_drift(
            pose.t_unix,
            pose.velocity_ned_mps[:, :2],
            uav_ne_m(pose),
            e.knot_t_s,
            e.velocity_walk_ne_m if len(e.velocity_walk_ne_m) else None,
        )
        return walk + np.nan_to_num(remainder)

    def describe(self) -> str:
        """One line: what was estimated and how sure (:meth:`localizer.bottom.BottomEstimate.describe`), what was
        applied, and the sigmas h_acc took for it (:meth:`claimed_deg`; the rest of h_acc is as without it)."""
        what = [w for w, on in (("tilt", self.tilt_applied), ("heading", self.yaw_applied)) if on]
        applied = (
            f"applied: {' and '.join(what)} ({self.tilt_frame} frame tilt) and the position walk"
            if what
            else "applied: the position walk only"
        )
        claimed = [
            f"{word} ± {sigma:.2f}°"
            for word, sigma in zip(("tilt", "heading"), self.claimed_deg().values())
            if sigma is not None
        ]
        if claimed:
            applied += f"; h_acc takes {' and '.join(claimed)} for them, not [uncertainty]'s"
        applied += (
            "; not told by the bottom, in h_acc: the GNSS's offset (the walk is about its mean; with the walk's "
            "sigma) and the camera's height (the floor's depth takes most of its error; its term has the tilt and "
            "heading it moves)"
        )
        return f"pose from the bottom: {self.estimate.describe()}; {applied}"

    def values(self, session: Session, pose: CameraPose) -> dict[str, np.ndarray]:
        """The fixes' :data:`localizer.fix.POSE_COLUMNS` per frame of ``pose`` (the reported poses; see the module
        doc): what was estimated and applied, NaN sigmas where a part was not applied."""
        e, n = self.estimate, len(pose.t_unix)
        err = np.degrees(self.error_rotvec(session, pose))
        walk = self.position_ne_m(pose)
        sigma_walk = e.sigma_walk_at(pose.t_unix)
        return {
            "pose_source": np.full(n, "bottom", dtype=object),
            **{c: err[:, i] for i, c in enumerate(POSE_COLUMNS[1:4])},
            "sigma_tilt_deg": np.full(
                n, np.degrees(e.sigma_tilt_rad) if self.tilt_applied else np.nan
            ),
            "sigma_yaw_deg": np.full(
                n, np.degrees(e.sigma_yaw_rad) if self.yaw_applied else np.nan
            ),
            "walk_n_m": walk[:, 0],
            "walk_e_m": walk[:, 1],
            "sigma_walk_m": np.hypot(sigma_walk[:, 0], sigma_walk[:, 1]),
        }


def locate_on_track(cal: Calibration, pose: CameraPose, u, v, **kwargs) -> Fixes:
    """:func:`localizer.fix.locate`'s fixes (its ``kwargs``) of the poses a :class:`PoseCorrection` applied, their time
    term taking the camera's motion relative to the UUV's own (:func:`track_velocity_ne_mps` of the fixes made first):
    the pose from the bottom is measured in the frames, so a frame stamped late puts both the camera and the UUV
    where they were at its exposure, and its fix is off by the camera's motion less the UUV's (a drone flying with
    the UUV: next to none), not by the drone's whole motion. The positions are :func:`locate`'s."""
    first = locate(cal, pose, u, v, **kwargs)
    return locate(cal, pose, u, v, target_velocity_ne_mps=track_velocity_ne_mps(first), **kwargs)


def track_velocity_ne_mps(fixes: Fixes) -> np.ndarray:
    """(N, 2) the located UUV's horizontal velocity (m/s) at each fix: the slope of a straight line (least squares)
    through its ``ok`` fixes within :data:`TRACK_VELOCITY_S` / 2 either side, 0 where fewer than 3 (the time term then
    takes the camera's whole motion, as without a track)."""
    t = np.asarray(fixes.t_unix, dtype=float)
    out = np.zeros((len(t), 2))
    ok = np.flatnonzero((fixes.status == "ok") & np.isfinite(fixes.lat) & np.isfinite(t))
    if len(ok) < 3:
        return out
    n, e, _ = geodetic_to_ned(
        fixes.lat[ok], fixes.lon[ok], 0.0, fixes.lat[ok[0]], fixes.lon[ok[0]], 0.0
    )
    tk = t[ok] - t[ok[0]]
    lo = np.searchsorted(tk, tk - TRACK_VELOCITY_S / 2, side="left")
    hi = np.searchsorted(tk, tk + TRACK_VELOCITY_S / 2, side="right")
    sums = [
        np.concatenate([[0.0], np.cumsum(x)])
        for x in (np.ones_like(tk), tk, tk * tk, tk * n, tk * e, n, e)
    ]
    c, st, stt, stn, ste, sn, se = (s[hi] - s[lo] for s in sums)
    var = c * stt - st * st
    fit = (c >= 3) & (var > 1e-12)
    with np.errstate(divide="ignore", invalid="ignore"):
        out[ok, 0] = np.where(fit, (c * stn - st * sn) / var, 0.0)
        out[ok, 1] = np.where(fit, (c * ste - st * se) / var, 0.0)
    return out


def summary(correction: PoseCorrection) -> dict:
    """What was estimated, how sure and what was applied, as one JSON object (degrees, metres): the tilt about the
    bias frame (``tilt_frame``: the camera's heading or the airframe's) forward and right (and the largest of its
    wander about them, 0 where none is modelled), the heading, their 1-sigmas (with the parts' spread), how they move per metre the height reads high and each part's values, the floor's depth, the position's walk about the
    GNSS's mean (largest, and its largest 1-sigma), the walk prior's rate (m/√s, as the recording chose it), the
    fit (features, observations, frames, RMS pixels, slide share)."""
    e = correction.estimate
    deg = [round(float(np.degrees(x)), 4) for x in (*e.tilt_rad, e.yaw_rad)]
    return {
        "estimated": {"tilt": bool(e.tilt_estimated), "heading": bool(e.yaw_estimated)},
        "applied": {
            "tilt": bool(correction.tilt_applied),
            "heading": bool(correction.yaw_applied),
            "walk": True,
        },
        "tilt_frame": correction.tilt_frame,
        "tilt_fwd_deg": deg[0],
        "tilt_right_deg": deg[1],
        "sigma_tilt_deg": round(float(np.degrees(e.sigma_tilt_rad)), 4),
        "tilt_wander_max_deg": round(
            float(np.degrees(np.max(np.abs(e.tilt_wander_rad), initial=0.0))), 4
        ),
        "heading_deg": deg[2],
        "sigma_heading_deg": round(float(np.degrees(e.sigma_yaw_rad)), 4),
        "per_height_deg_per_m": [round(float(x), 4) for x in np.degrees(e.bias_per_height_rad)],
        "parts_deg": [
            [None if not np.isfinite(x) else round(float(np.degrees(x)), 4) for x in part[:3]]
            for part in e.parts
        ],
        "floor_depth_m": round(e.floor_depth_m, 4),
        "sigma_floor_depth_m": round(e.sigma_floor_depth_m, 4),
        "walk_max_m": round(float(np.max(np.hypot(*e.walk_ne_m.T))), 4),
        "sigma_walk_max_m": round(float(np.max(np.hypot(*e.sigma_walk_ne_m.T))), 4),
        "walk_rate_m_per_sqrt_s": round(float(e.priors.walk_rate_m), 5),
        "features": e.n_features,
        "observations": e.n_observations,
        "frames": e.n_frames,
        "rms_px": round(e.rms_px, 3),
        "slide_share": round(e.slide_share, 3),
    }


def write_summary(path: Path, correction: PoseCorrection) -> None:
    """:func:`summary` as a JSON file (atomically: a temporary file, then renamed)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".partial")
    tmp.write_text(json.dumps(summary(correction), indent=2) + "\n")
    os.replace(tmp, path)


def pose_cells(fixes: Fixes) -> dict[str, list[str]]:
    """positions.csv's extra cells per fix: :data:`localizer.fix.POSE_COLUMNS` (degrees and metres to 4 decimals,
    empty where NaN)."""
    return {
        c: [
            str(x) if c == "pose_source" else (f"{x:.4f}" if np.isfinite(x) else "")
            for x in getattr(fixes, c)
        ]
        for c in POSE_COLUMNS
    }


def uav_ne_m(pose: CameraPose) -> np.ndarray:
    """The reported UAV's horizontal position (K, 2), m north and east of the first frame with a position."""
    finite = np.flatnonzero(np.isfinite(pose.lat_deg))
    first = int(finite[0]) if len(finite) else 0
    origin = (pose.lat_deg[first], pose.lon_deg[first], pose.alt_amsl_m[first])
    n, e, _ = geodetic_to_ned(pose.lat_deg, pose.lon_deg, pose.alt_amsl_m, *origin)
    return np.column_stack([n, e])


def bias_headings(session: Session, pose: CameraPose, frame: str) -> np.ndarray:
    """The heading (radians) per frame of ``pose`` of the tilt's bias frame ``frame`` (:func:`tilt_frame`)."""
    if frame == "camera":
        return bottom.camera_heading_rad(pose.R_ned_from_cv)
    return body_yaw(session, pose.t_unix)


def body_yaw(session: Session, t_unix) -> np.ndarray:
    """The airframe's heading (radians) at times ``t_unix`` (station clock) from the session's attitude."""
    tel = session.telemetry
    a, _, _ = tel.attitude.sample(tel.uav_time(np.asarray(t_unix, dtype=float)))
    return a[:, 2]


def tilt_frame(session: Session) -> str:
    """Where the camera's tilt error lives: a stabilised gimbal's own heading, or the airframe's (a servo mount or a
    fixed camera carry the AHRS's tilt)."""
    cal = session.calibration
    if cal.mount.attitude_source == "fixed" or servo_mount(cal, session.telemetry):
        return "body"
    return "camera"


def subsample_rows(t: np.ndarray, rate_hz: float = RATE_HZ) -> np.ndarray:
    """Rows of frames about ``1/rate_hz`` apart."""
    if len(t) < 2:
        return np.arange(len(t))
    period = float(np.median(np.diff(t)))
    step = max(1, round(1.0 / (rate_hz * period)))
    return np.arange(0, len(t), step)


def pose_from_bottom(session: Session, pose: CameraPose, uuv_u, uuv_v, progress: bool = False):
    """The :class:`PoseCorrection` for a session whose frames have ``pose`` (all of video_frames.csv's rows) and the
    UUV's pixels ``uuv_u``, ``uuv_v`` (NaN where unknown), or a string saying why there is none."""
    if session.video_path is None or session.frames is None:
        return "no video"
    rows = subsample_rows(session.frames["t"])
    rows = rows[pose.status[rows] == "ok"]
    if len(rows) < 3:
        return "fewer than 3 frames with a pose"
    obs = track_bottom(
        session,
        rows,
        np.asarray(uuv_u, float),
        np.asarray(uuv_v, float),
        uuv_radius_px(session.calibration, pose),
        web_kernel_px(session.calibration, pose),
        progress,
    )
    frame_tilt = tilt_frame(session)
    poses = frame_poses(session, pose, rows, frame_tilt)
    sigma_uav_m = float(np.nanmedian(pose.sigma_uav_m[rows]))
    return fit(session, poses, obs, sigma_uav_m, frame_tilt, kept_height_wander_m(session, poses))


def frame_poses(
    session: Session, pose: CameraPose, rows: np.ndarray, frame_tilt: str, headings=None
) -> bottom.FramePoses:
    """The reported cameras of the frames ``rows`` of ``pose`` as the estimate takes them (:func:`uav_ne_m` of all
    ``pose``'s frames, the bias frame ``frame_tilt``'s headings: :func:`bias_headings`, or ``headings`` (radians, one
    per frame of ``pose``) when given)."""
    uav_ne = uav_ne_m(pose)
    if headings is None:
        headings = bias_headings(session, pose, frame_tilt)
    return bottom.FramePoses(
        pose.t_unix[rows],
        pose.R_ned_from_cv[rows],
        (uav_ne + pose.cam_offset_ned_m[:, :2])[rows],
        pose.height_m[rows],
        np.asarray(headings, float)[rows],
        pose.velocity_ned_mps[rows, :2],
        uav_ne[rows],
    )


def fit(
    session: Session,
    poses: bottom.FramePoses,
    obs: bottom.Observations,
    sigma_uav_m: float,
    frame_tilt: str,
    height_wander_m: float | None = None,
):
    """The :class:`PoseCorrection` from floor tracks ``obs`` seen from ``poses`` (the GNSS's horizontal 1-sigma
    ``sigma_uav_m``, the tilt's bias frame ``frame_tilt``), or a string saying why there is none (see the module
    doc). ``session``: anything with the session's ``calibration`` and ``telemetry``. ``height_wander_m``: the
    heights' wander the walk's sigma takes (:func:`kept_height_wander_m`; None: the barometer's, ``[uncertainty]
    baro_wander_m`` at most ``height_m``, as the live service's fits take it)."""
    n_features = int(obs.feature.max()) + 1 if len(obs.feature) else 0
    if n_features < MIN_FEATURES:
        return f"{n_features} floor features tracked (fewer than {MIN_FEATURES})"
    gnss_rate = sigma_uav_m / np.sqrt(GNSS_WALK_S)
    white = bottom.white_noise_m(poses)
    sigmas = session.calibration.sigmas
    priors = bottom.Priors(
        walk_rate_m=min(gnss_rate, VELOCITY_RATE_M),
        walk_rates_m=walk_rates_m(gnss_rate),
        white_m=0.0 if white is None else max(MIN_WHITE_M, white),
        tilt_wander_rad=np.radians(MIN_TILT_DEG) if frame_tilt == "body" else 0.0,
        tilt_wander_s=TILT_WANDER_S,
        height_wander_m=min(sigmas.baro_wander_m, sigmas.height_m)
        if height_wander_m is None
        else height_wander_m,
        height_wander_s=sigmas.baro_wander_s,
    )
    cam, n_water = session.calibration.camera, session.calibration.water.refractive_index
    est = bottom.estimate(cam, n_water, poses, obs, priors, parts=PARTS)
    priors = est.priors  # the walk rate the recording chose
    if est.rms_px > MAX_RMS_PX:
        return (
            f"the floor features do not stay put as a static floor would ({est.rms_px:.2f} px RMS, more than "
            f"{MAX_RMS_PX}: drifting light such as caustics, or a moving bottom); found but not applied: "
            f"{est.describe()}"
        )
    tilt, yaw = applicable(est, session.calibration)
    if not (tilt and yaw):  # the walk again, with what is not applied held at 0
        held = dataclasses.replace(
            priors,
            tilt_rad=priors.tilt_rad if tilt else 1e-7,
            tilt_wander_rad=priors.tilt_wander_rad if tilt else 0.0,
            yaw_rad=priors.yaw_rad if yaw else 1e-7,
        )
        again = bottom.estimate(cam, n_water, poses, obs, held)
        est = dataclasses.replace(
            again,
            cov_bias=est.cov_bias,
            sigma_floor_depth_m=est.sigma_floor_depth_m,
            priors=est.priors,
            parts=est.parts,
            bias_per_height_rad=est.bias_per_height_rad,
            walk_per_bias_m=est.walk_per_bias_m,
        ).with_walk_error(
            held_walk_error_m(est, again, sigmas, tilt, yaw)
        )  # sigmas: the free estimate's
    return PoseCorrection(est, tilt, yaw, frame_tilt)


def kept_height_wander_m(session: Session, poses: bottom.FramePoses) -> float:
    """The walk's prior for the reported heights' wander (:attr:`localizer.bottom.Priors.height_wander_m`, a
    first-order Gauss-Markov of ``[uncertainty] baro_wander_s``). The walk takes up how the heights' error changes
    over the recording (:func:`localizer.bottom.height_wander_cov_m2`), not its level: the barometer's wander
    (``baro_wander_m``, at most ``height_m``) where the heights follow it, less where they follow GNSS altitudes
    (the height's estimator fuses them, :mod:`localizer.height`). Their error then changes by what they move
    against the GNSS altitudes (the difference averaged over each of the walk's knot spans, about its mean: the
    GNSS's white noise left in it counts too) and by the GNSS altitude's own slow error's change (1-sigma the
    receiver's vertical accuracy less its white share, :data:`localizer.height.GNSS_WHITE`, correlation time
    :data:`localizer.height.GNSS_TAU_S`) together; the prior is the wander whose change over these knots is that
    (never more than the barometer's; without a GNSS altitude over every knot span, the barometer's)."""
    sigmas = session.calibration.sigmas
    barometer = min(sigmas.baro_wander_m, sigmas.height_m)
    tel = session.telemetry
    knots = bottom.knot_times(poses.t_s, bottom.Priors.knot_spacing_s)
    if barometer == 0 or len(knots) < 2 or not len(tel.gnss.times):
        return barometer
    frames_uav = tel.uav_time(np.asarray(poses.t_s, dtype=float))
    t, values = tel.gnss.times, tel.gnss.values
    fix, alt, v_acc, vdop = (values[:, i] for i in (2, 3, 4, 6))
    sigma_v = gnss.vertical_sigma_m(fix, v_acc, vdop)
    used = (t >= frames_uav.min()) & (t <= frames_uav.max()) & np.isfinite(alt + sigma_v)
    span = np.clip(
        np.searchsorted(tel.uav_time(knots), t[used], side="right") - 1, 0, len(knots) - 2
    )
    counts = np.bincount(span, minlength=len(knots) - 1)
    if np.any(counts == 0):
        return barometer
    apart = np.interp(t[used], frames_uav, poses.height_m) - alt[used]
    means = np.bincount(span, weights=apart) / counts
    moved = float(np.sqrt(np.mean((means - means.mean()) ** 2)))
    slow = np.sqrt(1.0 - GNSS_WHITE**2) * float(np.median(sigma_v[used]))
    change = np.hypot(moved, centred_wander_m(slow, GNSS_TAU_S, knots))
    return min(barometer, change / centred_wander_m(1.0, sigmas.baro_wander_s, knots))


def centred_wander_m(sigma_m: float, tau_s: float, knots_s: np.ndarray) -> float:
    """The RMS over the knots ``knots_s`` of a first-order Gauss-Markov process (1-sigma ``sigma_m``, correlation
    time ``tau_s``) about its mean over them (:func:`localizer.bottom.height_wander_cov_m2`)."""
    priors = bottom.Priors(height_wander_m=sigma_m, height_wander_s=tau_s)
    return float(np.sqrt(np.mean(np.diagonal(bottom.height_wander_cov_m2(priors, knots_s)))))


def held_walk_error_m(
    free: bottom.BottomEstimate, held: bottom.BottomEstimate, sigmas, tilt: bool, yaw: bool
) -> np.ndarray:
    """(2J, 4): what the walk ``held`` (fitted again with the parts not applied held at 0) does not know of, as
    :meth:`localizer.bottom.BottomEstimate.with_walk_error` takes it: the tilt_fwd, tilt_right and yaw errors that
    move it as they move the ``free`` fit's walk (:attr:`~localizer.bottom.BottomEstimate.walk_per_bias_m`), a part
    held as wrong as the calibration says (``[uncertainty] tilt_deg``, ``yaw_deg``, what h_acc takes for it), one
    applied by its sigma with the parts' spread (the fit's own share counted twice: never surer); and how far it
    is from the free fit's walk (holding a part at 0 moves the floor's depth and the walk with it)."""
    sigma_rad = np.array(
        [
            *(
                np.sqrt(np.diagonal(free.cov_bias)[:2])
                if tilt
                else np.radians([sigmas.tilt_deg] * 2)
            ),
            free.sigma_yaw_rad if yaw else np.radians(sigmas.yaw_deg),
        ]
    )
    moved = (held.walk_ne_m - free.walk_ne_m).reshape(-1, 1)
    return np.column_stack([free.walk_per_bias_m * sigma_rad, moved])


def walk_rates_m(gnss_rate_m: float) -> tuple[float, ...]:
    """The walk rates (m/√s) the recording chooses from (:attr:`localizer.bottom.Priors.walk_rates_m`): from
    :data:`MIN_WALK_RATE_M` to the GNSS's own (a velocity's integral no worse than the position), geometric, about
    :data:`WALK_RATES_PER_DECADE` a decade."""
    top = max(gnss_rate_m, MIN_WALK_RATE_M)
    n = max(2, int(np.ceil(np.log10(top / MIN_WALK_RATE_M) * WALK_RATES_PER_DECADE)) + 1)
    return tuple(float(r) for r in np.geomspace(MIN_WALK_RATE_M, top, n))


def applicable(est: bottom.BottomEstimate, cal: Calibration) -> tuple[bool, bool]:
    """Whether the tilt and the heading may be applied: the bottom told each (not the prior) and its sigma (with the
    parts' spread) is within the calibration's own for it (``[uncertainty] tilt_deg``, ``yaw_deg``)."""
    return (
        est.tilt_estimated and np.degrees(est.sigma_tilt_rad) <= cal.sigmas.tilt_deg,
        est.yaw_estimated and np.degrees(est.sigma_yaw_rad) <= cal.sigmas.yaw_deg,
    )


def pixels_at(t_frames, t, u, v):
    """The UUV's pixel at each frame time (NaN where none is within half a frame period)."""
    t_frames, t = np.asarray(t_frames, float), np.asarray(t, float)
    if len(t) == 0:
        return np.full(len(t_frames), np.nan), np.full(len(t_frames), np.nan)
    i = np.clip(np.searchsorted(t, t_frames), 1, max(1, len(t) - 1))
    i = np.where(
        (i > 0) & (np.abs(t[i - 1] - t_frames) < np.abs(t[np.minimum(i, len(t) - 1)] - t_frames)),
        i - 1,
        np.minimum(i, len(t) - 1),
    )
    period = float(np.median(np.diff(t_frames))) if len(t_frames) > 1 else np.inf
    near = np.abs(t[i] - t_frames) <= 0.5 * period
    return np.where(near, np.asarray(u, float)[i], np.nan), np.where(
        near, np.asarray(v, float)[i], np.nan
    )


def append_columns(path: Path, cells: dict[str, list[str]]) -> None:
    """Add columns at the end of a positions.csv (rewritten atomically: a temporary file, then renamed)."""
    path = Path(path)
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    tmp = path.with_name(path.name + ".partial")
    with open(tmp, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(rows[0] + list(cells))
        for i, row in enumerate(rows[1:]):
            w.writerow(row + [cells[c][i] for c in cells])
    os.replace(tmp, path)

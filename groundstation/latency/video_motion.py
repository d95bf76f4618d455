"""The camera's rotation between consecutive frames, measured in the image.

Corners of the scene's texture (seafloor, waves) are tracked from one frame to
the next (pyramidal Lucas–Kanade on a reduced grey image, kept only when the
backward track returns to the start; new corners are found when too few are
left), turned into rays through the calibrated
camera (distortion removed), and the rotation that best maps the first frame's
rays onto the second's is fitted (Kabsch), twice: the second time without the
tracks the first fit explains worst (the UUV, glints). Over one frame interval
the UAV moves centimetres at tens of metres' range, so the rotation is the
image's motion.

:class:`MotionThread` runs a :class:`RotationMeter` in a thread of its own, beside the caller's work: OpenCV
releases the interpreter lock while it resizes and tracks the corners, so on a second core the motion costs the
caller's loop little. It measures every frame, or every :func:`measured_every`-th: offline, a recording long
enough that each of its thirds (:func:`groundstation.latency.estimate.offset_from_rotations`) keeps
:data:`PAIRS_PER_THIRD` pairs is measured at most :data:`OFFLINE_HZ` a second, as live
(:data:`groundstation.latency.estimate.MEASURE_HZ`): a pair three frames apart turns three times as far as a pair
of neighbours, so a third of the pairs tells the offset about as well, for a third of the CPU
(``bench/profile_stages.py``: the biggest stage of ``skyfix process`` after decoding).
"""

from __future__ import annotations

import queue
import threading
from dataclasses import dataclass

import cv2
import numpy as np

from localizer.camera import Camera, pixel_to_ray

WIDTH_PX = 480  # frames are reduced to this width to find and track corners
MIN_TRACKS = 12
MAX_CORNERS = 60
REDETECT_BELOW = 30  # tracked corners left before new ones are found
LK_WINDOW_PX = 15  # Lucas-Kanade's window (on the reduced image) ...
LK_LEVELS = 3  # ... and its pyramid's levels above the image
OFFLINE_HZ = 10.0  # offline, frames measured at most this often (live's rate) ...
PAIRS_PER_THIRD = 120  # ... while each third of the recording keeps this many frame pairs (twice a sure estimate's)


@dataclass(frozen=True)
class Rotation:
    """The camera's rotation from the frame at ``t0`` to the frame at ``t1`` (any clock, s)."""

    t0: float
    t1: float
    rotvec: np.ndarray  # (3,) rotation vector of R_cv1_from_cv0, radians
    tracks: int


def kabsch(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The rotation R (3×3) minimising Σ|b_i − R a_i|² for unit vectors a, b (N×3)."""
    u, _, vt = np.linalg.svd(a.T @ b)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    return vt.T @ np.diag([1.0, 1.0, d]) @ u.T


def rotvec(r: np.ndarray) -> np.ndarray:
    """The rotation vector of a rotation matrix (radians)."""
    v, _ = cv2.Rodrigues(r)
    return v.ravel()


class RotationMeter:
    """Feed frames in order; each after the first gives the :class:`Rotation` from the one before (or None)."""

    def __init__(self, camera: Camera):
        self.camera = camera
        self.scale = min(1.0, WIDTH_PX / camera.width)
        self._prev: tuple[float, np.ndarray] | None = None
        self._points: np.ndarray | None = None  # corners tracked into the previous frame

    def measure(self, t: float, image: np.ndarray) -> Rotation | None:
        small = cv2.resize(image, None, fx=self.scale, fy=self.scale, interpolation=cv2.INTER_AREA)
        gray = cv2.cvtColor(small, cv2.COLOR_BGR2GRAY) if small.ndim == 3 else small
        prev, self._prev = self._prev, (t, gray)
        p0, self._points = self._points, None
        if prev is None:
            return None
        t0, gray0 = prev
        if (
            p0 is None or len(p0) < REDETECT_BELOW
        ):  # corners are found again only when too few are left
            p0 = cv2.goodFeaturesToTrack(
                gray0, maxCorners=MAX_CORNERS, qualityLevel=0.01, minDistance=8, blockSize=7
            )
        if p0 is None or len(p0) < MIN_TRACKS:
            return None
        lk = {"winSize": (LK_WINDOW_PX, LK_WINDOW_PX), "maxLevel": LK_LEVELS}
        p1, ok1, _ = cv2.calcOpticalFlowPyrLK(gray0, gray, p0, None, **lk)
        back, ok2, _ = cv2.calcOpticalFlowPyrLK(gray, gray0, p1, None, **lk)
        good = (
            (ok1.ravel() == 1)
            & (ok2.ravel() == 1)
            & (np.linalg.norm((back - p0).reshape(-1, 2), axis=1) < 0.3)
        )
        self._points = p1[good]
        if good.sum() < MIN_TRACKS:
            return None
        a = self._rays(p0.reshape(-1, 2)[good])
        b = self._rays(p1.reshape(-1, 2)[good])
        r = kabsch(a, b)
        err = np.linalg.norm(b - a @ r.T, axis=1)
        keep = err <= max(3.0 * np.median(err), 1e-9)
        if keep.sum() >= MIN_TRACKS:
            r = kabsch(a[keep], b[keep])
        return Rotation(t0, t, rotvec(r), int(keep.sum()))

    def _rays(self, px_small: np.ndarray) -> np.ndarray:
        px = (px_small + 0.5) / self.scale - 0.5  # pixel centres back in full resolution
        rays = np.asarray(pixel_to_ray(self.camera, px[:, 0], px[:, 1]), dtype=float)
        return rays / np.linalg.norm(rays, axis=1, keepdims=True)


def measured_every(frames: int, period_s: float) -> int:
    """Offline: the motion of a recording of ``frames`` frames ``period_s`` apart (s) is measured in every this
    many-th frame: at most :data:`OFFLINE_HZ` a second, while each third keeps :data:`PAIRS_PER_THIRD` pairs."""
    if not 0.0 < period_s < float("inf"):
        return 1
    fastest = max(1, round(1.0 / (OFFLINE_HZ * period_s)))
    return max(1, min(fastest, (frames - 1) // (3 * PAIRS_PER_THIRD)))


class MotionThread:
    """A :class:`RotationMeter` in a background thread: :meth:`feed` the frames in order (it waits while ``depth``
    frames are not measured yet), :meth:`finish` for the rotations, the same and in the same order as measured in
    the caller's thread (each frame waiting holds its decoded frame, 12 MB at 4K: ``bench/offline_speed.py``'s 4K
    peak RSS grew 579 -> 713 MB with 8, so the default is smaller). An error of the meter is raised by :meth:`finish`; :meth:`close` stops the thread (any
    time; after :meth:`finish` nothing to do). The images fed must not change until measured. ``every``: only the
    first of every this many frames fed is measured (:func:`measured_every`); the others are dropped at once."""

    def __init__(self, camera: Camera, depth: int = 4, every: int = 1):
        self.meter = RotationMeter(camera)
        self.every = every
        self._fed = 0
        self.rotations: list[Rotation] = []
        self._queue: queue.Queue = queue.Queue(maxsize=depth)
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="video-motion", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while (item := self._queue.get()) is not None:
            if self._error is not None:
                continue  # failed: drain until the end, so feed never waits forever
            try:
                if (r := self.meter.measure(*item)) is not None:
                    self.rotations.append(r)
            except BaseException as e:  # noqa: BLE001 - raised again in the caller's thread by finish
                self._error = e

    def feed(self, t: float, image: np.ndarray) -> None:
        """The next frame (time in any clock, s; grey or BGR image)."""
        self._fed += 1
        if (self._fed - 1) % self.every == 0:
            self._queue.put((t, image))

    def close(self) -> None:
        if self._thread.is_alive():
            self._queue.put(None)
            self._thread.join()

    def finish(self) -> list[Rotation]:
        """Every frame fed measured: the rotations between consecutive frames (see :meth:`RotationMeter.measure`)."""
        self.close()
        if self._error is not None:
            raise self._error
        return self.rotations

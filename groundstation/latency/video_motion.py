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
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from localizer.camera import Camera, pixel_to_ray

WIDTH_PX = 480  # frames are reduced to this width to find and track corners
MIN_TRACKS = 12
MAX_CORNERS = 150
REDETECT_BELOW = 80  # tracked corners left before new ones are found


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
        lk = {"winSize": (21, 21), "maxLevel": 3}
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

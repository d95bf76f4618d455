"""OpenCV's trackers as backends: MIL (the paper's baseline), KCF and CSRT.

They see pixels only and ignore the prediction. Their loss signal is OpenCV's:
``update`` returning False (KCF below ``detect_thresh``, CSRT below
``psr_threshold``); MIL has none and reports ``ok`` even after drifting away.
MIL is random: the seed is set at ``init`` so runs repeat.
"""

from __future__ import annotations

import cv2
import numpy as np

from . import Prediction, TrackResult

MIL_SEED = 1


def check_box(frame: np.ndarray, box) -> tuple[int, int, int, int]:
    """The box as ints, or ValueError naming it if it does not lie inside the frame."""
    h, w = frame.shape[:2]
    x, y, bw, bh = (round(c) for c in box)
    if bw < 2 or bh < 2 or x < 0 or y < 0 or x + bw > w or y + bh > h:
        raise ValueError(f"init box {tuple(box)!r} does not lie inside the {w}x{h} frame")
    return x, y, bw, bh


def _create(name: str):
    if name == "mil":
        return cv2.TrackerMIL_create()
    if name == "kcf":
        p = cv2.TrackerKCF_Params()
        p.detect_thresh = 0.2  # facts.md: 0.5 loses targets, 0.2 holds them
        return cv2.TrackerKCF_create(p)
    if name == "csrt":
        return cv2.TrackerCSRT_create()
    raise ValueError(f"tracker = {name!r}: not an OpenCV backend")


class OpenCVTracker:
    """``mil``, ``kcf`` or ``csrt``; the UUV's pixel keeps its init offset from the box centre."""

    def __init__(self, name: str):
        self.name = name
        self._tracker = _create(name)
        self._ready = False

    def init(self, frame_bgr, box, prediction: Prediction | None = None, point=None) -> None:
        box = check_box(frame_bgr, box)
        x, y, w, h = box
        centre = (x + (w - 1) / 2.0, y + (h - 1) / 2.0)
        self._offset = (0.0, 0.0) if point is None else (point[0] - centre[0], point[1] - centre[1])
        if self.name == "mil":
            cv2.setRNGSeed(MIL_SEED)
        self._tracker.init(frame_bgr, box)
        self._ready = True

    def update(self, frame_bgr, prediction: Prediction | None = None) -> TrackResult:
        if not self._ready:  # OpenCV's update() before init() crashes the process
            return TrackResult("not_initialized")
        ok, box = self._tracker.update(frame_bgr)
        if not ok:
            return TrackResult("lost")
        x, y, w, h = (int(c) for c in box)
        # pixel centres: a box [x, x + w) spans pixel centres x … x + w − 1
        u, v = x + (w - 1) / 2.0 + self._offset[0], y + (h - 1) / 2.0 + self._offset[1]
        return TrackResult("ok", u, v, (x, y, w, h), float("nan"))

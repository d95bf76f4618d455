"""OpenCV's trackers as matchers: MIL (the paper's baseline), KCF and CSRT.

They see pixels only and ignore the prediction; ``follow``, ``search`` and
``confirm`` are each one OpenCV ``update`` (which searches near its last box).
Their loss signal is OpenCV's: ``update`` returning False (KCF below
``detect_thresh``, CSRT below ``psr_threshold``); MIL has none and reports a
match even after drifting away. A candidate confirms when it lies within
``CONFIRM_TOLERANCE`` box sides of where it is expected. MIL is random: the seed
is set at ``start`` so runs repeat.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from . import Match, Prediction

MIL_SEED = 1
# a confirmed candidate lies this close (in box sides) to where it is expected
CONFIRM_TOLERANCE = 0.3


def check_box(frame: np.ndarray, box) -> tuple[int, int, int, int]:
    """The box as ints, or ValueError naming it if it does not lie inside the frame."""
    h, w = frame.shape[:2]
    x, y, bw, bh = (round(c) for c in box)
    if bw < 2 or bh < 2 or x < 0 or y < 0 or x + bw > w or y + bh > h:
        raise ValueError(f"box {tuple(box)!r} does not lie inside the {w}x{h} frame")
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


class OpenCVMatcher:
    """``mil``, ``kcf`` or ``csrt``; the UUV's pixel keeps its start offset from the box centre."""

    def __init__(self, name: str):
        self.name = name
        self._tracker = _create(name)

    def start(self, frame_bgr, box, point=None, px_per_m: float = float("nan")) -> None:
        box = check_box(frame_bgr, box)
        x, y, w, h = box
        centre = (x + (w - 1) / 2.0, y + (h - 1) / 2.0)
        self._offset = (0.0, 0.0) if point is None else (point[0] - centre[0], point[1] - centre[1])
        if self.name == "mil":
            cv2.setRNGSeed(MIL_SEED)
        # OpenCV's update() before init() would crash the process
        self._tracker.init(frame_bgr, box)

    def follow(self, frame_bgr, prediction: Prediction | None = None) -> Match:
        ok, box = self._tracker.update(frame_bgr)
        if not ok:
            return Match(False, float("nan"))
        x, y, w, h = (int(c) for c in box)
        # pixel centres: a box [x, x + w) spans pixel centres x … x + w − 1
        u, v = x + (w - 1) / 2.0 + self._offset[0], y + (h - 1) / 2.0 + self._offset[1]
        return Match(True, float("nan"), u, v, (x, y, w, h))

    search = follow

    def confirm(self, frame_bgr, u: float, v: float, prediction: Prediction | None = None) -> Match:
        m = self.follow(frame_bgr, prediction)
        near = m.found and math.hypot(m.u - u, m.v - v) <= CONFIRM_TOLERANCE * max(
            m.box[2], m.box[3]
        )
        return m if near else Match(False, m.score, m.u, m.v)

    def waves(self) -> float:
        """No reading of the sea state (see :class:`~localizer.tracking.Matcher`)."""
        return 0.0

    def resume(self, match: Match) -> None:
        pass

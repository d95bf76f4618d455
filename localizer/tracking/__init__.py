"""Tracking the UUV in video frames: a frame in; box, pixel, confidence and status out.

Interface shared by every backend (see ``make_tracker``)::

    tracker = make_tracker("default", calibration)
    tracker.init(frame_bgr, (x, y, w, h), prediction, point)
    result = tracker.update(frame_bgr, prediction)   # prediction: Prediction | None
    result.status   # "ok", "lost", ...; result.u, result.v: the UUV's distorted pixel

``prediction`` carries what the telemetry says about where the UUV should be
(pixel, expected size and uncertainty in pixels; see :mod:`.predict`); backends
may ignore it. Status words: ``ok``; ``lost`` (the target is not where it should
be and has not been found again yet); ``not_initialized``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np


@dataclass(frozen=True)
class Prediction:
    """Where the telemetry expects the UUV: distorted pixel and apparent size (pixels)."""

    u: float
    v: float
    width_px: float
    height_px: float
    sigma_px: float = float("nan")  # 1-sigma uncertainty of (u, v); NaN: unknown
    px_per_m: float = float("nan")  # image scale at the UUV (pixels per metre); NaN: unknown


@dataclass(frozen=True)
class TrackResult:
    """One frame's tracking result."""

    status: str  # "ok" or why not: "lost", "not_initialized"
    u: float = float("nan")  # the UUV's centre, distorted pixels
    v: float = float("nan")
    box: tuple[int, int, int, int] | None = None  # x, y, w, h
    confidence: float = float("nan")  # 0..1

    @property
    def ok(self) -> bool:
        return self.status == "ok"


class Tracker(Protocol):
    """A tracking backend: ``init`` once with the UUV's box, then ``update`` every frame."""

    def init(
        self, frame_bgr: np.ndarray, box: tuple[int, int, int, int], prediction: Prediction | None = None,
        point: tuple[float, float] | None = None,
    ) -> None:
        """Start on the UUV inside ``box`` (x, y, w, h); ``point``: the pixel to report (default the box centre)."""

    def update(self, frame_bgr: np.ndarray, prediction: Prediction | None = None) -> TrackResult:
        """Track into the next frame; never ``ok`` unless the UUV was found."""


TRACKERS = ("default", "ncc", "mil", "kcf", "csrt")  # "default" is "ncc"


def make_tracker(name: str, calibration=None) -> Tracker:
    """A new tracker by backend name (one of :data:`TRACKERS`); raises ValueError for others."""
    if name in ("default", "ncc"):
        from .template import TemplateTracker

        return TemplateTracker()
    if name in ("mil", "kcf", "csrt"):
        from .opencv import OpenCVTracker

        return OpenCVTracker(name)
    raise ValueError(f"tracker = {name!r}: unknown (known: {', '.join(TRACKERS)})")

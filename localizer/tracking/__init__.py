"""Tracking the UUV in video frames: a frame in; box, pixel, confidence and status out.

Interface shared by every backend (see ``make_tracker``)::

    tracker = make_tracker("default", calibration)
    tracker.init(frame_bgr, (x, y, w, h))
    result = tracker.update(frame_bgr, prediction)   # prediction: Prediction | None
    result.status   # "ok", "lost", ...; result.u, result.v: the UUV's distorted pixel

``prediction`` carries what the telemetry says about where the UUV should be
(pixel and expected size in pixels); backends may ignore it.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Prediction:
    """Where the telemetry expects the UUV: distorted pixel and apparent size (pixels)."""

    u: float
    v: float
    width_px: float
    height_px: float


@dataclass(frozen=True)
class TrackResult:
    """One frame's tracking result."""

    status: str  # "ok" or why not: "lost", "searching", "not_initialized"
    u: float = float("nan")  # the UUV's centre, distorted pixels
    v: float = float("nan")
    box: tuple[int, int, int, int] | None = None  # x, y, w, h
    confidence: float = float("nan")  # 0..1

    @property
    def ok(self) -> bool:
        return self.status == "ok"

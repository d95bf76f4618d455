"""Tracking the UUV in video frames: a target's life from selection to release.

Layers, each usable alone:

- A *matcher* (:class:`Matcher`, see ``make_matcher``) is an appearance model: started
  on the UUV's box in one frame, it says where the UUV is in the next
  (``follow``), looks for it anywhere the telemetry allows (``search``) and checks
  a candidate again (``confirm``). ``ncc`` (the default, :mod:`.template`), and
  OpenCV's ``mil`` (the paper's), ``kcf``, ``csrt`` (:mod:`.opencv`).
- :class:`~.target.Target` is the state machine in the image: awaiting a target,
  tracking, lost, confirming a candidate, released (:class:`~.target.TargetState`).
- :class:`~.session.TrackingSession` adds the telemetry: each frame's
  :class:`~localizer.pose.CameraPose` gives the prediction (:mod:`.predict`), the
  vehicle's size for a click, and the UUV's own position estimate becomes a place to
  search without any template (:mod:`.detect`). ``skyfix process``, ``skyfix run`` and
  the operator's commands all drive a ``TrackingSession``.

``prediction`` (:class:`Prediction`) carries what the telemetry says about where the
UUV should be: pixel, expected size and uncertainty in pixels; matchers may ignore it.
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
    # how far its heading may have turned since it was last seen (deg); NaN: any
    turn_deg: float = float("nan")


@dataclass(frozen=True)
class TrackResult:
    """One frame's tracking result."""

    status: str  # "ok" or why not: "lost", "awaiting_target", "released"
    u: float = float("nan")  # the UUV's centre, distorted pixels
    v: float = float("nan")
    box: tuple[int, int, int, int] | None = None  # x, y, w, h
    # 0..1; while lost or acquiring, the best candidate's score when one was sought
    confidence: float = float("nan")
    # 1-sigma of each of u and v (pixels) when ok (:mod:`.sigma`); NaN: unknown
    sigma_px: float = float("nan")

    @property
    def ok(self) -> bool:
        return self.status == "ok"


@dataclass(frozen=True)
class Match:
    """A matcher's answer for one frame: the best place found and whether it passes for the UUV."""

    found: bool
    score: float = -1.0  # the matcher's similarity (NCC for ``ncc``; NaN when it has none)
    u: float = float("nan")  # the tracked point (the UUV's reference pixel), distorted pixels
    v: float = float("nan")
    box: tuple[int, int, int, int] | None = None  # x, y, w, h around the UUV
    held: bool = False  # not found, but still followed: a frame where waves hide it for a moment, not yet a loss


class Matcher(Protocol):
    """An appearance model of the UUV, started on a box; each frame exactly one of follow/search/confirm."""

    def start(
        self,
        frame_bgr: np.ndarray,
        box: tuple[int, int, int, int],
        point: tuple[float, float] | None = None,
        px_per_m: float = float("nan"),
    ) -> None:
        """Learn the UUV inside ``box`` (x, y, w, h); ``point``: the pixel to report (default the box centre);
        ``px_per_m``: the image scale there (NaN: unknown, the first prediction's is taken). ValueError for a box
        outside the frame."""

    def follow(self, frame_bgr: np.ndarray, prediction: Prediction | None) -> Match:
        """While tracking: the UUV near the prediction (or its last place); ``found`` False when it is not there."""

    def search(self, frame_bgr: np.ndarray, prediction: Prediction | None) -> Match:
        """While lost: the best candidate anywhere the prediction allows (the whole frame without one)."""

    def confirm(
        self, frame_bgr: np.ndarray, u: float, v: float, prediction: Prediction | None
    ) -> Match:
        """The candidate again, expected at (u, v) (its last place moved as the camera moved)."""

    def resume(self, match: Match) -> None:
        """Tracking again from a confirmed candidate."""

    def waves(self) -> float:
        """How far its matches wobble as through wind waves: 0 (a still surface, or a matcher that cannot tell) to 1."""


TRACKERS = ("default", "ncc", "mil", "kcf", "csrt")  # "default" is "ncc"
#: Backends that never report a loss (OpenCV's MIL reports a match even after drifting off the UUV): fine offline
#: and as a baseline, never a position source for the UUV's autopilot (``skyfix run --gps-input`` refuses them).
#: KCF and CSRT report one (``update`` False below their detection and PSR thresholds).
WITHOUT_LOSS_SIGNAL = ("mil",)
#: Backends that read the frames' grey levels alone, and from a grey frame (H, W) as from a BGR one: a video's luma
#: plane serves them without a conversion (normalized cross-correlation and contrasts relative to the first
#: appearance's do not change with the levels' offset and gain).
GREY_TRACKERS = ("default", "ncc")


def make_matcher(name: str) -> Matcher:
    """A new matcher by backend name (one of :data:`TRACKERS`); raises ValueError for others."""
    if name in ("default", "ncc"):
        from .template import TemplateMatcher

        return TemplateMatcher()
    if name in ("mil", "kcf", "csrt"):
        from .opencv import OpenCVMatcher

        return OpenCVMatcher(name)
    raise ValueError(f"tracker = {name!r}: unknown (known: {', '.join(TRACKERS)})")

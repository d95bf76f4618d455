"""A target's life in the image: selected, tracked, lost, confirmed again, released.

:class:`Target` is the state machine over one :class:`~localizer.tracking.Matcher`;
frames come with the telemetry's :class:`~localizer.tracking.Prediction` (or None).
States (:class:`TargetState`) and what moves between them:

- ``AWAITING_TARGET``: nothing to track yet (start, or after :meth:`Target.acquire`).
  :meth:`Target.select` (the operator's box) starts tracking at once;
  :meth:`Target.propose` (a candidate found without a template, e.g. near the UUV's
  own position estimate) starts the matcher on it and goes to ``CONFIRMING``.
- ``TRACKING``: each frame the matcher follows the UUV; when it is not where it
  should be, the target is ``LOST`` (unless the matcher holds on: a frame's match
  under waves, :attr:`~localizer.tracking.Match.held`; that frame is ``lost``).
- ``LOST``: the matcher searches for it every ``search_every`` frames (every
  ``search_every_long`` once lost ``long_loss_frames``); a candidate goes to ``CONFIRMING``.
- ``CONFIRMING``: the candidate must be matched again in ``confirm_frames`` consecutive
  frames (the first included), each where the previous one moved as the prediction moved
  (the camera's motion), so a hidden UUV is not replaced by a look-alike patch of
  seafloor; then ``TRACKING``. A failed confirmation goes back where the candidate came
  from (``LOST``, or ``AWAITING_TARGET`` with the matcher dropped).
- ``RELEASED``: the operator let go (:meth:`Target.release`); nothing is tracked until
  a new selection or :meth:`Target.acquire`.

Per-frame status words (:class:`~localizer.tracking.TrackResult`): ``ok`` only while
``TRACKING`` and found; ``lost`` while lost or confirming a re-acquisition;
``awaiting_target`` while awaiting or confirming a first acquisition; ``released``.
"""

from __future__ import annotations

import copy
import enum
import math
from collections.abc import Callable
from dataclasses import dataclass

from . import Match, Matcher, Prediction, TrackResult


class TargetState(enum.StrEnum):
    AWAITING_TARGET = "awaiting_target"
    TRACKING = "tracking"
    LOST = "lost"
    CONFIRMING = "confirming"
    RELEASED = "released"


@dataclass(frozen=True)
class TargetParams:
    confirm_frames: int = 3  # consecutive matches of a candidate before tracking (re)starts
    search_every: int = 2  # while lost with no candidate, search every this many frames...
    long_loss_frames: int = 60  # ... and once lost this many frames (2 s at 30 fps), ...
    search_every_long: int = 6  # ... every this many


class Target:
    """One UUV's life in the image (see the module doc); ``make_matcher()`` gives a fresh matcher per start."""

    def __init__(self, make_matcher: Callable[[], Matcher], params: TargetParams | None = None):
        self.p = params or TargetParams()
        self._make_matcher = make_matcher
        self.state = TargetState.AWAITING_TARGET
        self._matcher: Matcher | None = None
        self._origin = TargetState.AWAITING_TARGET  # where a candidate being confirmed came from
        self._hits: list[tuple[float, float, float, float]] = []  # u, v, predicted u, v
        self._lost_frames = 0
        # the latest frame's match when the matcher held it (:attr:`~localizer.tracking.Match.held`; None otherwise)
        self.held: Match | None = None

    # -- commands ------------------------------------------------------------------------------
    def select(self, frame_bgr, box, point=None, px_per_m: float = float("nan")) -> TrackResult:
        """Track the UUV inside ``box`` (x, y, w, h) from this frame on; ValueError (state unchanged) for a bad box."""
        matcher = self._make_matcher()
        matcher.start(frame_bgr, box, point, px_per_m)
        self._matcher, self._hits = matcher, []
        self.state = TargetState.TRACKING
        x, y, w, h = box
        u, v = point if point is not None else (x + (w - 1) / 2.0, y + (h - 1) / 2.0)
        return TrackResult("ok", u, v, tuple(round(c) for c in box), 1.0)

    def propose(
        self,
        frame_bgr,
        box,
        point,
        px_per_m: float,
        prediction: Prediction | None,
        score: float = float("nan"),
    ) -> TrackResult:
        """A candidate found in this frame while awaiting a target: the matcher starts on it, to be confirmed."""
        matcher = self._make_matcher()
        matcher.start(frame_bgr, box, point, px_per_m)
        self._matcher = matcher
        self._origin = TargetState.AWAITING_TARGET
        self._hits = [(point[0], point[1], *_centre(prediction))]
        return self._candidate_seen(Match(True, score, point[0], point[1], box))

    def release(self) -> None:
        self._matcher, self._hits = None, []
        self.state = TargetState.RELEASED

    def acquire(self) -> None:
        """Await a target again (a selection, or a candidate to :meth:`propose`)."""
        self._matcher, self._hits = None, []
        self.state = TargetState.AWAITING_TARGET

    @property
    def waves(self) -> float:
        """How far the matches wobble as through wind waves, 0 to 1 (:meth:`~localizer.tracking.Matcher.waves`; 0
        without a matcher)."""
        return self._matcher.waves() if self._matcher is not None else 0.0

    @property
    def distinct(self) -> float:
        """Through waves, how much the UUV followed in the latest frame stands out of the seafloor beside it (the
        matcher's ``distinct``, as :class:`~localizer.tracking.template.TemplateMatcher` reads it); NaN otherwise."""
        return getattr(self._matcher, "distinct", math.nan)

    def adopt(self, other: Target, found: TrackResult) -> None:
        """Track on with a copy of ``other``'s matcher (what it learnt of the UUV), from ``found``: the UUV as
        ``other`` found it in this frame."""
        self._matcher, self._hits = copy.deepcopy(other._matcher), []
        self._matcher.resume(Match(True, found.confidence, found.u, found.v, found.box))
        self.state = TargetState.TRACKING

    # -- per frame -------------------------------------------------------------------------------
    def update(self, frame_bgr, prediction: Prediction | None) -> TrackResult:
        """The UUV in the next frame (see the module doc for the states)."""
        self.held = None
        if self.state is TargetState.TRACKING:
            m = self._matcher.follow(frame_bgr, prediction)
            if m.found:
                return TrackResult("ok", m.u, m.v, m.box, _confidence(m.score))
            if m.held:
                self.held = m
                return TrackResult("lost", confidence=_confidence(m.score))
            self.state = TargetState.LOST
            self._lost_frames = -1  # search on the next frame, then every search_every frames
            return TrackResult("lost", confidence=_confidence(m.score))
        if self.state is TargetState.LOST:
            self._lost_frames += 1
            long_loss = self._lost_frames >= self.p.long_loss_frames
            if self._lost_frames % (self.p.search_every_long if long_loss else self.p.search_every):
                return TrackResult("lost")
            m = self._matcher.search(frame_bgr, prediction)
            if not m.found:
                return TrackResult("lost", confidence=_confidence(m.score))
            self._origin = TargetState.LOST
            self._hits = [(m.u, m.v, *_centre(prediction))]
            return self._candidate_seen(m)
        if self.state is TargetState.CONFIRMING:
            pu, pv = _centre(prediction)
            lu, lv, lpu, lpv = self._hits[-1]
            m = self._matcher.confirm(frame_bgr, lu + pu - lpu, lv + pv - lpv, prediction)
            if not m.found:
                status = self._status()
                self._hits = []
                if self._origin is TargetState.AWAITING_TARGET:
                    self.acquire()
                else:
                    self.state = TargetState.LOST
                return TrackResult(status, confidence=_confidence(m.score))
            self._hits.append((m.u, m.v, pu, pv))
            return self._candidate_seen(m)
        return TrackResult(self._status())

    def _candidate_seen(self, m: Match) -> TrackResult:
        """A candidate matched once more: tracking once it has ``confirm_frames`` matches."""
        if len(self._hits) < self.p.confirm_frames:
            self.state = TargetState.CONFIRMING
            return TrackResult(self._status(), confidence=_confidence(m.score))
        self._hits = []
        self._matcher.resume(m)
        self.state = TargetState.TRACKING
        return TrackResult("ok", m.u, m.v, m.box, _confidence(m.score))

    def _status(self) -> str:
        """The status word of a frame without a fix in the current state."""
        if self.state is TargetState.CONFIRMING:
            return "awaiting_target" if self._origin is TargetState.AWAITING_TARGET else "lost"
        return "lost" if self.state is TargetState.LOST else self.state.value


def _centre(prediction: Prediction | None) -> tuple[float, float]:
    return (prediction.u, prediction.v) if prediction is not None else (0.0, 0.0)


def _confidence(score: float) -> float:
    return max(0.0, score) if math.isfinite(score) else float("nan")

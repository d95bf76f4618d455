"""One tracking session: a target's life with the telemetry, the same for ``process``, ``run`` and the operator.

:class:`TrackingSession` owns a :class:`~localizer.tracking.target.Target` (the
state machine in the image) and gives it, frame by frame, what the telemetry says.
Every call takes the frame's image and its :class:`~localizer.pose.CameraPose`
(``pose`` with the frame at index ``i``: a batch offline, one frame live), computed
once by the caller and shared with the geometry.

- :meth:`~TrackingSession.select`: the operator's box, or a click (the object
  outlined there by :func:`~localizer.tracking.detect.detect`, at the size the
  pose gives), on that frame; tracking starts there at once. The tracked pixel is
  the top face's centre (:func:`~localizer.tracking.predict.top_face_pixel`). With
  ``verify`` (the operator's live selections), a box must hold a vehicle-sized object
  standing out of the water, as a click must: a box on open water would otherwise be
  tracked as the seafloor's texture, and every fix would be wrong. The object's outline
  then replaces the drawn box: a box dragged by hand is pixels off the vehicle, and a
  tracker that never drifts toward the vehicle would keep that offset in every fix.
  With ``keep_drawn`` as well (a configured ``init_bbox``, drawn on a recorded frame), a
  box whose centre is within :data:`DRAWN_AGREES` outline errors of the outline's is kept
  as drawn (a box drawn on the frame is exact, an outline pixels off); one further off is
  snapped onto the outline. With ``steady`` as well (the live service's boxes), the box is
  checked over the frames of the next :data:`STEADY_S` instead of its own alone: followed
  from it (its frames ``awaiting_target``, the state ``CONFIRMING``, :attr:`~TrackingSession.check`
  ``"confirming"``), then taken when a vehicle-sized object stands out of the mean of its
  window's saliencies over them (:class:`~localizer.tracking.steady.SteadyWindow`; its floor
  :data:`STEADY_MIN_SALIENCY`), refused (awaiting a target) otherwise. Through wind waves one
  frame does not tell a small, deep UUV from the seafloor: the waves break the vehicle's image
  up and caustics on the seafloor stand out as much, while over a fraction of a second a
  caustic's flicker averages out and the vehicle's saliency stays. A box on the frame's edge
  (drawn, or the outline found for a click, a box or a prior) is refused: the vehicle may be
  cut off there, and a template of part of it puts every fix off its centre by up to half its
  length, which no claim carries.
- :meth:`~TrackingSession.step`: the next frame. Its prediction is the UUV's last
  sighting moved by what the camera did since: the sighting is located (an *anchor*,
  re-located every :data:`REANCHOR_FRAMES` frames), projected into this frame's
  pose, and shifted by the residual between the sighting's pixel and the anchor's
  projection there (:func:`~localizer.tracking.predict.follow`). A sighting in a
  frame without a pose has no residual: the last one with a pose stays the
  prediction's start, its uncertainty growing with its age. Projections are
  made for up to :data:`REANCHOR_FRAMES` frames of the pose batch at once.
  Through waves the UUV is looked for from the last sighting it stood out of the
  seafloor in (the matcher's ``distinct``, at least :data:`STOOD_OUT_DISTINCT`), when
  later ones did not and it is at most :data:`STOOD_OUT_WITHIN_S` older: a follow
  that slid onto a patch of seafloor beside a small, deep UUV does not drag the
  next frames' window (and a search's, once lost) onto that patch.
- The vehicle's colour: learnt on the first frame tracked from a selection, when it stands out of its
  surroundings in the chroma channels (:mod:`.colour`, from the ``chroma`` given with the frames); every later
  ``ok`` frame whose tracked place does not stand out in that colour is no fix (``lost``), the tracker following on
  as it would have. Through wind waves a follow can slide onto caustic-lit seafloor that matches the vehicle's grey
  levels: that place does not have its colour. Through waves (read for :data:`COLOUR_SEARCH_ROUGH_S`: a vehicle
  passing over the UUV makes the matches wobble for a moment too; or a configured wind of at least
  :data:`COLOUR_SEARCH_WIND_MPS`), after :data:`COLOUR_SEARCH_AFTER` frames in a row
  without it (or once lost), the window the UUV is sought in is searched for the vehicle's colour
  (:func:`.colour.find`) and tracking restarts where it stands out as when learnt, and nowhere else does
  (:meth:`TrackingSession._found_by_colour`). A restart the colour check refutes before it is proven
  (:data:`COLOUR_PROVEN_FRAMES`) is undone: the track goes back to what it was, the UUV sought from its last
  sighting (a place of the seafloor shows the vehicle's colour now and then as the waves play). A frame the matcher
  holds through waves (not yet a loss) is a fix at its best place when that is close to where the UUV was sought and
  the vehicle's colour stands out there (:data:`HELD_COLOUR_REACH`).
- While awaiting a target with a :class:`Prior` (the UUV's own position estimate),
  every ``search_every`` frames the prior is projected into the frame at the UUV's
  depth and the window its uncertainty spans is searched for a vehicle-sized object
  (:func:`~localizer.tracking.detect.detect`); a candidate is confirmed like a
  re-acquisition, moving as the camera moves, before any ``ok`` frame.
- :meth:`~TrackingSession.release` and :meth:`~TrackingSession.acquire`: let go; await
  a target again.

Pure: no I/O, no clock; a frame's time is its pose's ``t_unix``.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, replace

import numpy as np

from ..calibration import Calibration
from ..fix import locate
from ..pose import CameraPose, take
from . import Match, Prediction, TrackResult, make_matcher
from .colour import Chroma, ColourModel, find, learn, separation
from .detect import DetectParams, detect
from .predict import (
    BASE_SIGMA_M,
    VEHICLE_FOOTPRINT_M,
    follow,
    prediction_at,
    project_uuv,
    top_face_pixel,
)
from .predict import window as search_window
from .sigma import OUTLINED_SHARE, jitter2_px2, pixel_sigma_px
from .steady import SteadyWindow
from .target import Target, TargetParams, TargetState

#: A sighting's located position is reused for the predictions of this many frames, then located afresh.
REANCHOR_FRAMES = 64
#: A click asks for an object within this share of the vehicle's diagonal of it (the window's 3 sigma).
CLICK_REACH = 1.0
#: A drawn box kept (``keep_drawn``) when its centre is within this many outline errors
#: (:data:`~localizer.tracking.sigma.OUTLINED_SHARE` of the vehicle's length) of the outline's, per axis.
DRAWN_AGREES = 3.0
#: Through waves, a follow whose vehicle stands out of the seafloor less than this (the matcher's ``distinct``) does
#: not move where the next frames look for the UUV: the last sighting that stood out does ...
STOOD_OUT_DISTINCT = 0.95
#: ... while it is at most this much older than the latest sighting (s)
STOOD_OUT_WITHIN_S = 0.5
#: A box checked over frames (``select(..., steady=True)``) is followed this long (s) before it is taken or refused ...
STEADY_S = 0.3
#: ... in at least this share of the frames ...
STEADY_FOLLOWED = 0.5
#: ... and taken when the mean of its window's saliencies over them stands out this much (the one-frame
#: ``min_saliency``'s counterpart: a caustic's flicker averages down, a vehicle's saliency stays)
STEADY_MIN_SALIENCY = 18.0
#: The UUV's speed is measured over its sightings of the last this many seconds ...
SPEED_WINDOW_S = 0.5
#: ... at least this long apart ...
SPEED_SPAN_S = 0.2
#: ... and taken this much faster (m/s): the sightings' own scatter.
SPEED_MARGIN_MPS = 0.1
#: Through waves (the matcher's reading at least this), after this many frames in a row without the vehicle's
#: colour at the tracked place (or once lost), the window the UUV is sought in is searched for its colour (on a still
#: surface the grey-level tracker's own guards against look-alikes hold, a search by colour alone would jump to a
#: second vehicle of the same colour) ...
COLOUR_SEARCH_WAVES = 0.5
COLOUR_SEARCH_AFTER = 2
#: ... when the matcher has read that sea state for at least this long (s), and until it has read a calmer one as
#: long: waves last, while a vehicle passing over the UUV makes the matches wobble for a moment as waves would
#: (tests/test_tracking_lookalikes.py, crossing_close: the reading rose to 1 within 0.2 s of the pass, and a search
#: by colour then jumped to the passing vehicle), and a restart's new matcher reads a calm sea over its first frames
#: (before either has been read this long, the latest reading)
COLOUR_SEARCH_ROUGH_S = 1.0
#: ... or from the start when the configured wind (``[uncertainty] wind_mps``: the operator's word on the sea) is at
#: least this (m/s): the matcher reads the sea from its follows, and a small UUV lost through waves in its first
#: frames left a reading of too few follows (0.43 of a 5 m/s sea) that no later follow changed, so the UUV, standing out
#: in its colour at the prediction, was never sought by it (bench/results/tracker_waves_wind_s19.txt)
COLOUR_SEARCH_WIND_MPS = 2.0
#: ... and tracking restarts where it stands out at least this share of its separation when learnt, and at least
#: this much (ring spreads: the best of a window's places of seafloor reached 2.2 through waves in the renders it was
#: set on; while the UUV is hidden a few pass, as far as the UUV itself stands out when it is found again:
#: :data:`COLOUR_PROVEN_FRAMES` undoes those, bench/results/tracker_waves_colour_undo_s19.txt)
COLOUR_FOUND_SHARE = 0.5
COLOUR_FOUND_MIN = 3.0
#: A box checked over frames whose vehicle stands out of its surroundings in colour at least this much when drawn
#: (ring spreads: :func:`.colour.learn`; nearly every UUV box of the wave renders does, no seafloor box, the most
#: just under it: bench/results/box_check_colour_s17.txt) is also taken when its colour is found where it is
#: sought (:meth:`TrackingSession._colour_found`) in :data:`STEADY_FOLLOWED` of the check's frames, and is at the
#: tracked place in the frame the check ends on: through waves the matcher may lose a small, deep UUV in the check's
#: first frames, and the grey levels' mean then shows no vehicle where the colour does.
STEADY_COLOUR_MIN = 3.0
#: A restart by colour gives no fix until the vehicle's colour is at the tracked place on this many frames in a row
#: after it (a place of the seafloor that stands out in it once, as the waves play, rarely does twice more; a frame
#: the matcher held counts where the colour stands out there as a restart needs: :meth:`TrackingSession._held_coloured`,
#: bench/results/tracker_waves_held_confirms_s23.txt). The
#: restart's own frame is a fix when the restart is within :data:`HELD_COLOUR_REACH` of where the UUV was sought:
#: the evidence that makes a held frame one (bench/results/tracker_waves_restart_near_s21.txt).
COLOUR_CONFIRM_FRAMES = 2
#: ... and on this many when the restart is further than that from where the UUV was sought: such places of the
#: seafloor showed the vehicle's colour on the two frames after too, while the UUV was hidden and as it came back
#: beside them (bench/results/tracker_waves_confirm_far_s22.txt).
COLOUR_CONFIRM_FAR_FRAMES = 4
#: A frame the matcher held through waves (its best place under its bars, not yet a loss) is a fix at that place when
#: it is within this share of the vehicle's box of where the UUV was sought and the vehicle's colour stands out there
#: as a restart by colour needs it to (:data:`COLOUR_FOUND_SHARE`, :data:`COLOUR_FOUND_MIN`): the waves drag a small or
#: deep UUV's score under the bars for a few frames at a time while it is there. Further from where it was sought the
#: held place was more often beside the UUV, and with the colour check's own bar a held frame just after the UUV was
#: hidden was taken (bench/results/tracker_waves_held_s19.txt). A held place further off is no fix, but through waves
#: where the UUV was sought is when the colour stands out there so: the matcher held a place of the seafloor beside a
#: UUV whose colour stood out at the prediction (bench/results/tracker_waves_held_sought_s23.txt).
HELD_COLOUR_REACH = 0.2
#: A restart by colour is undone when, before its colour has been at the track on this many frames and within
#: :data:`COLOUR_PROVEN_S` of it, the colour check withholds :data:`COLOUR_SEARCH_AFTER` frames in a row and the
#: search by colour finds it nowhere in the window: the track goes back to what it was before (lost: the grey levels'
#: search from the last sighting). A place of the seafloor shows the vehicle's colour for a few frames now and then
#: as the waves play, and a track restarted there during an occlusion held that place and never found the UUV again
#: when it came back beside it; a small, deep UUV's own colour comes and goes for a frame or two, but a restart on
#: it has its colour on most frames (bench/results/tracker_waves_colour_undo_s19.txt).
COLOUR_PROVEN_FRAMES = 8
COLOUR_PROVEN_S = 1.0


@dataclass(frozen=True)
class Prior:
    """Where the UUV says it is (its own estimate, or an operator's hint): WGS84 degrees and a 1-sigma in metres."""

    lat: float
    lon: float
    sigma_m: float


class SelectionError(ValueError):
    """A selection that cannot be used; the message is one line naming the value."""


@dataclass
class _Sighting:
    """The last frame the UUV was seen in: its pixel, the anchor's projection there, that frame's pose."""

    t_unix: float
    u: float
    v: float
    pu: float  # NaN without an anchor
    pv: float
    # that frame's pose: frame ``i`` of ``poses`` (taken only when located: most sightings never are)
    poses: CameraPose
    i: int = 0

    def pose(self) -> CameraPose:
        """The one frame's pose."""
        return take(self.poses, [self.i])


class TrackingSession:
    """A target's life, frame by frame (see the module doc); ``tracker`` names the matcher (ValueError if unknown)."""

    def __init__(
        self,
        cal: Calibration,
        tracker: str = "default",
        target_params: TargetParams | None = None,
        detect_params: DetectParams | None = None,
    ):
        make_matcher(tracker)  # fail early on an unknown name
        self.cal = cal
        self.tracker = tracker
        self.target = Target(lambda: make_matcher(tracker), target_params)
        self.detect_params = detect_params or DetectParams()
        self.origin: str | None = None  # how the current target was chosen: "box", "click", "prior"
        self._outlined = False  # the target's box is an outline skyfix found (its pixel carries the outline's error)
        # the latest step's prediction: the last sighting moved by what the camera did since (None: none)
        self.prediction: Prediction | None = None
        # where the latest step looked for the UUV (None: nowhere in particular): the prediction, or through waves
        # the last sighting that stood out of the seafloor moved so (see the module doc)
        self.sought: Prediction | None = None
        self.last = TrackResult("awaiting_target")
        # the vehicle's apparent length at the latest prediction or selection
        self._length_px = math.nan
        # a box being checked over frames (``select(..., steady=True)``): see :meth:`_select_steady`
        self._steady: _Steady | None = None
        # how the latest box checked over frames was taken: "confirming", "kept", "snapped", "refused: <why>";
        # None: no such box since the latest selection, release or acquire
        self.check: str | None = None
        # the vehicle's colour, learnt on the first frame tracked from a selection (:mod:`.colour`; None: not learnt,
        # or it does not stand out in colour), and whether it is still to be learnt
        self._colour: ColourModel | None = None
        self._learn_colour = False
        # frames in a row the colour check withheld, the frames a restart by colour still needs it on in a row
        # before a fix, and the last box it passed (w, h)
        self._vetoed = self._unconfirmed = 0
        self._confirming = COLOUR_CONFIRM_FRAMES  # the frames the latest restart by colour needs
        self._box_wh: tuple[int, int] | None = None
        # what the latest restarts by colour replaced (used while they are not proven: :data:`COLOUR_PROVEN_FRAMES`),
        # and how many restarts were undone so far
        self._undo: _Undo | None = None
        self.refuted = 0
        # the latest restart by colour's distance from where the UUV was sought (px)
        self._restart_px = math.nan
        # the sea as read (see :data:`COLOUR_SEARCH_ROUGH_S`): rough or not (None: not yet read that long), and the
        # matcher's latest reading (rough or not) since when (t_unix)
        self._rough: bool | None = None
        self._reading_rough: bool | None = None
        self._reading_since_t = math.nan
        self._forget()
        self._awaiting_frames = 0
        self._noted_state = None
        self.since_t = math.nan  # the first frame (t_unix) in the current state
        self.frames_in_state = 0

    @property
    def state(self) -> TargetState:
        """The target's state; ``CONFIRMING`` while a box is checked over frames."""
        return TargetState.CONFIRMING if self._steady is not None else self.target.state

    @property
    def outlined(self) -> bool:
        """Whether the target's box is an outline skyfix found, not the box as given."""
        return self._outlined

    # -- the operator's commands ------------------------------------------------------------------
    def select(
        self,
        frame_bgr,
        pose: CameraPose,
        i: int = 0,
        *,
        box=None,
        point=None,
        verify: bool = False,
        keep_drawn: bool = False,
        steady: bool = False,
        chroma: Chroma | None = None,
    ) -> TrackResult:
        """Track the UUV in ``box`` (x, y, w, h) or at the click ``point`` (u, v) of this frame, from now on.

        Raises :class:`SelectionError` (and changes nothing) for a box outside the
        frame or on its edge (the box tracked: drawn, or the outline found), or a click with no object standing out
        near it or without a pose;
        with ``verify``, also for a box with no object standing out in it (checked
        when the pose can size the vehicle); ``keep_drawn``: a verified box on the
        vehicle's outline is kept as drawn (see the module doc). ``chroma``: the frame's colour, the vehicle's
        learnt there (:mod:`.colour`; a box checked over frames: on the frame it is taken in).
        """
        if (box is None) == (point is None):
            raise SelectionError("give either a box [x, y, w, h] or a point [u, v]")
        given = box if box is not None else point
        if not all(math.isfinite(c) for c in given):
            raise SelectionError(
                f"{'box' if box is not None else 'point'} {list(given)}: expected finite pixels"
            )
        one = take(pose, [i])
        if verify and steady and box is not None:
            return self._learned(
                chroma, self._select_steady(frame_bgr, one, box, keep_drawn, chroma)
            )
        outlined = None
        if point is not None:
            outlined = self._outline_click(frame_bgr, one, point)
        elif verify:
            outlined = self._outline_box(frame_bgr, one, box)
            if keep_drawn and outlined is not None and self._agrees(one, box, outlined):
                outlined = None
        box = outlined or box
        _refuse_at_edge(frame_bgr, box)
        x, y, w, h = box
        cu, cv_ = top_face_pixel(self.cal, one, [x + (w - 1) / 2.0], [y + (h - 1) / 2.0])
        centre = (float(cu[0]), float(cv_[0]))
        origin = "click" if point is not None else "box"
        return self._learned(
            chroma, self._track_from(frame_bgr, one, box, centre, origin, outlined is not None)
        )

    def start_at(self, frame_bgr, pose: CameraPose, i: int, box, point) -> TrackResult:
        """Track the UUV from a sighting another pass over the same video made (e.g. offline, tracing a
        re-acquisition back in time): the top face's pixel ``point`` (u, v) inside ``box`` (x, y, w, h) of this
        frame, taken as they are (no outline, no correction to the top face). SelectionError for a box outside
        the frame."""
        one = take(pose, [i])
        return self._track_from(
            frame_bgr, one, box, (float(point[0]), float(point[1])), "box", False
        )

    def back_from(self, frame_bgr, pose: CameraPose, i: int) -> TrackingSession:
        """A session tracking the UUV this one found in this frame (its latest result, ``ok``) through other frames
        of the same video, e.g. offline back in time: started there as :meth:`start_at` starts, its matcher a copy
        of this one's (the appearance it learnt, and through waves the sea state and the water's levels it read).
        SelectionError for a box outside the frame."""
        found = self.last
        back = TrackingSession(self.cal, self.tracker)
        back.start_at(frame_bgr, pose, i, found.box, (found.u, found.v))
        back.target.adopt(self.target, found)
        back.take_colour(self)
        return back

    def unproven(self, t_unix: float) -> bool:
        """Whether the track at ``t_unix`` is on a restart by colour not yet proven (:data:`COLOUR_PROVEN_FRAMES`,
        :data:`COLOUR_PROVEN_S`): the colour may still refute it (:attr:`refuted` counts those), and the track go back
        to what it was."""
        return self._undo is not None and not self._undo.proven(t_unix)

    def take_colour(self, other: TrackingSession) -> None:
        """Check the vehicle's colour as ``other`` learnt it (a tracker of the same UUV through other frames of the
        same video), not learning its own."""
        self._colour, self._learn_colour = other._colour, False
        self._vetoed, self._unconfirmed, self._box_wh = 0, 0, other._box_wh

    def _track_from(
        self, frame_bgr, one: CameraPose, box, centre, origin: str, outlined: bool
    ) -> TrackResult:
        """Tracking starts on ``box`` with the top face's pixel ``centre`` in the one-frame pose ``one``."""
        return self._note(
            float(one.t_unix[0]), self._begin(frame_bgr, one, box, centre, origin, outlined)
        )

    def _begin(
        self, frame_bgr, one: CameraPose, box, centre, origin: str, outlined: bool
    ) -> TrackResult:
        """:meth:`_track_from`'s start, its result not yet noted."""
        self._steady = None
        self.check = None
        self._colour, self._learn_colour = None, True
        self._undo = None
        anchor, px_per_m = self._locate(one, centre)
        try:
            result = self.target.select(frame_bgr, box, centre, px_per_m)
        except ValueError as e:
            raise SelectionError(str(e)) from None
        self._start(one, centre, anchor)
        self.origin = origin
        self._outlined = outlined
        self.prediction = self.sought = None
        self._length_px = VEHICLE_FOOTPRINT_M[0] * px_per_m
        return result

    def release(self) -> None:
        """Let go of the target: every frame is ``released`` until a new selection or :meth:`acquire`."""
        self.target.release()
        self._steady, self.check = None, None
        self._undo = None
        self._forget()

    def acquire(self) -> None:
        """Drop the target and await one: a selection, or automatic acquisition from a prior."""
        self.target.acquire()
        self._steady, self.check = None, None
        self._undo = None
        self._forget()

    # -- per frame ----------------------------------------------------------------------------------
    def step(
        self,
        frame_bgr,
        pose: CameraPose,
        i: int = 0,
        prior: Prior | None = None,
        chroma: Chroma | None = None,
    ) -> TrackResult:
        """The UUV in the next frame (``pose``'s frame ``i``); ``prior`` is used while awaiting a target;
        ``chroma``: the frame's colour, the tracked place checked against the vehicle's (:meth:`_coloured`)."""
        self.prediction = self.sought = None
        if self.target.state is TargetState.AWAITING_TARGET:
            result = (
                self._acquire(frame_bgr, pose, i, prior)
                if prior is not None
                else TrackResult("awaiting_target")
            )
        else:
            self.prediction = self._predict(pose, i)
            self.sought = self._from_stood_out(pose, i) or self.prediction
            result = self.target.update(frame_bgr, self.sought)
            self._read_sea(float(pose.t_unix[i]))
            if result.ok:
                self._saw(pose, i, result.u, result.v)
                if not self.target.distinct < STOOD_OUT_DISTINCT:  # NaN: not read (a still surface)
                    self._stood_out = self._seen
            elif self.target.state is TargetState.AWAITING_TARGET:
                self._forget()  # a candidate that did not confirm
            held = self.target.held  # the matcher's place in a frame it held (None: not held)
            if self._steady is not None:
                result, held = self._checked(frame_bgr, pose, i, result, chroma), None
            if self._colour is not None and chroma is not None:
                result = self._coloured(chroma, result)
                if self._vetoed >= COLOUR_SEARCH_AFTER or self.target.state is TargetState.LOST:
                    found = self._found_by_colour(frame_bgr, chroma, pose, i)
                    if found is None and self._vetoed >= COLOUR_SEARCH_AFTER:
                        self._undo_refuted(float(pose.t_unix[i]))
                    result = found or result
                if held is not None and self.target.held is held:  # not undone meanwhile
                    result = self._held_coloured(chroma, held, result) or result
            result = self._learned(chroma, result)
        return self._note(float(pose.t_unix[i]), result)

    def status(self) -> dict:
        """JSON-ready: state, how the target was chosen, since when, and the last frame's result."""
        r = self.last
        seen = self._seen

        def num(x):
            return round(float(x), 3) if math.isfinite(x) else None

        return {
            "state": self.state.value,
            "tracker": self.tracker,
            "origin": self.origin,
            "since_t": num(self.since_t),
            "frames_in_state": self.frames_in_state,
            "status": r.status,
            "u": num(r.u),
            "v": num(r.v),
            "box": list(r.box) if r.box else None,
            "confidence": num(r.confidence),
            "seen_t": num(seen.t_unix) if seen else None,
        }

    # -- internals ----------------------------------------------------------------------------------
    def _learned(self, chroma: Chroma | None, result: TrackResult) -> TrackResult:
        """``result``, the vehicle's colour learnt at its pixel when it is still to be (the first frame tracked
        ``ok`` from a selection; one checked over frames once taken)."""
        if (
            self._learn_colour
            and result.ok
            and self._steady is None
            and chroma is not None
            and self._length_px > 0  # sized by a pose
        ):
            self._learn_colour = False
            self._colour = learn(chroma, result.u, result.v, _half_px(result))
            self._vetoed, self._unconfirmed, self._box_wh = 0, 0, result.box[2:]
        return result

    def _coloured(self, chroma: Chroma, result: TrackResult) -> TrackResult:
        """A frame's ``ok`` result, no fix (``lost``) where the tracked place does not have the vehicle's colour
        (:mod:`.colour`). Only the frame's word changes: the tracker follows on as it would have, its sighting and
        its template as they were (a loss declared on the colour, with the searches after it, located fewer frames
        through waves: bench/results/colour_check_s16.txt)."""
        if not result.ok:
            return result
        d = separation(self._colour, chroma, result.u, result.v, _half_px(result))
        if self._colour.matches(d):
            if self._undo is not None:
                self._undo.passed += 1
            self._vetoed, self._box_wh = 0, result.box[2:] if result.box else self._box_wh
            if self._unconfirmed == 0:
                return result
            self._unconfirmed -= 1
        else:
            self._vetoed += 1
            if self._unconfirmed:
                self._unconfirmed = self._confirming
        return TrackResult("lost", confidence=result.confidence)

    def _held_coloured(
        self, chroma: Chroma, held: Match, result: TrackResult
    ) -> TrackResult | None:
        """A frame the matcher held (its best place under its bars, not yet a loss), ``ok`` where the vehicle's colour
        stands out as a restart by colour needs: at the held place when it is near where the UUV was sought
        (:meth:`_near_sought`), else, through waves (:meth:`_sea_rough`), at where it was sought (placed by the colour
        there, not by a match: the claim of a tracker without a score); None when at neither. On a still surface a
        held frame is a vehicle cut by the frame's edge or hidden in part, and the prediction is no better than the
        match (tests/test_tracking_frame_edge.py). While a restart by colour awaits its confirmation such
        a frame is one of its frames of the vehicle's colour at the track (and of its proof), not yet a fix: the
        waves hold a small or deep UUV's matches under the bars for a few frames at a time, and a restart on it
        waited through them. ``result``: the frame's (``lost``). The tracker follows on as it would have."""
        sought = self.sought or self.prediction
        if self._box_wh is None or sought is None:
            return None
        places = [(held.u, held.v, result.confidence)] if self._near_sought(held.u, held.v) else []
        if self._sea_rough():
            places.append((sought.u, sought.v, math.nan))
        half_px = max(self._box_wh) / 2
        bar = self._colour_bar()
        place = next(
            (p for p in places if separation(self._colour, chroma, p[0], p[1], half_px) >= bar),
            None,
        )
        if place is None:
            return None
        if self._unconfirmed:
            self._unconfirmed -= 1
            if self._undo is not None:
                self._undo.passed += 1
            return None
        u, v, confidence = place
        return TrackResult("ok", u, v, self._box_at(u, v), confidence)

    def _near_sought(self, u: float, v: float) -> bool:
        """Whether (u, v) is within :data:`HELD_COLOUR_REACH` of the vehicle's box (its last size the colour check
        passed) of where the UUV was sought in this frame."""
        sought = self.sought or self.prediction
        reach = HELD_COLOUR_REACH * max(self._box_wh)
        return sought is not None and math.hypot(u - sought.u, v - sought.v) <= reach

    def _found_by_colour(
        self, frame_bgr, chroma: Chroma, pose: CameraPose, i: int
    ) -> TrackResult | None:
        """Through waves, tracking restarted where the vehicle's colour stands out most in the window the UUV is
        sought in, when it stands out there as it did when learnt (:data:`COLOUR_FOUND_SHARE`) and nowhere else in
        the window more than a vehicle's length away does; None otherwise. The track then gives no fix until
        :data:`COLOUR_CONFIRM_FRAMES` more frames have its colour there (:data:`COLOUR_CONFIRM_FAR_FRAMES` for a
        restart away from where the UUV was sought); the restart's own frame is ``lost`` unless the restart is near
        where the UUV was sought (:meth:`_near_sought`: a fix there, as a held frame would be, without a score:
        :data:`~localizer.tracking.sigma.UNSCORED_SHARE` of the vehicle's length claimed)."""
        got = self._colour_found(chroma) if self._sea_rough() else None
        if got is None:
            return None
        near = self._near_sought(got[0], got[1])
        sought = self.sought or self.prediction
        restart_px = math.hypot(got[0] - sought.u, got[1] - sought.v)
        one = take(pose, [i])
        cu, cv_ = top_face_pixel(self.cal, one, [got[0]], [got[1]])
        centre = (float(cu[0]), float(cv_[0]))
        anchor, px_per_m = self._locate(one, centre)
        box = self._box_at(got[0], got[1])
        before = copy.copy(self.target)  # its matcher is replaced, not changed
        try:
            result = self.target.select(frame_bgr, box, centre, px_per_m)
        except ValueError:  # the box reaches beyond the frame
            return None
        t_unix = float(one.t_unix[0])
        if self._undo is None or self._undo.proven(t_unix):
            self._undo = _Undo(before, {name: getattr(self, name) for name in _TRACK})
        self._undo.t_unix, self._undo.passed = t_unix, 0
        self._start(one, centre, anchor)
        self._confirming = COLOUR_CONFIRM_FRAMES if near else COLOUR_CONFIRM_FAR_FRAMES
        self._vetoed, self._unconfirmed = 0, self._confirming
        self._restart_px = restart_px
        if near:  # placed by its colour, not by a match: the claim of a tracker without a score
            return TrackResult("ok", result.u, result.v, result.box, math.nan)
        return TrackResult("lost", confidence=result.confidence)

    def _undo_refuted(self, t_unix: float) -> None:
        """The track as it was before the latest restarts by colour when the colour refuted them before they were
        proven (:data:`COLOUR_PROVEN_FRAMES`)."""
        undo, self._undo = self._undo, None
        if undo is None or undo.proven(t_unix):
            return
        self.refuted += 1
        self.target = undo.target
        for name, value in undo.track.items():
            setattr(self, name, value)
        self._vetoed, self._unconfirmed = 0, 0

    def _colour_found(self, chroma: Chroma) -> tuple[float, float, float, float] | None:
        """:func:`.colour.find`'s answer in the window the UUV is sought in, where the vehicle's colour stands out
        as learnt (:data:`COLOUR_FOUND_SHARE`, :data:`COLOUR_FOUND_MIN`) and nowhere else more than a vehicle's
        length away does; None otherwise (none, or two of the vehicle's colour)."""
        win = search_window(self.sought or self.prediction)
        if win is None or self._box_wh is None:
            return None
        got = find(self._colour, chroma, win, max(self._box_wh) / 2)
        bar = self._colour_bar()
        return None if got is None or not got[2] >= bar or got[3] >= bar else got

    def _colour_bar(self) -> float:
        """How far (ring spreads) a place must stand out in the vehicle's colour to be taken for it without the
        matcher: :data:`COLOUR_FOUND_SHARE` of its separation when learnt, at least :data:`COLOUR_FOUND_MIN`."""
        return max(COLOUR_FOUND_MIN, COLOUR_FOUND_SHARE * self._colour.separation)

    def _box_at(self, u: float, v: float) -> tuple[int, int, int, int]:
        """The last box the colour check passed (its size), centred on (u, v)."""
        bw, bh = self._box_wh
        return (round(u - (bw - 1) / 2), round(v - (bh - 1) / 2), bw, bh)

    def _sea_rough(self) -> bool:
        """Whether the vehicle's colour alone may place it (a search by colour, a held frame's fix where the UUV was
        sought): the sea as read rough (:meth:`_read_sea`), or a configured wind of at least
        :data:`COLOUR_SEARCH_WIND_MPS`."""
        rough = self._rough if self._rough is not None else self._reading_rough
        return bool(rough) or self.cal.sigmas.wind_mps >= COLOUR_SEARCH_WIND_MPS

    def _read_sea(self, t_unix: float) -> None:
        """The sea as read: rough once the matcher has read it so (:data:`COLOUR_SEARCH_WAVES`) for
        :data:`COLOUR_SEARCH_ROUGH_S`, calm once it has read it calmer as long; before either, the latest reading
        (a track's first second: waves from the start are read at once, and no pass has a calm to rise from)."""
        rough = self.target.waves >= COLOUR_SEARCH_WAVES
        if rough is not self._reading_rough:
            self._reading_rough, self._reading_since_t = rough, t_unix
        if t_unix - self._reading_since_t >= COLOUR_SEARCH_ROUGH_S:
            self._rough = rough

    def _note(self, t_unix: float, result: TrackResult) -> TrackResult:
        """The frame's result, with its pixel's 1-sigma when ok (:func:`~localizer.tracking.sigma.pixel_sigma_px`:
        the match's score, the prediction's window, the time since the UUV was (re)acquired, how it was chosen, the
        follows' jitter against their predictions through waves, a restart by colour not yet proven)."""
        if self.state is not self._noted_state:
            self._noted_state, self.since_t, self.frames_in_state = self.state, t_unix, 0
        self.frames_in_state += 1
        p = self.prediction
        if p is not None:
            self._length_px = p.width_px
        if result.ok:
            window = p.sigma_px if p is not None else math.nan
            if p is not None and math.isfinite(p.u + p.v):
                self._follows += 1
                self._jitter2 = jitter2_px2(
                    self._jitter2, self._follows, result.u - p.u, result.v - p.v
                )
            sigma_px = pixel_sigma_px(
                self._length_px,
                result.confidence,
                window,
                t_unix - self.since_t,
                self._outlined,
                math.sqrt(self._jitter2),
                self.target.waves,
                self._restart_px if self.unproven(t_unix) else math.nan,
            )
            # a TrackResult made afresh (dataclasses.replace costs as much as the sigma itself)
            result = TrackResult(
                result.status, result.u, result.v, result.box, result.confidence, sigma_px
            )
        self.last = result
        return result

    def _forget(self) -> None:
        """No sighting, no motion: the track's own state (each field here is in :data:`_TRACK`)."""
        self._seen: _Sighting | None = None
        # the last sighting the UUV stood out of the seafloor in (through waves; see the module doc)
        self._stood_out: _Sighting | None = None
        self._anchor: tuple[float, float] | None = None  # lat, lon of a sighting
        self._anchor_age = 0  # frames predicted from it
        self._anchor_tried: _Sighting | None = None  # the sighting last located
        # anchor projected: pose, first index, (n, 3)
        self._proj: tuple[CameraPose, int, np.ndarray] | None = None
        self._moves: list[
            tuple[float, float, float, float]
        ] = []  # recent sightings: t, residual u, v, px_per_m
        self.speed_mps = math.nan  # how fast the UUV was last seen moving (NaN: not known)
        # the follows' mean square jitter against their predictions (pixels², per axis) and their count
        self._jitter2, self._follows = 0.0, 0

    def _locate(self, one: CameraPose, point) -> tuple[tuple[float, float] | None, float]:
        """The pixel's position at the UUV's depth and the image scale there: ``((lat, lon) or None, px_per_m)``."""
        fix = locate(self.cal, one, [point[0]], [point[1]])
        if fix.status[0] != "ok":
            return None, math.nan
        _, _, px_per_m = project_uuv(self.cal, one, fix.lat[0], fix.lon[0])
        return (float(fix.lat[0]), float(fix.lon[0])), float(px_per_m[0])

    def _start(self, one: CameraPose, point, anchor) -> None:
        """A new target seen at ``point`` in the one-frame pose ``one`` (located at ``anchor``, or None)."""
        self._forget()
        pu, pv = point if anchor is not None else (math.nan, math.nan)
        self._seen = self._stood_out = _Sighting(
            float(one.t_unix[0]), point[0], point[1], pu, pv, one
        )
        self._anchor, self._anchor_tried = anchor, self._seen

    def _saw(self, pose: CameraPose, i: int, u: float, v: float) -> None:
        """The UUV seen at (u, v) in frame ``i``: the sighting later predictions start from.

        A frame without a camera pose cannot say where the UUV was relative to the
        anchor: the last sighting that could stays (its age widens the prediction),
        never the anchor's own place, which may be many frames old.
        """
        proj = self._projection(pose, i)
        if proj is not None and not (math.isfinite(proj[0]) and math.isfinite(proj[1])):
            return
        pu, pv = (proj[0], proj[1]) if proj is not None else (math.nan, math.nan)
        self._seen = _Sighting(float(pose.t_unix[i]), u, v, pu, pv, pose, i)
        if proj is not None:
            self._moved(float(pose.t_unix[i]), u - pu, v - pv, float(proj[2]))

    def _moved(self, t: float, ru: float, rv: float, px_per_m: float) -> None:
        """A sighting's residual from the anchor's projection (pixels): the UUV's own motion, the camera's taken
        out. Its speed: the residuals' trend over the last :data:`SPEED_WINDOW_S` (least squares), in metres."""
        self._moves = [m for m in self._moves if t - m[0] <= SPEED_WINDOW_S] + [
            (t, ru, rv, px_per_m)
        ]
        if t - self._moves[0][0] < SPEED_SPAN_S or not px_per_m > 0:
            return
        # one row per quantity (each row's mean as of a 1-D array: pairwise along the row)
        moves = np.array(self._moves).T.copy()
        (ts, us, vs, _), (t_mean, u_mean, v_mean, _) = moves, moves.mean(axis=1)
        ts = ts - t_mean
        tt = np.dot(ts, ts)
        du, dv = (float(np.dot(ts, x - mean) / tt) for x, mean in ((us, u_mean), (vs, v_mean)))
        self.speed_mps = math.hypot(du, dv) / px_per_m + SPEED_MARGIN_MPS

    def _predict(self, pose: CameraPose, i: int) -> Prediction | None:
        seen = self._seen
        if seen is None:
            return None
        self._anchor_age += 1
        if (
            self._anchor is None or self._anchor_age > REANCHOR_FRAMES
        ) and seen is not self._anchor_tried:
            self._anchor_tried = seen
            anchor, _ = self._locate(seen.pose(), (seen.u, seen.v))
            if anchor is not None:
                self._anchor, self._anchor_age, self._proj = anchor, 1, None
                ru, rv = (
                    seen.u - seen.pu,
                    seen.v - seen.pv,
                )  # residuals so far: now from the new anchor
                self._moves = (
                    [(t, u - ru, v - rv, s) for t, u, v, s in self._moves]
                    if math.isfinite(ru + rv)
                    else []
                )
                seen.pu, seen.pv = seen.u, seen.v  # the anchor is where this pixel is
                stood_out = self._stood_out
                if stood_out is not None and stood_out is not seen:
                    if math.isfinite(ru + rv):  # its projection moved as the others' residuals did
                        stood_out.pu, stood_out.pv = stood_out.pu + ru, stood_out.pv + rv
                    else:
                        self._stood_out = None
        return self._follow(seen, pose, i)

    def _from_stood_out(self, pose: CameraPose, i: int) -> Prediction | None:
        """Through waves, the prediction from the last sighting the UUV stood out of the seafloor in, when later
        ones did not (see the module doc); None otherwise."""
        stood_out, seen = self._stood_out, self._seen
        if (
            stood_out is None
            or seen is None
            or stood_out is seen
            or seen.t_unix - stood_out.t_unix > STOOD_OUT_WITHIN_S
        ):
            return None
        return self._follow(stood_out, pose, i)

    def _follow(self, sighting: _Sighting, pose: CameraPose, i: int) -> Prediction | None:
        """The prediction for the pose's frame ``i`` from ``sighting`` (:func:`~localizer.tracking.predict.follow`)."""
        proj = self._projection(pose, i)
        if proj is None:
            return None
        return follow(
            proj,
            (sighting.pu, sighting.pv),
            (sighting.u, sighting.v),
            float(pose.t_unix[i]) - sighting.t_unix,
            self.speed_mps,
        )

    def _projection(self, pose: CameraPose, i: int):
        """``(u, v, px_per_m)`` of the anchor in the pose's frame ``i`` (None without an anchor)."""
        if self._anchor is None:
            return None
        cached = self._proj
        if cached is not None and cached[0] is pose and cached[1] <= i < cached[1] + len(cached[2]):
            return cached[2][i - cached[1]]
        ahead = take(pose, slice(i, min(i + REANCHOR_FRAMES, len(pose.t_unix))))
        u, v, px_per_m = project_uuv(self.cal, ahead, *self._anchor)
        self._proj = (pose, i, np.stack([u, v, px_per_m], axis=-1))
        return self._proj[2][0]

    def _outline_click(self, frame_bgr, one: CameraPose, point) -> tuple[int, int, int, int]:
        u, v = float(point[0]), float(point[1])
        _, px_per_m = self._locate(one, (u, v))
        if not px_per_m > 0:
            why = (
                f"no camera pose at that frame ({one.status[0]}) to size the vehicle"
                if one.status[0] != "ok"
                else f"{locate(self.cal, one, [u], [v]).status[0]}: not a place on the water in the image"
            )
            raise SelectionError(f"point [{u:g}, {v:g}]: {why}; select with a box")
        guess = prediction_at(u, v, px_per_m, 0.0)
        reach = (
            CLICK_REACH
            * math.hypot(guess.width_px, guess.height_px)
            / self.detect_params.search_sigmas
        )
        found = detect(
            frame_bgr,
            Prediction(u, v, guess.width_px, guess.height_px, reach, px_per_m),
            self.detect_params,
        )
        if found is None:
            raise SelectionError(
                f"point [{u:g}, {v:g}]: no vehicle-sized object stands out there; select with a box"
            )
        return found.box

    def _box_prediction(self, one: CameraPose, box) -> Prediction | None:
        """The window :func:`~localizer.tracking.detect.detect` reads for a box (x, y, w, h): centred on it, the
        vehicle's size at its centre, its half-diagonal 3 sigma; None without a pose to size the vehicle."""
        x, y, w, h = (float(c) for c in box)
        cu, cv_ = x + (w - 1) / 2.0, y + (h - 1) / 2.0
        _, px_per_m = self._locate(one, (cu, cv_))
        guess = prediction_at(cu, cv_, px_per_m, 0.0)
        if guess is None:
            return None
        reach = math.hypot(w, h) / 2.0 / self.detect_params.search_sigmas
        return Prediction(cu, cv_, guess.width_px, guess.height_px, reach, px_per_m)

    def _outline_box(self, frame_bgr, one: CameraPose, box) -> tuple[int, int, int, int] | None:
        """The outline of the vehicle-sized object standing out of the water within ``box`` (see the module doc);
        SelectionError if there is none; None without a pose to size the vehicle."""
        window = self._box_prediction(one, box)
        if window is None:
            return None  # no pose to size the vehicle: the operator's box is all there is
        found = detect(frame_bgr, window, self.detect_params)
        if found is None or not _overlap(found.box, box):
            raise SelectionError(f"{_named(box)}: {_NOTHING_IN_BOX}; draw the box around the UUV")
        return found.box

    def _select_steady(
        self, frame_bgr, one: CameraPose, box, keep_drawn: bool, chroma: Chroma | None
    ) -> TrackResult:
        """A box to check over frames (see :meth:`select`): followed from this frame on, its frames
        ``awaiting_target`` until :meth:`_checked` takes or refuses it; its colour learnt in ``chroma``, for the
        check (:data:`STEADY_COLOUR_MIN`) and kept once the box is taken as drawn (learnt again on the outline it is
        snapped to). Without a pose to size the vehicle, the box is tracked unchecked, as :meth:`select` does."""
        _refuse_at_edge(frame_bgr, box)
        window = self._box_prediction(one, box)
        x, y, w, h = box
        cu, cv_ = top_face_pixel(self.cal, one, [x + (w - 1) / 2.0], [y + (h - 1) / 2.0])
        centre = (float(cu[0]), float(cv_[0]))
        if window is None:
            return self._track_from(frame_bgr, one, box, centre, "box", False)
        self._begin(frame_bgr, one, box, centre, "box", False)
        params = replace(self.detect_params, min_saliency=STEADY_MIN_SALIENCY)
        self._steady = _Steady(
            SteadyWindow(window, centre, params), tuple(box), keep_drawn, float(one.t_unix[0])
        )
        self._steady.window.add(frame_bgr, centre)
        self._colour = learn(chroma, centre[0], centre[1], max(box[2], box[3]) / 2)
        self._vetoed, self._unconfirmed, self._box_wh = 0, 0, tuple(box[2:])
        self.check = "confirming"
        return self._note(float(one.t_unix[0]), TrackResult("awaiting_target"))

    def _checked(
        self, frame_bgr, pose: CameraPose, i: int, result: TrackResult, chroma: Chroma | None
    ) -> TrackResult:
        """A frame of a box being checked over frames, ``result`` the target's: ``awaiting_target`` until
        :data:`STEADY_S` has passed and the box is followed in the frame (at most twice that); then the box
        refused (awaiting a target; :attr:`check` says why) unless it was followed in :data:`STEADY_FOLLOWED` of
        the frames and a vehicle-sized object stands out of the mean of its window's saliencies, overlapping the
        box as followed here: then kept (``keep_drawn``, the box's centre agreeing with the outline's, or with
        where the mean's object is: an outline in one frame through waves may be a part of it) or snapped onto the
        outline in this frame, and ``ok``; or, its colour standing out (:data:`STEADY_COLOUR_MIN`), kept as followed
        when its colour was found where it was sought in :data:`STEADY_FOLLOWED` of the frames and is at the tracked
        place here."""
        steady = self._steady
        steady.frames += 1
        coloured = (
            chroma is not None
            and self._colour is not None
            and self._colour.separation >= STEADY_COLOUR_MIN
        )
        if coloured and self._colour_found(chroma) is not None:
            steady.coloured += 1
        if result.ok:
            steady.window.add(frame_bgr, (result.u, result.v))
        age_s = float(pose.t_unix[i]) - steady.t0_unix
        if age_s < STEADY_S or (not result.ok and age_s < 2 * STEADY_S):
            return TrackResult("awaiting_target", confidence=result.confidence)
        window, found = steady.window, None
        if result.ok and window.frames >= STEADY_FOLLOWED * steady.frames:
            x, y, w, h = steady.box
            du, dv = result.u - window.start_uv[0], result.v - window.start_uv[1]
            followed = (round(x + du), round(y + dv), w, h)
            found = window.detect()
        if found is None or not _overlap(found.box, followed):
            if (
                coloured
                and result.ok
                and steady.coloured >= STEADY_FOLLOWED * steady.frames
                and self._colour.matches(
                    separation(self._colour, chroma, result.u, result.v, _half_px(result))
                )
            ):
                return self._kept(result)
            return self._refused(
                f"refused: {_named(steady.box)}: {_NOTHING_IN_BOX} over {window.frames} of "
                f"{steady.frames} frames it was followed in; draw the box around the UUV"
            )
        one = take(pose, [i])
        pu, pv = window.peak()
        fw, fh = found.box[2:]
        if steady.keep_drawn and (
            self._agrees(one, followed, found.box)
            or self._agrees(one, followed, (pu - (fw - 1) / 2.0, pv - (fh - 1) / 2.0, fw, fh))
        ):
            return self._kept(result)
        if _at_edge(frame_bgr, found.box):
            return self._refused(
                f"refused: the vehicle's outline {_named(found.box)} is {_AT_EDGE}"
            )
        fx, fy, fw, fh = found.box
        cu, cv_ = top_face_pixel(self.cal, one, [fx + (fw - 1) / 2.0], [fy + (fh - 1) / 2.0])
        snapped = self._begin(frame_bgr, one, found.box, (float(cu[0]), float(cv_[0])), "box", True)
        self.check = "snapped"
        return snapped

    def _refused(self, why: str) -> TrackResult:
        """The box checked over frames refused (:attr:`check` says ``why``): awaiting a target, its colour dropped."""
        self.acquire()
        self._colour = None  # the refused box's
        self.check = why
        return TrackResult("awaiting_target")

    def _kept(self, result: TrackResult) -> TrackResult:
        """The box checked over frames taken as drawn, ``result`` its frame's: the vehicle's colour stays as learnt
        in the drawn box (as offline, where init_bbox is taken on its frame), not learnt again where the check ends
        (the matcher's place then, or a search by colour's)."""
        self._steady, self.check, self._learn_colour = None, "kept", False
        return result

    def _agrees(self, one: CameraPose, drawn, outline) -> bool:
        """Whether the drawn box's centre is within :data:`DRAWN_AGREES` outline errors of the outline's."""
        (dx, dy), (ox, oy) = (
            (b[0] + (b[2] - 1) / 2.0, b[1] + (b[3] - 1) / 2.0) for b in (drawn, outline)
        )
        _, px_per_m = self._locate(one, (ox, oy))
        reach_px = DRAWN_AGREES * OUTLINED_SHARE * VEHICLE_FOOTPRINT_M[0] * px_per_m
        return abs(dx - ox) <= reach_px and abs(dy - oy) <= reach_px

    def _acquire(self, frame_bgr, pose: CameraPose, i: int, prior: Prior) -> TrackResult:
        """Awaiting a target, with the UUV's own estimate: search near it for a candidate to confirm."""
        self._awaiting_frames += 1
        if (self._awaiting_frames - 1) % self.target.p.search_every:
            return TrackResult("awaiting_target")
        one = take(pose, [i])
        u, v, px_per_m = project_uuv(self.cal, one, prior.lat, prior.lon)
        near_prior = self.prediction = prediction_at(u[0], v[0], px_per_m[0], prior.sigma_m)
        found = (
            detect(frame_bgr, near_prior, self.detect_params) if near_prior is not None else None
        )
        if found is None or _at_edge(frame_bgr, found.box):
            return TrackResult("awaiting_target")
        cu, cv_ = top_face_pixel(self.cal, one, [found.u], [found.v])
        centre = (float(cu[0]), float(cv_[0]))
        anchor, scale = self._locate(one, centre)
        if anchor is None:
            return TrackResult("awaiting_target")
        self._start(one, centre, anchor)
        self.origin = "prior"
        self._outlined = True
        here = prediction_at(centre[0], centre[1], scale, BASE_SIGMA_M)
        return self.target.propose(frame_bgr, found.box, centre, scale, here)


#: Why a box is refused: the one-frame check's and the check over frames' words
_NOTHING_IN_BOX = "no vehicle-sized object stands out of the water in it"


#: Why a box on the frame's edge is refused
_AT_EDGE = (
    "on the frame's edge: the UUV may be cut off there, and a template of part of it would put every fix off "
    "its centre; select the UUV when it is wholly in view"
)


def _at_edge(frame, box) -> bool:
    """Whether a box (x, y, w, h) inside the frame reaches its edge (its first or last row or column): the object
    in it may be cut off by the edge. A box reaching beyond the frame is not (the matcher names that)."""
    rows, cols = frame.shape[:2]
    x, y, w, h = (round(c) for c in box)
    inside = x >= 0 and y >= 0 and x + w <= cols and y + h <= rows
    return inside and (x == 0 or y == 0 or x + w == cols or y + h == rows)


def _refuse_at_edge(frame, box) -> None:
    """SelectionError for a box on the frame's edge (:func:`_at_edge`)."""
    if _at_edge(frame, box):
        raise SelectionError(f"{_named(box)} is {_AT_EDGE}")


def _named(box) -> str:
    """A box as its refusal names it: ``box [x, y, w, h]``."""
    return "box [" + ", ".join(f"{float(c):g}" for c in box) + "]"


@dataclass
class _Steady:
    """A box being checked over frames: the mean window, the box as drawn, whether to keep it as drawn on the
    outline, the first frame's time, the frames seen since (the first included) and those its colour was found in."""

    window: SteadyWindow
    box: tuple
    keep_drawn: bool
    t0_unix: float
    frames: int = 1
    coloured: int = 0  # frames its colour was found where it was sought


#: The track's own state a restart by colour replaces (:meth:`TrackingSession._start`) and an undo restores
_TRACK = (
    "_seen",
    "_stood_out",
    "_anchor",
    "_anchor_age",
    "_anchor_tried",
    "_proj",
    "_moves",
    "speed_mps",
    "_jitter2",
    "_follows",
)


@dataclass
class _Undo:
    """What restarts by colour replaced: the target (its matcher then) and the track's state (:data:`_TRACK`); the
    latest restart's time (t_unix) and the frames its colour was at the track since."""

    target: Target
    track: dict
    t_unix: float = math.nan
    passed: int = 0

    def proven(self, t_unix: float) -> bool:
        """Whether the latest restart stands (:data:`COLOUR_PROVEN_FRAMES`, :data:`COLOUR_PROVEN_S`)."""
        return self.passed >= COLOUR_PROVEN_FRAMES or t_unix - self.t_unix > COLOUR_PROVEN_S


def _half_px(result: TrackResult) -> float:
    """Half the tracked box's longer side (px; NaN without a box): the vehicle's colour is read in a square of it."""
    return max(result.box[2:]) / 2 if result.box else math.nan


def _overlap(a, b) -> bool:
    """Whether two boxes (x, y, w, h) share any area."""
    return a[0] < b[0] + b[2] and b[0] < a[0] + a[2] and a[1] < b[1] + b[3] and b[1] < a[1] + a[3]

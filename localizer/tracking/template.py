"""The default matcher: normalized cross-correlation in the window the telemetry predicts.

The UUV's grey-level appearance is kept as a *canonical* template (upright, at
the size it had at start). Each frame it is rotated to the UUV's current heading
in the image and scaled to the predicted apparent size, then matched
(``cv2.matchTemplate``, ``TM_CCOEFF_NORMED``) inside a window centred on the
prediction and as large as its uncertainty. Candidates are ranked by their score
less a penalty for their distance from the prediction (``distance_weight`` × half
the squared distance in prediction sigmas: a look-alike further from where the UUV
should be needs a better score to win); the best is refined to sub-pixel precision
by a parabola fit of the raw scores, and every ``adapt_every`` frames (at once when
the score sags) the heading is followed by trying ±``turn_step_deg`` steps. The
matched patch, turned back upright, is blended slowly into the canonical
template when the match is confident, so it follows lighting, depth and the side
the vehicle shows. A drift is refused, not learnt: a clear match (see
:meth:`~TemplateMatcher._visible`) must show the UUV's first appearance at the
tracked point (within ``anchor_drift`` of its side, NCC at least ``anchor_score``), else it
is no match (the template was sliding onto a shadow, a rock, the seafloor), and a
blend after which the template would not show it is not made.
Patches with less than ``learn_contrast`` of the first appearance's grey-level
spread are not learnt: a UUV fading into turbid water as it dives would
otherwise teach the template the water's noise.
Images are block-averaged by an integer factor so the template keeps about
``work_px`` pixels across whatever the UUV's size: the cost per frame is nearly
independent of resolution. The reported pixel is the start ``point`` (default:
the box centre), carried along as the vehicle moves and turns.

What passes for the UUV (the lost/re-acquire life itself is :class:`~.target.Target`'s):

- :meth:`~TemplateMatcher.follow`: a peak of at least ``ok_score`` (and no more than
  ``level_drop`` below the recent level), inside the predicted window, on a patch with
  at least ``min_contrast`` of the first appearance's grey-level spread (a UUV that has
  dived out of sight would otherwise leave NCC matching the water's noise) that, when
  clear enough to tell, shows the first appearance at the tracked point.
- :meth:`~TemplateMatcher.search`: the best match over ``reacquire_headings`` headings
  (only those within the prediction's ``turn_deg`` of the last one or of its reverse, as far apart;
  refined by turn steps) in a window that grows with the prediction's uncertainty
  (the whole frame without a prediction; a wide window is searched block-averaged
  first, and its best places again at working resolution), with at least
  ``reacquire_score`` (and within ``reacquire_below_level`` of the recent level) and
  ``min_contrast``.
- :meth:`~TemplateMatcher.confirm`: the same bar within ``reacquire_tolerance``
  template sides of where the candidate is expected.
- Waves (issue 28): the UUV's image wobbles, breaks up and flickers from frame to frame, and its scores scatter
  about their recent mean. That scatter (:meth:`~TemplateMatcher._waves`, nil on a still surface: the bars above
  as set) eases the bars (``wave_*``), smooths image and template before matching (the waves scramble the fine
  structure, not the shape), lets the template learn the mean distorted appearance, and holds up to
  ``wave_misses`` frames without a match before a loss (:attr:`~localizer.tracking.Match.held`; up to
  ``wave_hold_misses`` while the held place still stands out of the water beside it; a match that climbed out of
  the window holds the prediction's place while it has the contrast a follow needs); a match after
  such frames needs nearly the re-acquisition's bar. In waves every match, followed or a candidate, also needs
  ``wave_contrast_share`` of the UUV's contrast level (:meth:`~TemplateMatcher._least_contrast`: the waves scramble
  its structure, not how much it stands out; the water and the seafloor the template finds without it have a
  fraction of it); a follow with ``wave_keep_contrast`` of it needs a score only above the water's level less
  ``wave_keep_below`` and within ``wave_keep_drop`` of the recent level of its matches (a second vehicle passing
  over it raises the contrast too, and drags the score down); a search for a candidate ranks the places with
  less contrast last (:meth:`~TemplateMatcher._least_spread`), the water beside its window too. The level, and
  the template, learn only from follows with ``wave_keep_contrast`` of it (a reference kept from clear frames);
  the template only where something near the match stands out of the seafloor (``wave_learn_distinct``).
  A search's best is judged as a candidate from the re-acquisition's wave bar on (:meth:`~TemplateMatcher._candidate`),
  not refused under ``ok_score`` first (a UUV the waves let the template match only at 0.3 is otherwise never found).
  A candidate further than ``wave_far_sigmas`` from the prediction pays the distance penalty of the sigmas beyond
  (:meth:`~TemplateMatcher._far_penalty`), and a re-acquisition's contrast averaged over its confirmation frames
  reaches ``wave_keep_contrast`` of the level (a seafloor patch passes a frame's lower bar now and then).
  A follow that passes in waves is moved part of the way onto the vehicle standing out of the seafloor near it
  (:meth:`~TemplateMatcher._centred`; the smoothed template matches about as well with the vehicle in a corner of
  its square), or the whole way onto the vehicle near the prediction where it passed on its contrast alone and
  lies beyond that vehicle's square: judged, and learnt from, where the template matched.
- Neither takes a candidate away from the prediction while the UUV's first appearance
  still matches nearer the prediction (:meth:`~TemplateMatcher._still_there`: the UUV
  partly hidden, say by a vehicle passing over it, beside a look-alike). Only a candidate
  beyond the prediction's sigma is away from it: after a long loss the prediction is a
  wide window, not a place, and its centre matches the first appearance's small core on
  the water's texture about as well as a hidden UUV does (NCC 0.5-0.7 at 320×180).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.lib.stride_tricks import as_strided

from . import Match, Prediction
from .opencv import check_box


@dataclass(frozen=True)
class TemplateParams:
    work_px: int = 24  # the template's side after block averaging (pixels)
    ok_score: float = 0.5  # NCC below this: the UUV is not there
    level_drop: float = 0.25  # ... or this far below the recent level of confident matches
    update_score: float = 0.7  # NCC above this: blend the match into the template
    adapt_every: int = 1  # try other headings and learn the appearance every this many frames
    learn_rate: float = 0.04  # fraction of the template replaced per learning step
    # learn only from patches with at least this share of the first appearance's contrast
    learn_contrast: float = 0.2
    # check a match against the first appearance when it has at least this share of it
    check_contrast: float = 0.5
    # a match with less (faded into the water: deep, turbid) is not the UUV
    min_contrast: float = 0.08
    # undo the learnt template's drift from its first appearance beyond this
    recentre_px: float = 0.2
    anchor_score: float = 0.2  # a clear match (check_contrast) shows the first appearance at least this well (NCC) ...
    # ... within this share of the template's side of the tracked point (else: a drift),
    anchor_drift: float = 0.12
    anchor_drift_px: float = 2.0  # ... or this many working pixels if more ...
    # ... sought within this many working pixels of it; further off only if it matches
    anchor_shift_px: int = 4
    anchor_level: float = 0.05  # ... at the tracked point no more than this less well
    # the first appearance compared: the central square of this share of the template's
    # side, the vehicle at any heading (the corners hold the seafloor, which changes) ...
    core_share: float = 0.6
    # ... turned up to this much either way from the learnt template's own turn from
    # it (the heading followed strays slowly) ...
    first_turn_deg: float = 15.0
    first_turn_step_deg: float = 5.0  # ... in these steps
    # a candidate away from the prediction is refused while the first appearance matches
    # this well (NCC) nearer the prediction (the UUV partly hidden beside a look-alike)
    there_score: float = 0.5
    distance_weight: float = 0.2  # a candidate's score less this × half its squared distance from the prediction in sigmas
    turn_step_deg: float = 6.0  # heading change tried each time (each way)
    max_turn_steps: int = 4  # ... and up to this many steps while the match improves
    # try other headings at once when the score falls this far below the level
    turn_drop: float = 0.05
    turn_gain: float = 0.01  # turn a whole step only to a heading that matches better by this much
    search_sigmas: float = 3.0  # window half-size in prediction sigmas
    min_radius_px: float = 6.0  # smallest window half-size (full-resolution pixels)
    default_radius_px: float = 40.0  # window half-size without a prediction while tracking
    reacquire_score: float = 0.7
    # re-acquisition also needs a score within this of the level
    reacquire_below_level: float = 0.15
    reacquire_tolerance: float = 0.3  # agreement between consecutive matches, in template sides
    reacquire_headings: int = 8  # headings tried while lost (then refined by turn steps)
    # re-scale the template when the predicted size changes by more than this
    scale_step: float = 0.01
    # windows wider than this (working pixels) are searched block-averaged first
    coarse_side: int = 96
    coarse_px: int = 8  # ... with the template about this many blocks across
    # ... and this many of the best places found there matched again at full resolution
    coarse_keep: int = 3
    wobble_rate: float = 0.03  # the match score's scatter about its recent mean: a moving mean square at this rate ...
    # ... about a moving mean at this rate (a few frames: a slow change is no wobble)
    wobble_mean_rate: float = 0.2
    wobble_cap: float = 0.2  # ... each frame's change counted up to this much (a loss is one change, waves are many)
    # scatter (NCC, 1-sigma) of a still surface's matches: no wave tolerance below it ...
    wobble_flat: float = 0.04
    # ... the whole tolerance from this (waves: the UUV wobbles, breaks up, flickers)
    wobble_waves: float = 0.09
    # waves: image and template smoothed by up to this (working pixels, Gaussian sigma)
    wave_blur_px: float = 1.0
    wave_ok_drop: float = 0.1  # ... ok_score and reacquire_score lowered by up to this
    wave_level_drop: float = 0.15  # ... level_drop and reacquire_below_level raised by up to this
    # ... update_score lowered by up to this (learn the mean wave-distorted appearance)
    wave_update_drop: float = 0.2
    # ... and up to this many frames in a row without a match are held, not yet a loss ...
    wave_misses: float = 3.0
    #: ... or up to this many while the held match keeps ``wave_hold_between`` of the way from the contrast of the
    #: water beside the UUV to its level (see :meth:`~TemplateMatcher._least_contrast`): the waves break its image up
    #: or caustics dim it for a few frames, it has not gone (where it is hidden, the water has the water's contrast)
    wave_hold_misses: float = 6.0
    wave_hold_between: float = 0.25
    # from this much wave (see _waves; until it is nil again) the UUV is judged on the
    # evidence of several frames and on how it stands out of the water beside it:
    wave_mode: float = 0.5
    # ... the mean of the last this many follows' best scores (one frame's may fall
    # as low as the water's) reaching this share of the way from the water's level to
    wave_evidence_frames: int = 3
    wave_evidence_share: float = 0.5  # the UUV's (the recent level of its matches) ...
    # ... and the frame's own score this share; a candidate while lost this share:
    wave_follow_share: float = 0.35
    # the seafloor holds still patches that match as well as the water's best
    wave_reacquire_share: float = 0.75
    # ... the water's level: a running mean at this rate of the best score in
    # windows beside the prediction's (the template on the water around the UUV)
    wave_background_rate: float = 0.1
    # ... those windows this many template sides further out, each way
    wave_background_sides: float = 1.5
    #: a follow below those bars (a candidate being confirmed: below its bar) is still the UUV if its patch keeps
    #: this share of the UUV's contrast level (below; the waves scramble its structure, not its spread; the water
    #: where it was has less) ...
    wave_keep_contrast: float = 0.8
    #: ... and its score is above the water's level less this (a deep UUV's distorted image scores as the water's)
    wave_keep_below: float = 0.2
    #: ... and (a follow) no more than this below the recent level of its matches (a second vehicle passing over
    #: it raises the contrast too, and drags the score down from the UUV's own level)
    wave_keep_drop: float = 0.3
    # a candidate found again where it is expected (confirming it): this share of the way
    wave_confirm_share: float = 0.5
    # in waves a match (followed or a candidate) has at least this share of the UUV's
    # contrast level (see _contrast): the water and the seafloor the template
    # finds where the UUV is hidden, or beside it, have a fraction of its spread
    wave_contrast_share: float = 0.7
    #: ... or, when lower, this share of the way from the contrast of the water beside the UUV (the best places of
    #: the template there, a running mean) to that level: at 8 m/s caustics dim a UUV that stands far above the
    #: water to 0.6 of its level for several frames, while a UUV that stands out little keeps the strict share
    wave_contrast_between: float = 0.4
    #: the follow below the usual bars (wave_keep_contrast): or, when lower, this share of that way
    wave_keep_between: float = 0.5
    wave_contrast_rate: float = 0.05  # ... that level: a running mean at this rate of the clear follows (wave_keep_contrast)
    #: in waves a candidate found while lost further than this many of the prediction's sigmas from it passes
    #: (:meth:`~TemplateMatcher._candidate_passes`) with its score less the distance penalty (``distance_weight``)
    #: of the sigmas beyond: a wide window's best patch of seafloor near its edge matches as well as the UUV does
    wave_far_sigmas: float = 2.0
    #: in waves a follow is moved ``wave_centre_pull`` of the way onto the vehicle-sized square (this share of the
    #: template's side) standing out most from the seafloor within ``wave_centre_reach`` of the template's side,
    #: where it departs from the seafloor ``wave_centre_distinct`` times as much as 9 in 10 of the seafloor's
    #: squares around it (see :meth:`~TemplateMatcher._centred`)
    wave_centre_share: float = 0.5
    wave_centre_reach: float = 0.3
    wave_centre_pull: float = 0.5
    wave_centre_distinct: float = 1.2
    #: in waves the template learns only from follows where the square standing out most near the match departs
    #: from the seafloor this many times as much as 9 in 10 of the seafloor's squares (see
    #: :meth:`~TemplateMatcher._teaches`)
    wave_learn_distinct: float = 1.0


#: Taken from the rank of a place too flat to be the UUV (see ``spread`` of :meth:`TemplateMatcher._search`): it
#: ranks below every place that is not.
_FLAT_PENALTY = 10.0

#: Working pixels: a frame's first conversion (:meth:`TemplateMatcher._prepare`) holds the upright patch about a
#: match this far from the prediction (a match further off converts its own: slower, the same values).
_UPRIGHT_SLACK = 2


def _running(mean: float, value: float, rate: float) -> float:
    """A running mean at ``rate`` moved towards ``value`` (``value`` itself while ``mean`` is NaN: the first)."""
    return value if not math.isfinite(mean) else mean + rate * (value - mean)


def _parabola(a: float, b: float, c: float) -> float:
    """Offset of the extremum of a parabola through (-1, a), (0, b), (1, c), clipped to ±0.5."""
    den = a - 2.0 * b + c
    return 0.0 if den >= 0 else min(0.5, max(-0.5, 0.5 * (a - c) / den))


def _peak(
    scores: np.ndarray, penalty: np.ndarray | None = None
) -> tuple[float, float, float, float]:
    """(rank, score, x, y) of the best match with sub-pixel offsets.

    With a ``penalty`` map (as ``scores``), the best place is the one whose score minus
    its penalty (the rank) is highest, moved uphill to the raw scores' own peak there:
    the penalty picks the peak, never shifts it.
    """
    _, rank, _, (j, i) = cv2.minMaxLoc(scores if penalty is None else scores - penalty)
    h, w = scores.shape
    if penalty is not None:
        while True:
            di, dj = divmod(
                int(np.argmax(scores[max(i - 1, 0) : i + 2, max(j - 1, 0) : j + 2])),
                min(j + 2, w) - max(j - 1, 0),
            )
            ni, nj = max(i - 1, 0) + di, max(j - 1, 0) + dj
            if (ni, nj) == (i, j):
                break
            i, j = ni, nj
        rank = float(scores[i, j] - penalty[i, j])
    dx = _parabola(scores[i, j - 1], scores[i, j], scores[i, j + 1]) if 0 < j < w - 1 else 0.0
    dy = _parabola(scores[i - 1, j], scores[i, j], scores[i + 1, j]) if 0 < i < h - 1 else 0.0
    return float(rank), float(scores[i, j]), float(j + dx), float(i + dy)


#: :func:`_ncc_maps`: a place whose spread is within this share of its squares' sum is flat (float32's rounding)
_FLAT_EPS = 10.0 * np.finfo(np.float32).eps


def _ncc_maps(image: np.ndarray, columns: np.ndarray, side: int) -> np.ndarray:
    """``cv2.matchTemplate(image, t, TM_CCOEFF_NORMED)`` for several side × side templates ``t`` at once: maps
    (templates, rows, columns). ``columns``: each template flattened, less its mean, divided by its norm.

    One product of matrices in place of a call per template: for a few small templates on a small image the calls'
    own cost is most of it. As OpenCV, a flat place of the image scores 0.
    """
    rows, cols = image.shape[0] - side + 1, image.shape[1] - side + 1
    # the places as a strided view converted in one copy (sliding_window_view's checks and a float32 copy cost
    # about as much as the product below), in C order: the strided view's own order makes the reshape copy again
    s0, s1 = image.strides
    places = (
        as_strided(image, (rows, cols, side, side), (s0, s1, s0, s1), writeable=False)
        .astype(np.float64, order="C")
        .reshape(rows * cols, side * side)
    )
    sums = places.sum(axis=1)
    squares = np.einsum("ij,ij->i", places, places)
    spread = squares - sums * sums / (side * side)
    flat = spread <= np.minimum(0.5, _FLAT_EPS * squares)
    scores = (places @ columns) / np.sqrt(np.where(flat, 1.0, spread))[:, None]
    scores[flat] = 0.0
    return scores.T.reshape(columns.shape[1], rows, cols)


def _spread_map(image: np.ndarray, side: int) -> np.ndarray:
    """The grey levels' standard deviation in every side × side window of ``image`` (as ``cv2.matchTemplate``'s
    places: rows - side + 1, columns - side + 1)."""
    image = image.astype(np.float32)
    mean, square = (cv2.blur(x, (side, side)) for x in (image, image * image))
    h = side // 2
    rows, cols = image.shape[0] - side + 1, image.shape[1] - side + 1
    var = square[h : h + rows, h : h + cols] - mean[h : h + rows, h : h + cols] ** 2
    return np.sqrt(np.maximum(var, 0.0))


def _warp(src: np.ndarray, centre, angle_deg: float, scale: float, side: int) -> np.ndarray:
    """side × side image whose pixel d (from its centre) samples ``src`` at ``centre + scale · R(angle) · d``."""
    a = math.radians(angle_deg)
    ca, sa = scale * math.cos(a), scale * math.sin(a)
    c = (side - 1) / 2.0
    M = np.array([[ca, -sa, centre[0] - (ca - sa) * c], [sa, ca, centre[1] - (sa + ca) * c]])
    return cv2.warpAffine(
        src,
        M,
        (side, side),
        flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
        borderMode=cv2.BORDER_REPLICATE,
    )


class TemplateMatcher:
    """Rotating, scaling NCC template steered by the telemetry's :class:`Prediction` (optional)."""

    def __init__(self, params: TemplateParams | None = None):
        self.p = params or TemplateParams()
        self._grey = None  # (bx0, by0, blocks): the largest area of the current frame converted (see _blocks)
        # the current frame's spreads and upright patches by place (read-only; a follow reads each up to thrice)
        self._looks: dict = {}
        # in waves, how much the vehicle standing out near this frame's followed match departs from the seafloor
        # (:meth:`_blob`'s distinctness); NaN for a frame not followed so
        self.distinct = math.nan

    # -- images at working resolution ------------------------------------------------------
    def _blocks(self, frame_bgr, bx0: int, by0: int, bw: int, bh: int) -> np.ndarray:
        """Grey blocks [bx0, bx0 + bw) × [by0, by0 + bh) of k×k pixels (clipped to the frame): float32, read-only.

        Within one frame, blocks inside the largest area converted so far
        are a view of it: a frame is converted once, not once per look.
        """
        k = self.k
        bx1, by1 = min(bx0 + bw, frame_bgr.shape[1] // k), min(by0 + bh, frame_bgr.shape[0] // k)
        if bx1 <= bx0 or by1 <= by0:
            return np.zeros((0, 0), np.float32)
        if self._grey is not None:
            gx0, gy0, grey = self._grey
            if (
                gx0 <= bx0
                and gy0 <= by0
                and bx1 <= gx0 + grey.shape[1]
                and by1 <= gy0 + grey.shape[0]
            ):
                return grey[by0 - gy0 : by1 - gy0, bx0 - gx0 : bx1 - gx0]
        roi = frame_bgr[by0 * k : by1 * k, bx0 * k : bx1 * k]
        gray = cv2.cvtColor(roi, cv2.COLOR_BGR2GRAY) if roi.ndim == 3 else roi
        if k > 1:
            gray = cv2.resize(gray, (bx1 - bx0, by1 - by0), interpolation=cv2.INTER_AREA)
        blocks = gray.astype(np.float32)
        blocks.flags.writeable = False
        if self._grey is None or blocks.size > self._grey[2].size:
            self._grey = (bx0, by0, blocks)
        return blocks

    def _to_work(self, u: float, v: float) -> tuple[float, float]:
        k = self.k
        return (u - (k - 1) / 2.0) / k, (v - (k - 1) / 2.0) / k

    def _to_full(self, qx: float, qy: float) -> tuple[float, float]:
        k = self.k
        return qx * k + (k - 1) / 2.0, qy * k + (k - 1) / 2.0

    def _upright(self, frame_bgr, u: float, v: float) -> np.ndarray | None:
        """The canonical-frame patch (side D) of the UUV centred at full-res (u, v), or None off the frame
        (read-only)."""
        key = ("upright", u, v, self._angle, self._scale)
        if key in self._looks:
            return self._looks[key]
        qx, qy = self._to_work(u, v)
        half = self._upright_half()
        bx0, by0 = int(qx) - half, int(qy) - half
        region = self._blocks(
            frame_bgr,
            max(bx0, 0),
            max(by0, 0),
            2 * half + 1 + min(bx0, 0),
            2 * half + 1 + min(by0, 0),
        )
        patch = None
        if region.shape[0] >= 4 and region.shape[1] >= 4:
            centre = (qx - max(bx0, 0), qy - max(by0, 0))
            patch = _warp(region, centre, self._angle, self._scale, self.D)
            patch.flags.writeable = False
        self._looks[key] = patch
        return patch

    def _spread(self, frame_bgr, u: float, v: float) -> float:
        """Standard deviation (grey levels) of the working-resolution square the template covers at full-res (u, v)."""
        key = ("spread", u, v, self._scale)
        if key in self._looks:
            return self._looks[key]
        qx, qy = self._to_work(u, v)
        half = max(1, round(self.S * self._scale) // 2)
        square = self._blocks(
            frame_bgr,
            max(round(qx) - half, 0),
            max(round(qy) - half, 0),
            2 * half + 1,
            2 * half + 1,
        )
        self._looks[key] = float(cv2.meanStdDev(square)[1][0, 0]) if square.size else 0.0
        return self._looks[key]

    def _contrast(self, frame_bgr, u: float, v: float) -> float:
        """The grey-level spread at (u, v) relative to the first appearance's (see :meth:`_spread`)."""
        return self._spread(frame_bgr, u, v) / max(self._first_spread, 1e-6)

    def _template(self, angle_deg: float, shrink: int = 1) -> np.ndarray:
        """The template at a heading and the current scale, block-averaged by ``shrink`` (cached until the next change).

        Its side is S, or the odd number of ``shrink`` × ``shrink`` blocks covering S
        (at least 5); its centre pixel is centred on the vehicle's.
        """
        key = (angle_deg, self._scale, shrink)
        if key not in self._cache:
            side = max(5, -(-self.S // shrink)) | 1 if shrink > 1 else self.S
            c = (self.D - 1) / 2.0
            t = _warp(self._canon, (c, c), -angle_deg, 1.0 / self._scale, side * shrink)
            if shrink > 1:
                t = cv2.resize(t, (side, side), interpolation=cv2.INTER_AREA)
            if len(self._cache) > 64:
                self._cache.clear()
            self._cache[key] = t
        return self._cache[key]

    # -- setup -----------------------------------------------------------------------------
    def start(self, frame_bgr, box, point=None, px_per_m: float = float("nan")) -> None:
        x, y, w, h = check_box(frame_bgr, box)
        self.k = max(1, round(max(w, h) / self.p.work_px))
        self.S = math.ceil(max(w, h) / self.k) | 1  # matching template side (odd)
        self.D = math.ceil(self.S * math.sqrt(2.0)) + 2 | 1  # canonical side: holds every rotation
        self._grey, self._looks = None, {}
        self._angle, self._scale = 0.0, 1.0
        # the heading the UUV was last seen at (a candidate's own may differ)
        self._seen_angle = 0.0
        self._ref_px_per_m = px_per_m
        self.u, self.v = point if point is not None else (x + (w - 1) / 2.0, y + (h - 1) / 2.0)
        self._cache: dict = {}
        self._canon = self._upright(frame_bgr, self.u, self.v)
        # the first appearance; compared: its core (the vehicle alone) ...
        self._first = self._canon.copy()
        self._core = max(5, round(self.p.core_share * self.S)) | 1
        self._first_turn = 0.0  # ... turned as the learnt template has turned from it
        self._firsts: dict = {}  # the core at turns (multiples of first_turn_step_deg)
        self._first_columns: dict = {}  # ... and the turns about each step's, ready for _ncc_maps
        self._first_spread = self._spread(frame_bgr, self.u, self.v)
        self._weights = self._polarity(frame_bgr, self.u, self.v)  # see _blob
        # the tracked point's offset from the box's centre (the vehicle's, e.g. its top face's seen obliquely)
        self._offset = (self.u - (x + (w - 1) / 2.0), self.v - (y + (h - 1) / 2.0))
        self._velocity = (0.0, 0.0)
        self._level = 1.0  # the recent level of the matches' scores (the first appearance's own, at first) ...
        self._levels = 0  # ... over this many matches
        self._candidate_contrast = 1.0  # the contrast of the last candidate (see _candidate_passes)
        # in waves: the contrasts of the candidate being confirmed, found by the search and again since
        self._candidate_contrasts: list[float] = []
        # the recent level of the matches' contrast (the first's own, at first)
        self._contrast_level = 1.0
        self._frames = 0
        self._mean_score = math.nan  # the follows' best scores' mean ...
        self._scatter2 = 0.0  # ... and mean square departure from it (see _waves) ...
        self._changes = 0  # ... over this many follows
        self._misses = 0  # follows in a row without a match
        self._recent: list[
            float
        ] = []  # in waves: the last follows' best scores (see _evidence) ...
        # ... and the water's level (the best score beside the UUV, a running mean)
        self._water = math.nan
        self._water_contrast = math.nan  # ... and the contrast there (a running mean)
        self._wavy = False  # judged as through waves (see _in_waves)

    def _begin(self, prediction: Prediction | None) -> None:
        """A new frame: follow the predicted apparent size relative to that at start (in steps of
        ``scale_step``; without a scale at start, the first prediction's is the reference)."""
        self._grey, self._looks = None, {}
        self.distinct = math.nan
        if prediction is None or not prediction.px_per_m > 0:
            return
        if not self._ref_px_per_m > 0:
            self._ref_px_per_m = prediction.px_per_m / self._scale
        scale = prediction.px_per_m / self._ref_px_per_m
        if abs(scale / self._scale - 1.0) > self.p.scale_step:
            self._scale = scale

    # -- matching ----------------------------------------------------------------------------
    def _region(self, frame_bgr, cu: float, cv_: float, radius_px: float, side: int):
        """Working-resolution window where a template of ``side`` may sit within ``radius_px`` of (cu, cv_)."""
        H, W = frame_bgr.shape[:2]
        qx, qy = self._to_work(cu, cv_)
        r = max(1, math.ceil(radius_px / self.k))
        half = (side - 1) // 2
        bx0, by0 = max(round(qx) - half - r, 0), max(round(qy) - half - r, 0)
        bx1 = min(round(qx) + half + r + 1, W // self.k)
        by1 = min(round(qy) + half + r + 1, H // self.k)
        if bx1 - bx0 < side + 1 or by1 - by0 < side + 1:
            return None, 0, 0
        return self._blocks(frame_bgr, bx0, by0, bx1 - bx0, by1 - by0), bx0, by0

    def _upright_half(self) -> int:
        """Half the side (working pixels) of the square :meth:`_upright` reads about its centre."""
        return math.ceil(self.D * self._scale * 0.75) + 2

    def _prepare(self, frame_bgr, cu: float, cv_: float, radius_px: float) -> None:
        """Convert at once what a search within ``radius_px`` of (cu, cv_) reads, what the
        refinement and the contrast check around its match read, and the upright patch about a match
        within :data:`_UPRIGHT_SLACK` of (cu, cv_) (see :meth:`_blocks`): one conversion a frame, not two."""
        qx, qy = self._to_work(cu, cv_)
        half = max(
            (self.S - 1) // 2 + max(1, math.ceil(radius_px / self.k) + 4),
            self._upright_half() + _UPRIGHT_SLACK,
        )
        bx0, by0 = max(round(qx) - half, 0), max(round(qy) - half, 0)
        self._blocks(frame_bgr, bx0, by0, round(qx) + half + 1 - bx0, round(qy) + half + 1 - by0)

    def _penalty(self, shape, x0: float, y0: float, step: float, prior) -> np.ndarray | None:
        """The distance penalty (see :data:`TemplateParams.distance_weight`) of a score map whose cell (i, j) puts
        the template's centre at working-resolution (x0 + j·step, y0 + i·step); None without a ``prior``."""
        if prior is None:
            return None
        cu, cv_, sigma_px = prior
        qx, qy = self._to_work(cu, cv_)
        s = sigma_px / self.k
        dx = (x0 + step * np.arange(shape[1], dtype=np.float32) - qx) / s
        dy = (y0 + step * np.arange(shape[0], dtype=np.float32) - qy) / s
        return (0.5 * self.p.distance_weight) * (dy[:, None] ** 2 + dx[None, :] ** 2)

    def _match_in(
        self, region, bx0: int, by0: int, template: np.ndarray, prior=None, spread: float = 0.0
    ):
        """(rank, score, u, v) of the template's best match in a working-resolution region (rank: the score less
        the distance penalty from ``prior`` = (u, v, sigma_px), full-resolution pixels; the score without one;
        places whose grey levels spread less than ``spread`` rank last). In waves both are smoothed first
        (:meth:`_blur_px`): the waves scramble the vehicle's fine structure, not its shape."""
        flat = _spread_map(region, template.shape[0]) < spread if spread > 0 else None
        if (sigma := self._blur_px()) > 0:
            region, template = (cv2.GaussianBlur(x, (0, 0), sigma) for x in (region, template))
        scores = cv2.matchTemplate(region, template, cv2.TM_CCOEFF_NORMED)
        half = (template.shape[0] - 1) / 2.0
        penalty = self._penalty(scores.shape, bx0 + half, by0 + half, 1.0, prior)
        if flat is not None:
            penalty = _FLAT_PENALTY * flat + (0.0 if penalty is None else penalty)
        rank, best, j, i = _peak(scores, penalty)
        u, v = self._to_full(bx0 + j + half, by0 + i + half)
        return rank, best, u, v

    def _refine(self, frame_bgr, found0):
        """Best heading near the match ``found0`` = (score, u, v) at the current heading: (score, u, v).

        Tries the heading ±``turn_step_deg``: a whole step only to one that matches better by
        ``turn_gain`` (a vehicle seen from above matches nearly as well a little turned: its
        heading would wander), keeps turning (up to ``max_turn_steps`` steps) while the score
        still improves; updates the heading.
        """
        step = self.p.turn_step_deg
        region, bx0, by0 = self._region(frame_bgr, found0[1], found0[2], 3.0 * self.k, self.S)
        if region is None:
            return found0

        def at(angle):
            return self._match_in(region, bx0, by0, self._template(angle))[1:]

        left, right = at(self._angle - step), at(self._angle + step)
        if found0[0] + self.p.turn_gain >= max(
            left[0], right[0]
        ):  # no clearly better heading: stay near this one
            self._angle += step * _parabola(left[0], found0[0], right[0])
            return found0
        direction, best = (-1.0, left) if left[0] > right[0] else (1.0, right)
        angle = self._angle + direction * step
        for _ in range(self.p.max_turn_steps - 1):
            further = at(angle + direction * step)
            if further[0] <= best[0]:
                break
            angle, best = angle + direction * step, further
        self._angle = angle
        return best

    def _search(
        self,
        frame_bgr,
        cu: float,
        cv_: float,
        radius_px: float,
        angles,
        sigma_px: float = math.nan,
        spread: float = 0.0,
    ):
        """Best (score, u, v, angle) over headings within ``radius_px`` of (cu, cv_).

        With a finite ``sigma_px`` the best is the one whose score less its distance
        penalty from (cu, cv_) is highest (see :data:`TemplateParams.distance_weight`);
        places whose grey levels spread less than ``spread`` (see :meth:`_spread`) rank last.
        A window wider than ``coarse_side`` is first searched block-averaged (the
        template about ``coarse_px`` across); the ``coarse_keep`` best places
        found there are matched again at working resolution, and the best of those counts.
        """
        prior = (cu, cv_, sigma_px) if sigma_px > 0 else None
        region, bx0, by0 = self._region(frame_bgr, cu, cv_, radius_px, self.S)
        if region is None:
            return -1.0, math.nan, math.nan, self._angle
        if max(region.shape) <= self.p.coarse_side:
            best = max(
                (*self._match_in(region, bx0, by0, self._template(a), prior, spread), a)
                for a in angles
            )
            return best[1:]
        flat = _spread_map(region, self.S) < spread if spread > 0 else None
        f = max(2, self.S // self.p.coarse_px)
        h, w = region.shape[0] // f, region.shape[1] // f
        small = cv2.resize(region[: h * f, : w * f], (w, h), interpolation=cv2.INTER_AREA)
        places = []  # (coarse rank, working-resolution x, y of the template's centre, heading)
        for a in angles:
            t = self._template(a, shrink=f)
            if t.shape[0] < min(h, w):
                scores = cv2.matchTemplate(small, t, cv2.TM_CCOEFF_NORMED)
                half = (t.shape[0] - 1) / 2.0
                # the first cell's centre, working pixels from the region's corner
                c = half * f + (f - 1) / 2.0
                penalty = self._penalty(scores.shape, bx0 + c, by0 + c, float(f), prior)
                if flat is not None:  # the full-resolution places nearest the cells' centres
                    at = [
                        np.clip(np.round(c + f * np.arange(n) - (self.S - 1) / 2.0), 0, m - 1)
                        for n, m in zip(scores.shape, flat.shape)
                    ]
                    low = flat[np.ix_(at[0].astype(int), at[1].astype(int))]
                    penalty = _FLAT_PENALTY * low + (0.0 if penalty is None else penalty)
                r, _, j, i = _peak(scores, penalty)
                places.append((r, c + j * f, c + i * f, a))
        best = (-math.inf, -1.0, math.nan, math.nan, self._angle)
        kept: list[tuple[float, float]] = []
        for _, x, y, a in sorted(places, reverse=True):
            if len(kept) == self.p.coarse_keep:
                break
            if any(math.hypot(x - kx, y - ky) < self.S / 2.0 for kx, ky in kept):
                continue  # the same place at another heading
            kept.append((x, y))
            r = (self.S - 1) // 2 + f + 1  # the template may sit within f + 1 of the coarse place
            x0, y0 = max(round(x) - r, 0), max(round(y) - r, 0)
            window = region[y0 : round(y) + r + 1, x0 : round(x) + r + 1]
            if min(window.shape) > self.S:
                found = (
                    *self._match_in(window, bx0 + x0, by0 + y0, self._template(a), prior, spread),
                    a,
                )
                best = max(best, found)
        return best[1:]

    def _first_core(self, turn_deg: float) -> np.ndarray:
        """The first appearance's core turned by ``turn_deg`` (a multiple of ``first_turn_step_deg``; cached)."""
        key = round(turn_deg / self.p.first_turn_step_deg) % round(
            360.0 / self.p.first_turn_step_deg
        )
        if key not in self._firsts:
            c = (self.D - 1) / 2.0
            self._firsts[key] = _warp(
                self._first, (c, c), key * self.p.first_turn_step_deg, 1.0, self._core
            )
        return self._firsts[key]

    def _first_cores(self, centre: int) -> tuple[list[float], np.ndarray]:
        """The turns within ``first_turn_deg`` of ``centre`` steps of ``first_turn_step_deg``, and the first
        appearance's cores at them (see :meth:`_first_core`) as the columns of one matrix, each less its mean and
        divided by its norm (float64): the templates of :func:`_ncc_maps`. Cached by ``centre``."""
        if centre not in self._first_columns:
            step = self.p.first_turn_step_deg
            n = round(self.p.first_turn_deg / step)
            turns = [step * (centre + j) for j in range(-n, n + 1)]
            cores = np.stack(
                [self._first_core(a).ravel().astype(np.float64) for a in turns], axis=1
            )
            cores -= cores.mean(axis=0)
            norms = np.linalg.norm(cores, axis=0)
            columns = np.divide(cores, norms, out=np.zeros_like(cores), where=norms > 0)
            self._first_columns[centre] = (turns, columns)
        return self._first_columns[centre]

    def _first_at(self, upright: np.ndarray) -> tuple[float, float, float] | None:
        """Where an upright canonical image (side D) shows the UUV's first appearance: ``(dx, dy, turn_deg)``, its
        offset from the centre (working pixels) and the turn that matches it best (within ``first_turn_deg`` of
        the learnt template's), or None when it is not there (NCC below ``anchor_score``) or further than
        ``anchor_drift`` of the template's side (the image's centre has drifted off the place the first appearance
        was tracked at)."""
        core = self._core
        m = min(self.p.anchor_shift_px, (self.D - core) // 2)
        lo = (self.D - core) // 2 - m
        window = upright[lo : lo + core + 2 * m, lo : lo + core + 2 * m]
        step = self.p.first_turn_step_deg
        turns, columns = self._first_cores(round(self._first_turn / step))
        maps = _ncc_maps(window, columns, core)
        tops = maps.reshape(len(turns), -1).max(axis=1)
        j = int(np.argmax(tops))
        _, score, dx, dy = _peak(maps[j])
        turn = turns[j] + (
            step * _parabola(tops[j - 1], score, tops[j + 1]) if 0 < j < len(turns) - 1 else 0.0
        )
        dx, dy = dx - m, dy - m
        if score < self.p.anchor_score:
            return None
        if math.hypot(dx, dy) <= max(self.p.anchor_drift * self.S, self.p.anchor_drift_px):
            return dx, dy, turn
        # further off: a drift, unless the first appearance matches (nearly) as well at the centre (a hull's
        # uniform middle matches all along itself)
        return (0.0, 0.0, turn) if maps[j][m, m] >= score - self.p.anchor_level else None

    def _learn(self, frame_bgr, u: float, v: float) -> None:
        """Blend the upright patch (a match :meth:`_visible` passed) into the template, held on the first appearance.

        The template may follow the UUV's lighting, depth and the side it shows, never
        slide onto something else: a blend after which it would no longer show the
        first appearance at its centre (:meth:`_first_at`) is refused. Each blend may
        be off by a fraction of a pixel; summed, that would slide the template off the
        vehicle: the learnt template's offset from the first appearance is undone
        whenever it exceeds ``recentre_px``.
        """
        patch = self._upright(frame_bgr, u, v)
        if patch is None or self._contrast(frame_bgr, u, v) < self.p.learn_contrast:
            return  # fading (deep, turbid water): keep the vehicle's structure rather than learn the noise
        canon = cv2.accumulateWeighted(patch, self._canon.copy(), self.p.learn_rate)
        held = self._first_at(canon)
        if held is None:
            return
        dx, dy, self._first_turn = held
        if math.hypot(dx, dy) > self.p.recentre_px:
            M = np.array([[1.0, 0.0, -dx], [0.0, 1.0, -dy]])
            canon = cv2.warpAffine(
                canon, M, (self.D, self.D), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
            )
        self._canon = canon
        self._cache.clear()

    # -- waves ------------------------------------------------------------------------------
    def _note_score(self, score: float) -> None:
        """Count a follow's best score in the scatter :meth:`_waves` reads: its departure from the last few scores'
        mean (up to ``wobble_cap``); both running means over the first follows, then moving averages."""
        self._changes += 1
        if math.isfinite(self._mean_score):
            change = min(abs(score - self._mean_score), self.p.wobble_cap)
            self._scatter2 += max(self.p.wobble_rate, 1.0 / self._changes) * (
                change * change - self._scatter2
            )
            self._mean_score += max(self.p.wobble_mean_rate, 1.0 / self._changes) * (
                score - self._mean_score
            )
        else:
            self._mean_score = score

    def _waves(self) -> float:
        """How far the matches wobble as through waves: 0 (a still surface: the bars as set) to 1 (the whole wave
        tolerance), from the follow scores' frame-to-frame scatter between ``wobble_flat`` and ``wobble_waves``.
        A still surface's scatter is the sensor's and the codec's noise; waves move the vehicle's image from one
        frame to the next, so its score jumps (a loss drops it once, counted up to ``wobble_cap``)."""
        scatter = math.sqrt(self._scatter2)
        return min(
            1.0,
            max(0.0, (scatter - self.p.wobble_flat) / (self.p.wobble_waves - self.p.wobble_flat)),
        )

    def _whole(self, frame_bgr, u: float, v: float) -> bool:
        """Whether the template's square at (u, v) lies inside the frame. The sea state is read only from follows
        whose vehicle is sought and found wholly in view: one cut by the frame's edge (drifting out of view and back
        with the camera's wobble) scores low from frame to frame as through waves, on a still surface too, and the
        waves' looser bars and the reported pixel's steer (:mod:`.centroid`) would then apply."""
        half = self.S * self.k * self._scale / 2.0
        rows, cols = frame_bgr.shape[:2]
        return half <= u <= cols - 1 - half and half <= v <= rows - 1 - half

    def waves(self) -> float:
        """The :class:`~localizer.tracking.Matcher`'s reading of the sea state: :meth:`_waves`."""
        return self._waves()

    def _in_waves(self) -> bool:
        """Whether the UUV is judged as seen through waves (:meth:`_stands_out`): from when :meth:`_waves` reaches
        ``wave_mode`` until it is nil again (the scatter eases as the template learns the wave-distorted mean)."""
        waves = self._waves()
        self._wavy = waves >= self.p.wave_mode or (self._wavy and waves > 0.0)
        return self._wavy

    def _blur_px(self) -> float:
        """The smoothing (working pixels, Gaussian sigma, in quarters) of images and template before matching."""
        return round(4.0 * self.p.wave_blur_px * self._waves()) / 4.0

    def _ok(self) -> float:
        """The least NCC that passes for the UUV: ``ok_score``, lower in waves."""
        return self.p.ok_score - self._waves() * self.p.wave_ok_drop

    def _candidate(self) -> float:
        """The least NCC a search's best (before refining) needs to be judged as a candidate: :meth:`_ok`; in waves
        no more than the bar a candidate must reach (:meth:`_stands_out`'s ``wave_reacquire_share`` of the way from
        the water's level to the UUV's): a UUV the waves let the template match no better than that is judged as
        the candidate bars judge it, not refused before."""
        if not self._wavy:
            return self._ok()
        return min(self._ok(), self._wave_bar(self.p.wave_reacquire_share))

    def _floor(self) -> float:
        """The least NCC a match near the prediction needs: :meth:`_ok`, and no more than ``level_drop`` (more in
        waves) below the recent level."""
        return max(
            self._ok(), self._level - self.p.level_drop - self._waves() * self.p.wave_level_drop
        )

    def _far(self) -> float:
        """The least NCC a candidate found while lost needs: ``reacquire_score`` and within ``reacquire_below_level``
        of the recent level (both eased in waves)."""
        waves = self._waves()
        return max(
            self.p.reacquire_score - waves * self.p.wave_ok_drop,
            self._level - self.p.reacquire_below_level - waves * self.p.wave_level_drop,
        )

    def _rebound(self) -> float:
        """The least NCC a match near the prediction needs after frames without one: :meth:`_floor` on a still
        surface (lost a moment ago: nothing else fits where it can be), nearer :meth:`_far` the more the waves make
        a single frame's score ambiguous (a loss is what outlasted the held frames; the water where the UUV was
        may match as well as it did at its worst)."""
        close = self._floor()
        return close + self._waves() * max(self._far() - close, 0.0)

    def _least_contrast(self, share: float | None = None, between: float | None = None) -> float:
        """In waves, the least contrast (see :meth:`_contrast`) that passes for the UUV: ``min_contrast``, and
        ``share`` (``wave_contrast_share``) of the level of the frames it was followed in (the water and the
        seafloor the template finds where it is hidden, or beside it, have a fraction of its grey-level spread) or,
        when lower, ``between`` (``wave_contrast_between``) of the way from the contrast of the water beside it
        to that level (a UUV whose contrast flickers far above the water's: its dim frames pass)."""
        level = self._contrast_level
        share = self.p.wave_contrast_share if share is None else share
        between = self.p.wave_contrast_between if between is None else between
        bar = self._water_contrast + between * (level - self._water_contrast)
        return max(self.p.min_contrast, min(share * level, bar if math.isfinite(bar) else level))

    def _least_spread(self) -> float:
        """In waves, the grey-level spread (see :meth:`_spread`) below which a place is not searched for a candidate
        (:meth:`_least_contrast`); 0 on a still surface."""
        return self._least_contrast() * self._first_spread if self._wavy else 0.0

    def _beside(
        self, frame_bgr, cu: float, cv_: float, radius: float, spread: float = 0.0
    ) -> list[tuple[float, float]]:
        """The template's best scores on the water beside the prediction's window, and the contrast there (see
        :meth:`_contrast`): in windows as large, ``wave_background_sides`` template sides further out on each side
        (those inside the frame); with a ``spread``, at places whose grey levels spread at least that much (see
        :meth:`_search`; none: no score)."""
        d = radius + self.p.wave_background_sides * self.S * self.k * self._scale
        found = (
            self._search(frame_bgr, cu + du, cv_ + dv, radius, (self._angle,), spread=spread)
            for du, dv in ((d, 0.0), (-d, 0.0), (0.0, d), (0.0, -d))
        )
        return [
            (s, self._contrast(frame_bgr, u, v))
            for s, u, v, _ in found
            if s > -1.0 and (spread <= 0 or self._spread(frame_bgr, u, v) >= spread)
        ]

    def _matched(self) -> float:
        """The recent level of the UUV's matches; before any, the follows' mean score (the first appearance's own
        1.0 is not what the waves let it reach)."""
        return self._level if self._levels else self._mean_score

    def _wave_bar(self, share: float) -> float:
        """In waves, an NCC ``share`` of the way from the water's level to the recent level of the UUV's matches
        (:meth:`_floor` until the water's level is known; before any match, the follows' mean score: the first
        appearance's own 1.0 is not what the waves let it reach)."""
        level = self._matched()
        return (
            self._water + share * (level - self._water)
            if math.isfinite(self._water)
            else self._floor()
        )

    def _stands_out(
        self,
        frame_bgr,
        cu: float,
        cv_: float,
        radius: float,
        score: float,
        evidence: float | None = None,
        again: bool = False,
    ) -> bool:
        """In waves: whether the UUV is in the window of ``radius`` about (cu, cv_) whose best score is ``score``.
        Its best stands out of the water beside the window (:meth:`_beside`). A follow (``evidence``: the mean of
        the last ``wave_evidence_frames`` scores; one frame's does not tell, the wave-distorted UUV's falls at times
        as low as the water's best) keeps the water's level from the water beside; ``score`` reaches
        ``wave_follow_share`` and ``evidence`` ``wave_evidence_share`` of the way from the water's level to the
        UUV's (:meth:`_wave_bar`). A candidate while lost: ``wave_reacquire_share``; found ``again`` where it was
        expected (confirmed in the window of a follow): ``wave_confirm_share``. A UUV just hidden leaves the
        water in the window, which stands out of the water beside it no more than by chance."""
        beside = self._beside(
            frame_bgr, cu, cv_, radius, self._least_spread() if evidence is None else 0.0
        )
        scores = [s for s, _ in beside]
        if beside and evidence is not None:
            water, flat = (float(np.median(x)) for x in zip(*beside, strict=True))
            self._water = _running(self._water, water, self.p.wave_background_rate)
            self._water_contrast = _running(self._water_contrast, flat, self.p.wave_background_rate)
        if evidence is None:
            share = self.p.wave_confirm_share if again else self.p.wave_reacquire_share
            passed = score >= self._wave_bar(share)
        else:
            passed = score >= self._wave_bar(self.p.wave_follow_share) and (
                evidence >= self._wave_bar(self.p.wave_evidence_share)
            )
        return passed and (not scores or score > float(np.median(scores)))

    def _departures(self, frame_bgr, u: float, v: float, half: int):
        """The working-resolution square of side 2·``half`` + 1 about full-res (u, v): its darker and brighter
        departures from the seafloor's grey level (the square's median), and its corner (bx0, by0); None where it
        leaves the frame."""
        qx, qy = self._to_work(u, v)
        bx0, by0 = round(qx) - half, round(qy) - half
        # checked before reading: a negative slice would wrap or come out empty
        if bx0 < 0 or by0 < 0:
            return None
        region = self._blocks(frame_bgr, bx0, by0, 2 * half + 1, 2 * half + 1)
        if region.shape != (2 * half + 1, 2 * half + 1):
            return None
        away = region - float(np.median(region))
        return np.maximum(-away, 0.0), np.maximum(away, 0.0), bx0, by0

    def _box(self) -> int:
        """The side (working pixels, odd) of the vehicle-sized square: ``wave_centre_share`` of the template's."""
        return max(3, round(self.p.wave_centre_share * self.S * self._scale)) | 1

    def _polarity(self, frame_bgr, u: float, v: float) -> tuple[float, float]:
        """How much the vehicle at (u, v) departs from the seafloor darker and brighter beyond the seafloor's own
        departures (its vehicle-sized square's mean departure less that of the square outside the template's, in a
        square twice the template's side), each at least 0: the weights of :meth:`_blob` (caustics and glint
        brighten the seafloor; a dark hull stands out as darker)."""
        inner = max(1, round(self.S * self._scale) // 2)
        found = self._departures(frame_bgr, u, v, 2 * inner)
        if found is None:
            return 0.0, 0.0
        *maps, _, _ = found
        half, box = 2 * inner, self._box()
        outside = np.ones(maps[0].shape, bool)
        outside[half - inner : half + inner + 1, half - inner : half + inner + 1] = False
        core = slice(half - box // 2, half + box // 2 + 1)
        return tuple(max(0.0, float(m[core, core].mean() - m[outside].mean())) for m in maps)

    def _blob(self, frame_bgr, u: float, v: float) -> tuple[float, float, float] | None:
        """The vehicle standing out of the seafloor near (u, v): the vehicle-sized square (:meth:`_box`) within
        ``wave_centre_reach`` of the template's side of it whose grey levels depart most from the seafloor's as the
        vehicle's first appearance did (:meth:`_polarity`); its centre (full-res) and how distinct it is: its
        mean departure over the 90th percentile of the squares' beyond three quarters of the template's side
        about (u, v). None where that leaves the frame or the first appearance did not depart."""
        side, box = round(self.S * self._scale), self._box()
        reach = max(1, round(self.p.wave_centre_reach * side))
        found = self._departures(frame_bgr, u, v, side + box // 2 + 1)
        if found is None or not sum(self._weights) > 0:
            return None
        darker, brighter, bx0, by0 = found
        away = cv2.blur(self._weights[0] * darker + self._weights[1] * brighter, (box, box))
        half, edge, inner = away.shape[0] // 2, box // 2, round(0.75 * side)
        _, best, j, i = _peak(
            away[half - reach : half + reach + 1, half - reach : half + reach + 1]
        )
        floor = np.zeros(away.shape, bool)
        floor[edge:-edge, edge:-edge] = True
        floor[half - inner : half + inner + 1, half - inner : half + inner + 1] = False
        distinct = best / max(float(np.percentile(away[floor], 90)), 1e-6)
        return (*self._to_full(bx0 + half + j - reach, by0 + half + i - reach), distinct)

    def _centred(
        self,
        frame_bgr,
        u: float,
        v: float,
        blob: tuple[float, float, float] | None,
        predicted: tuple[float, float] | None = None,
    ) -> tuple[float, float]:
        """In waves, a followed match (u, v) moved ``wave_centre_pull`` of the way onto the vehicle standing out of
        the seafloor near it (``blob``: :meth:`_blob` at (u, v); :meth:`_on_vehicle`; the smoothed template matches
        about as well with the vehicle in a corner of its square as at its centre). A follow that passed on its
        contrast alone (``predicted``: the prediction it was searched about; its score under the follow bar, the
        template does not tell where in the window the vehicle is) and whose match lies beyond the square of the
        vehicle standing out near the prediction is moved onto that vehicle instead (the match slides over
        the seafloor beside it)."""
        found = self._on_vehicle(blob)
        if (
            predicted is not None
            and (there := self._on_vehicle(self._blob(frame_bgr, *predicted))) is not None
        ):
            half = self._box() * self.k / 2.0
            if max(abs(u - there[0]), abs(v - there[1])) > half:
                return there
        if found is None:
            return u, v
        pull = self.p.wave_centre_pull
        return u + pull * (found[0] - u), v + pull * (found[1] - v)

    def _teaches(self, blob: tuple[float, float, float] | None) -> bool:
        """In waves, whether a follow may teach the template: the vehicle-sized square standing out most near its
        match (``blob``: :meth:`_blob` there) departs from the seafloor at least ``wave_learn_distinct`` times as
        much as 9 in 10 of the seafloor's squares. Where nothing stands out of the seafloor more than its own
        places do, the match is on a patch of seafloor beside the vehicle (or on a vehicle the waves hid in it)."""
        return blob is not None and blob[2] >= self.p.wave_learn_distinct

    def _on_vehicle(self, blob: tuple[float, float, float] | None) -> tuple[float, float] | None:
        """The tracked point on the vehicle standing out of the seafloor (``blob``: :meth:`_blob`) where it is at
        least ``wave_centre_distinct``: kept where it was on the vehicle at start (its offset from the box's
        centre, turned and scaled as the template); None where no vehicle stands out so."""
        if blob is None or blob[2] < self.p.wave_centre_distinct:
            return None
        a = math.radians(self._angle)
        ox, oy = self._offset
        c, s_ = self._scale * math.cos(a), self._scale * math.sin(a)
        return blob[0] + c * ox - s_ * oy, blob[1] + s_ * ox + c * oy

    # -- per frame ---------------------------------------------------------------------------
    def _radius(self, prediction: Prediction | None, fallback: float) -> float:
        if prediction is None or not math.isfinite(prediction.sigma_px):
            return fallback
        return max(self.p.min_radius_px, self.p.search_sigmas * prediction.sigma_px)

    def _visible(self, frame_bgr, u: float, v: float, either_way: bool = False) -> bool:
        """Whether the patch at (u, v) stands out of the water (at least ``min_contrast``, see :meth:`_contrast`)
        and, when it is clear enough to tell (``check_contrast``), shows the UUV's first appearance there
        (:meth:`_first_at`: not a drift onto something else). ``either_way`` (a candidate found by a search): a
        vehicle looks much the same end for end, so the heading may be half a turn off; it is turned round then."""
        contrast = self._contrast(frame_bgr, u, v)
        if contrast < self.p.check_contrast:
            # fading into the water: its structure is lost, the template judges
            return contrast >= self.p.min_contrast
        patch = self._upright(frame_bgr, u, v)
        if patch is not None and self._first_at(patch) is not None:
            return True
        if not either_way:
            return False
        self._angle += 180.0
        if (patch := self._upright(frame_bgr, u, v)) is not None and self._first_at(
            patch
        ) is not None:
            return True
        self._angle -= 180.0
        return False

    def _match(self, found: bool, score: float, u: float, v: float) -> Match:
        side = round(self.S * self.k * self._scale)
        box = (
            (round(u - (side - 1) / 2.0), round(v - (side - 1) / 2.0), side, side)
            if found
            else None
        )
        return Match(found, score, u, v, box)

    def follow(self, frame_bgr, prediction: Prediction | None) -> Match:
        self._begin(prediction)
        if prediction is not None:
            cu, cv_ = prediction.u, prediction.v
        else:
            cu, cv_ = self.u + self._velocity[0], self.v + self._velocity[1]
        radius = self._radius(prediction, self.p.default_radius_px)
        self._prepare(frame_bgr, cu, cv_, radius)
        score, u, v, _ = self._search(
            frame_bgr, cu, cv_, radius, (self._angle,), radius / self.p.search_sigmas
        )
        self._frames += 1
        slow_step = self._frames % self.p.adapt_every == 0
        if slow_step or score < self._level - self.p.turn_drop:
            score, u, v = self._refine(frame_bgr, (score, u, v))
        in_waves = self._in_waves()
        # after a held frame: convincingly back
        floor = self._floor() if not self._misses else self._rebound()
        if self._whole(frame_bgr, cu, cv_) and self._whole(frame_bgr, u, v):
            self._note_score(score)
        self._recent = (self._recent + [score])[-self.p.wave_evidence_frames :]
        near = math.hypot(u - cu, v - cv_) <= radius + 2 * self.k
        contrast = self._contrast(frame_bgr, u, v)
        clear = contrast >= self.p.wave_keep_contrast * self._contrast_level
        # passed on its contrast alone (its score under the follow bar)
        kept = False
        if in_waves:
            passed = (
                near
                and contrast >= self._least_contrast()
                and self._stands_out(
                    frame_bgr, cu, cv_, radius, score, float(np.mean(self._recent))
                )
            )
            kept = not passed and (
                near
                and contrast
                >= self._least_contrast(self.p.wave_keep_contrast, self.p.wave_keep_between)
                and score
                > max(self._water - self.p.wave_keep_below, self._matched() - self.p.wave_keep_drop)
            )
            passed = passed or kept
        else:
            passed = score >= floor and near and self._visible(frame_bgr, u, v)
        self._contrast_level += (
            self.p.wave_contrast_rate * (passed and clear) * (contrast - self._contrast_level)
        )
        if not passed:
            self._misses += 1
            # the first follows: the sea state not yet told
            young = self._changes <= self.p.wave_evidence_frames
            if in_waves and not near:
                # the match climbed out of the window onto something beside it: the prediction's place is held
                # while it stands out as the UUV does
                contrast = self._contrast(frame_bgr, cu, cv_)
                near = contrast >= self._least_contrast()
            misses = (
                self.p.wave_hold_misses
                if in_waves and contrast >= self._least_contrast(1.0, self.p.wave_hold_between)
                else self.p.wave_misses
            )
            held = near and self._misses <= misses * max(self._waves(), float(young))
            return Match(False, score, u, v, held=held)
        self._misses = 0
        # the template's own match: what it learns (the centring below jitters with the waves)
        matched_at = (u, v)
        # the vehicle standing out near the template's match: where the follow is centred, whether it teaches
        blob = self._blob(frame_bgr, u, v) if in_waves else None
        if blob is not None:
            self.distinct = blob[2]
        if in_waves:
            u, v = self._centred(frame_bgr, u, v, blob, (cu, cv_) if kept else None)
        self._velocity = (u - self.u, v - self.v) if prediction is None else (0.0, 0.0)
        self.u, self.v, self._seen_angle = u, v, self._angle
        self._levels += 1
        self._level += max(0.1, 1.0 / self._levels) * (
            score - self._level
        )  # a running mean over the first ones
        if (
            (clear or not in_waves)
            and score >= self.p.update_score - self._waves() * self.p.wave_update_drop
            and slow_step
            and (not in_waves or self._teaches(blob))
        ):
            self._learn(frame_bgr, *matched_at)
        return self._match(True, score, u, v)

    def _candidate_passes(
        self,
        frame_bgr,
        score: float,
        u: float,
        v: float,
        prediction: Prediction | None,
        window: tuple[float, float, float],
        again: bool = False,
    ) -> Match:
        """A candidate while lost, the best found in ``window`` (u, v, radius): the re-acquisition's bar, or the bar
        of :meth:`follow` when the prediction's window is no wider than the vehicle (lost a moment ago: nothing else
        fits where it can be). In waves: it stands out of the water beside the window (:meth:`_stands_out`; found
        ``again`` where it was expected: a lower bar) with the UUV's contrast (:meth:`_least_contrast`), and found
        ``again`` its contrast averaged over the frames it was found in is ``wave_keep_contrast`` of the UUV's. Its
        contrast is the UUV's level once it is confirmed on a still surface (:meth:`resume`: it may have faded or
        cleared meanwhile)."""
        contrast = self._candidate_contrast = self._contrast(frame_bgr, u, v)
        if self._wavy:
            self._candidate_contrasts = (self._candidate_contrasts if again else []) + [contrast]
            passed = contrast >= self._least_contrast() and self._stands_out(
                frame_bgr, *window, score, again=again
            )
            passed = passed or (
                again
                and contrast >= self.p.wave_keep_contrast * self._contrast_level
                and score > self._water - self.p.wave_keep_below
            )
            # one frame's contrast flickers (caustics); the seafloor's, averaged, has a fraction of the UUV's
            steady = float(np.mean(self._candidate_contrasts)) >= (
                self.p.wave_keep_contrast * self._contrast_level
            )
            return self._match(passed and (steady or not again), score, u, v)
        side = self.S * self.k * self._scale
        if prediction is not None and self._radius(prediction, math.inf) <= side:
            need = self._rebound()
        else:
            need = self._far()
        return self._match(
            bool(score >= need and self._visible(frame_bgr, u, v, either_way=True)), score, u, v
        )

    def confirm(self, frame_bgr, u: float, v: float, prediction: Prediction | None) -> Match:
        self._begin(prediction)
        tol = self.p.reacquire_tolerance * self.S * self.k * self._scale + self.k
        self._prepare(frame_bgr, u, v, tol)
        window = (u, v, tol)
        score, u, v, _ = self._search(
            frame_bgr, u, v, tol, (self._angle,), tol / self.p.search_sigmas, self._least_spread()
        )
        if score >= self._ok():
            score, u, v = self._refine(frame_bgr, (score, u, v))
        candidate = self._candidate_passes(frame_bgr, score, u, v, prediction, window, again=True)
        if (
            candidate.found
            and prediction is not None
            and self._still_there(frame_bgr, prediction, self._seen_angle, u, v)
        ):
            return self._match(False, score, u, v)
        return candidate

    def resume(self, match: Match) -> None:
        self._velocity = (0.0, 0.0)
        self._misses = 0
        self._recent = [match.score]
        self.u, self.v, self._seen_angle = match.u, match.v, self._angle
        if (
            not self._wavy
        ):  # in waves a candidate's contrast is one frame's (caustics, break-up): the level stays
            self._contrast_level = self._candidate_contrast

    def search(self, frame_bgr, prediction: Prediction | None) -> Match:
        """Best match over every heading in the prediction's window (the whole frame without one)."""
        self._begin(prediction)
        H, W = frame_bgr.shape[:2]
        if prediction is not None and math.isfinite(prediction.sigma_px):
            cu, cv_, radius = prediction.u, prediction.v, self._radius(prediction, float(max(W, H)))
            sigma = radius / self.p.search_sigmas
        else:
            cu, cv_, radius, sigma = W / 2.0, H / 2.0, float(max(W, H)), math.nan
        n = self.p.reacquire_headings
        turn = (
            prediction.turn_deg if prediction is not None and prediction.turn_deg < 180.0 else 180.0
        )
        self._angle = self._seen_angle  # not a candidate's that did not confirm
        if (
            turn < 90.0
        ):  # only the headings it can have turned to since it was seen (either way round: it looks
            #              much the same end for end), as far apart as at most
            m = math.ceil(2.0 * turn * n / 360.0) + 1
            angles = [
                self._angle + flip - turn + 2.0 * turn * j / (m - 1)
                for flip in (0.0, 180.0)
                for j in range(m)
            ]
        else:
            angles = [self._angle + 360.0 * j / n for j in range(n)]
        score, u, v, angle = self._search(
            frame_bgr, cu, cv_, radius, angles, sigma, self._least_spread()
        )
        if score < self._candidate():  # not even one (headings are coarse here: refined below)
            return self._match(False, score, u, v)
        saved, self._angle = self._angle, angle
        score, u, v = self._refine(frame_bgr, (score, u, v))
        far = self._far_penalty(u - cu, v - cv_, sigma)
        candidate = self._candidate_passes(
            frame_bgr, score - far, u, v, prediction, (cu, cv_, radius)
        )
        candidate = self._match(candidate.found, score, u, v)
        if (
            abs((self._angle - saved + 90.0) % 180.0 - 90.0) > turn
        ):  # a heading it cannot have turned to (either
            #                                                           way round): something else
            candidate = self._match(False, score, u, v)
        if (
            candidate.found
            and prediction is not None
            and self._still_there(frame_bgr, prediction, saved, u, v)
        ):
            # a look-alike beside the UUV, which is partly hidden
            candidate = self._match(False, score, u, v)
        if not candidate.found:
            self._angle = saved
        return candidate

    def _far_penalty(self, du: float, dv: float, sigma_px: float) -> float:
        """In waves, what a candidate (du, dv) pixels from the prediction of 1-sigma ``sigma_px`` (NaN: none) must
        score beyond its bar: the distance penalty (``distance_weight``) of its sigmas beyond ``wave_far_sigmas``.
        The search ranks by that penalty, but in a wide window the UUV's hidden place leaves only water and
        seafloor, whose best patch may lie near the window's edge; 0 on a still surface."""
        if not (self._wavy and sigma_px > 0):
            return 0.0
        beyond = max(0.0, math.hypot(du, dv) / sigma_px - self.p.wave_far_sigmas)
        return 0.5 * self.p.distance_weight * beyond * beyond

    def _still_there(
        self, frame_bgr, prediction: Prediction, angle: float, u: float, v: float
    ) -> bool:
        """Whether a candidate at (u, v), away from the prediction, has the UUV itself beside it: its first
        appearance, at the heading it was last seen at, where the prediction has it (partly hidden, say by a
        vehicle passing over it, it matches the template less well than the look-alike does)."""
        side = self.S * self.k * self._scale
        if math.hypot(u - prediction.u, v - prediction.v) <= max(
            self.p.reacquire_tolerance * side, prediction.sigma_px
        ):
            return False
        found, self._angle = self._angle, angle
        patch = self._upright(frame_bgr, prediction.u, prediction.v)
        self._angle = found
        if patch is None:
            return False
        scores = cv2.matchTemplate(patch, self._first_core(self._first_turn), cv2.TM_CCOEFF_NORMED)
        _, best, _, (j, i) = cv2.minMaxLoc(scores)
        c = (
            scores.shape[0] - 1
        ) / 2.0  # the prediction's place; the candidate is further than the patch reaches
        return best >= self.p.there_score and math.hypot(j - c, i - c) * self.k < 0.5 * math.hypot(
            u - prediction.u, v - prediction.v
        )

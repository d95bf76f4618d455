"""How sure the tracked pixel is: the 1-sigma of each of u and v, from what the tracker saw.

A template match is as precise as the template is large and as well as it matches: its
error is a share of the vehicle's apparent length that grows as the match score falls.
On top of that, a match is only as sure as the place it was sought in: a UUV found in a
wide window (frames skipped, a loss, a re-acquisition) may be a look-alike the window
held, most of all just after it was (re)acquired, until it has moved as the UUV does for
a while. :func:`pixel_sigma_px` adds these terms in quadrature:

- the match: ``length_px × √(MATCH_SHARE² + (SCORE_SHARE × (1 − score))²)``, at least
  ``FLOOR_PX`` (sub-pixel interpolation, the video's compression); a tracker without a
  score (OpenCV's KCF, CSRT: whole-pixel boxes of a fixed size that wander over the
  vehicle) ``UNSCORED_SHARE × length_px``;
- the window: ``WINDOW_SHARE`` × the prediction's 1-sigma beyond that of a frame that
  follows the previous one (``window_px - length_px × TRACKING_WINDOW``, at least 0),
  where ``window_px`` is the prediction's 1-sigma the match was sought with
  (:class:`~localizer.tracking.Prediction`; it grows with the frames skipped since the last
  match);
- the (re)acquisition: ``ACQUIRED_SHARE × length_px``, fading with the time since the UUV
  was (re)acquired (``ACQUIRED_S``, e-folding);
- a restart by colour not yet proven (through waves: the track restarted where the vehicle's colour stood out, not
  yet held long enough to stand, :data:`~localizer.tracking.session.COLOUR_PROVEN_FRAMES`): its place is the
  colour's, not a match's, ``UNSCORED_SHARE × length_px``; and where it is a place of the seafloor that shows the
  vehicle's colour for a few frames, the UUV is where it was sought: ``RESTART_SHARE`` × the restart's distance from
  there;
- the selection: a target skyfix outlined itself (a click, a live box snapped to the object in
  it, or the UUV's own position estimate: :func:`~localizer.tracking.detect.outline`) carries
  the outline's error, ``OUTLINED_SHARE × length_px``, for as long as it is tracked (the
  template holds the point it started on); a box given as exact (``init_bbox``) is taken as drawn;
- the jitter: ``JITTER_GAIN`` × the follows' recent jitter against their predictions, the running RMS per axis
  of each match's offset from the pixel the camera's motion predicted it at (:func:`jitter2_px2`), × how far the
  matches wobble as through waves (the matcher's reading, 0 on a still surface: there a noisy telemetry's
  prediction jitters more than the match, which is then a fraction of a pixel off). Through wind
  waves the UUV's image wobbles, breaks up and is at times matched beside the vehicle: the match's error is a
  share of the vehicle's size that no score tells (the smoothed template matches as well with the vehicle in a
  corner of its square), but the track then moves against the camera's motion as the UUV itself does not. The
  errors last over several frames (a wave's period, a slide onto the water beside the vehicle), so the
  frame-to-frame jitter shows a part of them only, hence a gain above the √½ of white errors.

The constants are calibrated on generated sessions against the exact pixel the simulator
writes (``bench/pixel_sigma.py``; docs/explanation/tracking.md, "How sure the pixel is", explains them):
the match's terms so that no scenario has fewer than 90 % of its tracked pixels within twice
their DRMS (√2·σ; a fix's h_acc is no longer a DRMS but half its 95 % radius): 91-100 % per session, 98.7 % pooled; the outline's from
clicks and acquisitions beside the UUV's shadow and elsewhere (2-6 px off a vehicle 28 px
long). Errors in those sessions are mostly a constant offset per session (where the reference
point was taken), so the share is near 100 % in most and lower in a few; the window's and the
(re)acquisition's terms did not show in them (no lock went to a look-alike) and are set small. The jitter's on
``bench/tracker_waves.py``'s renders through wind waves (2-8 m/s, the UUV 15-38 px, 1-3.4 m deep), against the
pixel seen through the waves: its results file has the shares within twice the DRMS, of all the frames reported
``ok`` and of those more than half the UUV's size off it.
Pure: no I/O.
"""

from __future__ import annotations

import math

MATCH_SHARE = 0.016  # a good match's error, per axis, as a share of the vehicle's apparent length
SCORE_SHARE = 0.1  # ... growing by this share of the length per unit of score lost below 1
FLOOR_PX = 0.2  # never surer than this (pixels)
UNSCORED_SHARE = 0.16  # a tracker without a score: this share of the length (KCF, CSRT: 1.3-4.9 px rms, 20-28 px long)
# a frame after a frame: the prediction's 1-sigma is up to this share of the length
TRACKING_WINDOW = 0.5
WINDOW_SHARE = 0.05  # a wider window adds this share of its 1-sigma beyond that
ACQUIRED_SHARE = 0.03  # just (re)acquired: this share of the length ...
ACQUIRED_S = 1.0  # ... fading with this time constant (s)
# a restart by colour not yet proven: this share of its distance from where the UUV was sought (with
# UNSCORED_SHARE of the length for its place): its fixes 48 px off the UUV were claimed 10 px before
# (bench/results/restart_claim_s23.txt)
RESTART_SHARE = 0.5
OUTLINED_SHARE = 0.08  # a target skyfix outlined (a click, a live box, the UUV's own estimate): this share of the length
JITTER_GAIN = 4.0  # the follows' jitter against their predictions (RMS per axis), times this
JITTER_RATE = (
    0.1  # ... a running mean square at this rate per follow (a running mean over the first ones)
)


def pixel_sigma_px(
    length_px: float,
    score: float,
    window_px: float,
    since_acquired_s: float,
    outlined: bool = False,
    jitter_px: float = 0.0,
    waves: float = 0.0,
    restart_px: float = math.nan,
) -> float:
    """1-sigma (pixels) of each of the tracked pixel's u and v (see the module doc).

    ``length_px``: the vehicle's apparent length; ``score``: the match's (0..1; NaN: the tracker has none);
    ``window_px``: the 1-sigma of the prediction it was sought with (NaN: none); ``since_acquired_s``: time since
    the UUV was selected or (re)acquired; ``outlined``: the target was outlined by skyfix (a click, a live box, a
    prior), not a box given as exact; ``jitter_px``: the follows' recent jitter against their predictions (RMS per
    axis, pixels: the square root of :func:`jitter2_px2`); ``waves``: how far the matches wobble as through waves
    (0..1, :meth:`~localizer.tracking.Matcher.waves`); ``restart_px``: on a restart by colour not yet proven, its
    distance from where the UUV was sought (pixels; NaN: none). NaN when the length is unknown.
    """
    if not length_px > 0:
        return math.nan
    if math.isfinite(score):
        match = length_px * math.hypot(MATCH_SHARE, SCORE_SHARE * (1.0 - min(max(score, 0.0), 1.0)))
    else:
        match = UNSCORED_SHARE * length_px
    wide = (
        WINDOW_SHARE * max(0.0, window_px - TRACKING_WINDOW * length_px)
        if math.isfinite(window_px)
        else 0.0
    )
    fresh = ACQUIRED_SHARE * length_px * math.exp(-max(since_acquired_s, 0.0) / ACQUIRED_S)
    selected = OUTLINED_SHARE * length_px if outlined else 0.0
    jitter = JITTER_GAIN * min(max(waves, 0.0), 1.0) * jitter_px
    restart = (
        math.hypot(UNSCORED_SHARE * length_px, RESTART_SHARE * restart_px)
        if math.isfinite(restart_px)
        else 0.0
    )
    return math.sqrt(
        max(match, FLOOR_PX) ** 2 + wide**2 + fresh**2 + selected**2 + jitter**2 + restart**2
    )


def jitter2_px2(jitter2: float, follows: int, du_px: float, dv_px: float) -> float:
    """The follows' mean square jitter per axis (pixels²) once a follow ``(du_px, dv_px)`` off its prediction is
    counted: a running mean square at ``JITTER_RATE`` (a running mean over the first ones; ``follows`` counts this
    one), from ``jitter2``, the mean before it."""
    return jitter2 + max(JITTER_RATE, 1.0 / follows) * (0.5 * (du_px**2 + dv_px**2) - jitter2)

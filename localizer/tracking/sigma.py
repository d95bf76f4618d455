"""How sure the tracked pixel is: the 1-sigma of each of u and v, from what the tracker saw.

A template match is as precise as the template is large and as well as it matches: its
error is a share of the vehicle's apparent length that grows as the match score falls.
On top of that, a match is only as sure as the place it was sought in: a UUV found in a
wide window (frames skipped, a loss, a re-acquisition) may be a look-alike the window
held, most of all just after it was (re)acquired, until it has moved as the UUV does for
a while. :func:`pixel_sigma_px` adds these terms in quadrature:

- the match: ``length_px × √(MATCH_SHARE² + (SCORE_SHARE × (1 − score))²)``, at least
  ``FLOOR_PX`` (sub-pixel interpolation, the video's compression); a tracker without a
  score (OpenCV's) counts as ``UNSCORED`` (its box is whole pixels, its size fixed);
- the window: ``WINDOW_SHARE`` × the prediction's 1-sigma beyond that of a frame that
  follows the previous one (``window_px - length_px × TRACKING_WINDOW``, at least 0),
  where ``window_px`` is the prediction's 1-sigma the match was sought with
  (:class:`~localizer.tracking.Prediction`; it grows with the frames skipped since the last
  match);
- the (re)acquisition: ``ACQUIRED_SHARE × length_px``, fading with the time since the UUV
  was (re)acquired (``ACQUIRED_S``, e-folding).

The constants are calibrated on generated sessions against the exact pixel the simulator
writes (``bench/pixel_sigma.py``: the share of tracked pixels within twice their DRMS,
√2·σ, is 0.90-0.98 per scenario); the README's "How sure the pixel is" gives the numbers.
Pure: no I/O.
"""

from __future__ import annotations

import math

MATCH_SHARE = 0.025  # a good match's error, per axis, as a share of the vehicle's apparent length
SCORE_SHARE = 0.25  # ... growing by this share of the length per unit of score lost below 1
FLOOR_PX = 0.3  # never surer than this (pixels)
UNSCORED = 0.6  # the score a tracker without one is taken to have
TRACKING_WINDOW = 0.5  # a frame after a frame: the prediction's 1-sigma is up to this share of the length
WINDOW_SHARE = 0.1  # a wider window adds this share of its 1-sigma beyond that
ACQUIRED_SHARE = 0.05  # just (re)acquired: this share of the length ...
ACQUIRED_S = 1.0  # ... fading with this time constant (s)


def pixel_sigma_px(length_px: float, score: float, window_px: float, since_acquired_s: float) -> float:
    """1-sigma (pixels) of each of the tracked pixel's u and v (see the module doc).

    ``length_px``: the vehicle's apparent length; ``score``: the match's (0..1; NaN: the tracker has none);
    ``window_px``: the 1-sigma of the prediction it was sought with (NaN: none); ``since_acquired_s``: time since
    the UUV was selected or (re)acquired. NaN when the length is unknown.
    """
    if not length_px > 0:
        return math.nan
    s = score if math.isfinite(score) else UNSCORED
    match = length_px * math.hypot(MATCH_SHARE, SCORE_SHARE * (1.0 - min(max(s, 0.0), 1.0)))
    wide = WINDOW_SHARE * max(0.0, window_px - TRACKING_WINDOW * length_px) if math.isfinite(window_px) else 0.0
    fresh = ACQUIRED_SHARE * length_px * math.exp(-max(since_acquired_s, 0.0) / ACQUIRED_S)
    return math.sqrt(max(match, FLOOR_PX) ** 2 + wide**2 + fresh**2)

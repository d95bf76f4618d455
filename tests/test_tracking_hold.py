"""Held frames through waves (issue 28, ``wave_hold_misses``): synthetic frames.

A dark vehicle on a textured seafloor, the matcher told the sea is wavy. Dimmed (as caustics dim it) below the
contrast a follow needs, but still standing well out of the seafloor, it is held for more frames than
``wave_misses`` and followed again when it clears; gone (the seafloor alone), it is lost after ``wave_misses``.
"""

from __future__ import annotations

import cv2
import numpy as np

from localizer.tracking import Prediction
from localizer.tracking.template import TemplateMatcher

SIZE = (360, 480)  # rows, columns
U, V, A, B = 240.0, 180.0, 15, 10  # the vehicle's centre and half-axes (px)
DARK, DIMMED = 60.0, 95.0  # its grey level, and as dimmed (the seafloor's is ~120 +- 8)
FLOOR = cv2.GaussianBlur(np.random.default_rng(3).normal(0.0, 30.0, SIZE), (0, 0), 3.0) + 120.0
PREDICTION = Prediction(U, V, 2 * A, 2 * B, sigma_px=3.0)


def _frame(level: float | None) -> np.ndarray:
    frame = FLOOR.copy()
    if level is not None:
        cv2.ellipse(frame, (round(U), round(V)), (A, B), 0.0, 0.0, 360.0, level, -1)
    return np.clip(frame, 0, 255).astype(np.uint8)


def _in_waves() -> TemplateMatcher:
    """A matcher started on the vehicle, the sea state told as waves (its follows' scores scatter twice as much as
    the whole wave tolerance needs: these frames do not wobble, and the reading eases only slowly), that has
    followed it a few frames (the water's contrast beside it measured)."""
    m = TemplateMatcher()
    m.start(_frame(DARK), (round(U) - A - 3, round(V) - B - 3, 2 * A + 7, 2 * B + 7))
    m._scatter2, m._changes = (2.0 * m.p.wobble_waves) ** 2, 10
    for _ in range(3):
        assert m.follow(_frame(DARK), PREDICTION).found
    return m


def test_a_dimmed_vehicle_is_held_beyond_wave_misses_and_followed_when_it_clears():
    m = _in_waves()
    frame = _frame(DIMMED)
    m._begin(PREDICTION)
    # below the bar a follow needs, above the bar for holding on
    assert m._least_contrast(1.0, m.p.wave_hold_between) < m._contrast(frame, U, V)
    assert m._contrast(frame, U, V) < m._least_contrast()
    dimmed = [m.follow(frame, PREDICTION) for _ in range(round(m.p.wave_hold_misses))]
    assert len(dimmed) > m.p.wave_misses
    assert all(not x.found and x.held for x in dimmed), [(x.found, x.held) for x in dimmed]
    assert m.follow(_frame(DARK), PREDICTION).found


def test_a_vehicle_gone_is_lost_after_wave_misses():
    """The seafloor where it was has about the water's contrast: held no longer than before (a miss not held ends
    the follows: :class:`~localizer.tracking.target.Target` searches then)."""
    m = _in_waves()
    gone = [m.follow(_frame(None), PREDICTION) for _ in range(round(m.p.wave_hold_misses))]
    assert not any(x.found for x in gone)
    assert not any(x.held for x in gone[round(m.p.wave_misses) :]), [x.held for x in gone]


def test_a_match_climbed_out_of_the_window_holds_the_prediction_while_the_vehicle_stands_out_there():
    """A follow's best match climbs uphill from where it ranked best (:func:`~localizer.tracking.template._peak`),
    in waves at times out of the window onto the seafloor beside the vehicle (w2_35px_3.4m of
    ``bench/tracker_waves.py``: 21 px off a prediction of 15 px radius). That says nothing of the prediction's
    place: the frame is held while the vehicle still stands out there, not held where it is gone."""
    for level, held in ((DARK, True), (None, False)):
        m = _in_waves()
        off = 3.0 * m.p.search_sigmas * PREDICTION.sigma_px  # beyond the window
        m._search = _returning((0.9, U + off, V + off, m._angle))  # the match as climbed
        x = m.follow(_frame(level), PREDICTION)
        assert not x.found and x.held is held, (level, x)


def _returning(found):
    """A stand-in for :meth:`TemplateMatcher._search` that finds ``found``."""
    return lambda *args, **kwargs: found

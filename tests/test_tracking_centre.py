"""Centring a follow on the vehicle through waves (issue 28, :meth:`TemplateMatcher._centred`): synthetic frames.

A dark vehicle on a textured seafloor with bright caustic patches: a follow that slid beside the vehicle is moved
half the way back onto it, not onto a bright caustic patch; where the seafloor has patches as dark as the vehicle,
the follow is not moved.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from localizer.tracking.template import TemplateMatcher

SIZE = (360, 480)  # rows, columns
VEHICLE = (240.0, 180.0, 15, 10)  # centre u, v; half-axes (px)


def _floor(seed: int) -> np.ndarray:
    """A smooth seafloor texture (grey ~120 +- 8) with bright caustic patches."""
    rng = np.random.default_rng(seed)
    floor = cv2.GaussianBlur(rng.normal(0.0, 30.0, SIZE), (0, 0), 3.0) + 120.0
    for u, v in rng.uniform((20, 20), (SIZE[1] - 20, SIZE[0] - 20), (60, 2)):
        cv2.circle(floor, (int(u), int(v)), 4, 200.0, -1)
    return floor


def _with_vehicle(floor: np.ndarray, u: float, v: float) -> np.ndarray:
    frame = floor.copy()
    a, b = VEHICLE[2:]
    cv2.ellipse(frame, (round(u), round(v)), (a, b), 0.0, 0.0, 360.0, 60.0, -1)
    return np.clip(frame, 0, 255).astype(np.uint8)


def _started(frame: np.ndarray) -> TemplateMatcher:
    u, v, a, b = VEHICLE
    m = TemplateMatcher()
    m.start(frame, (round(u) - a - 3, round(v) - b - 3, 2 * a + 7, 2 * b + 7))
    return m


def _centred(m, frame, u, v, predicted=None):
    """A follow matched at (u, v) centred as :meth:`TemplateMatcher.follow` does."""
    return m._centred(frame, u, v, m._blob(frame, u, v), predicted)


def test_a_slid_follow_is_moved_half_way_back_onto_the_vehicle_not_onto_a_caustic():
    floor = _floor(3)
    m = _started(_with_vehicle(floor, *VEHICLE[:2]))
    u, v = (
        VEHICLE[0] + 9.0,
        VEHICLE[1] - 6.0,
    )  # the vehicle moved there; the follow slid 7 px beside it
    frame = _with_vehicle(floor, u, v)
    cv2.circle(
        frame, (round(u) + 16, round(v) + 4), 7, 230, -1
    )  # a bright caustic patch beside the slid follow
    cu, cv_ = _centred(m, frame, u + 6.0, v + 3.0)
    assert math.hypot(cu - (u + 3.0), cv_ - (v + 1.5)) <= 1.5, (cu, cv_)


def test_a_follow_is_not_moved_where_the_seafloor_has_patches_as_dark_as_the_vehicle():
    floor = _floor(4)
    m = _started(_with_vehicle(floor, *VEHICLE[:2]))
    frame = floor.copy()
    rng = np.random.default_rng(5)
    for pu, pv in rng.uniform((190, 130), (290, 230), (16, 2)):  # dark rocks around the vehicle
        cv2.ellipse(frame, (int(pu), int(pv)), VEHICLE[2:], 0.0, 0.0, 360.0, 60.0, -1)
    frame = _with_vehicle(frame, *VEHICLE[:2])
    at = (VEHICLE[0] + 6.0, VEHICLE[1] + 3.0)
    assert _centred(m, frame, *at) == at


def test_a_vehicle_at_the_frames_edges_is_started_and_followed_without_centring():
    """The squares about a vehicle at the frame's edges leave the frame: no centring, no error (a start
    at the top-left corner once failed in cv2.cvtColor on an empty region)."""
    floor = _floor(6)
    for u, v in ((12.0, 10.0), (SIZE[1] - 13.0, SIZE[0] - 11.0)):
        frame = cv2.cvtColor(_with_vehicle(floor, u, v), cv2.COLOR_GRAY2BGR)  # as decoded
        m = TemplateMatcher()
        m.start(frame, (round(u) - 10, round(v) - 8, 21, 17))
        assert _centred(m, frame, u + 2.0, v + 1.0) == (u + 2.0, v + 1.0)


def test_a_follow_passed_on_contrast_alone_is_moved_onto_the_vehicle_near_the_prediction():
    """A follow whose score is under the follow bar (passed on its contrast alone) and whose match slid beyond
    the square of the vehicle standing out near the prediction is moved onto that vehicle; about its own
    match the vehicle is out of reach (it would stay on the seafloor). A match inside that square is centred
    about itself as any follow."""
    floor = _floor(7)
    m = _started(_with_vehicle(floor, *VEHICLE[:2]))
    u, v = VEHICLE[0] - 8.0, VEHICLE[1] - 5.0  # the vehicle moved there, as predicted
    frame = _with_vehicle(floor, u, v)
    slid = (u + 24.0, v + 3.0)  # the match slid onto the seafloor beside it
    cu, cv_ = _centred(m, frame, *slid, predicted=(u, v))
    assert math.hypot(cu - u, cv_ - v) <= 1.5, (cu, cv_)
    # about its own match: short of it (the vehicle's square out of reach)
    assert math.hypot(*np.subtract(_centred(m, frame, *slid), (u, v))) > 8.0
    inside = (u + 5.0, v + 2.0)
    assert _centred(m, frame, *inside, predicted=(u, v)) == _centred(m, frame, *inside)


def test_the_template_learns_a_follow_only_where_something_near_it_stands_out_of_the_seafloor():
    """In waves a follow on a patch of seafloor beside the vehicle (nothing near it departs from the seafloor more
    than the seafloor's own places) does not teach the template; one on the vehicle does."""
    floor = _floor(8)
    m = _started(_with_vehicle(floor, *VEHICLE[:2]))
    frame = _with_vehicle(floor, *VEHICLE[:2])
    assert m._teaches(m._blob(frame, *VEHICLE[:2]))
    assert not m._teaches(m._blob(frame, VEHICLE[0] - 150.0, VEHICLE[1] + 60.0))

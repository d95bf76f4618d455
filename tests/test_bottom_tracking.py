"""The floor's marks under caustics (groundstation.offline.bottom.floor_marks): a floor that moves one way under a
caustic web that drifts another is tracked by the floor's motion, not the web's.

The floor (sand grain, ripples, dark pebbles) and the web are the simulator's textures (sim_fixtures.texture); the
image is the floor times the sunlight, ``1 + 0.5·(2·web − 0.3)`` as the renderer lights it. OpenCV's pyramidal
Lucas-Kanade on the raw image and on :func:`floor_marks` must find the floor's shift.
"""

import cv2
import numpy as np
import pytest

from groundstation.offline.bottom import _LK, floor_marks
from sim_fixtures import texture

FLOOR_SHIFT_PX = (6.0, 3.0)  # the floor's motion between the frames (x, y)
WEB_SHIFT_PX = (-3.0, 4.0)  # the caustics' own drift over the floor on top of it


def _frame(floor, web, shift_floor, shift_web):
    """A 640x360 grey frame: the floor moved by ``shift_floor`` lit by the web moved by ``shift_floor + shift_web``."""

    def moved(img, dx, dy):
        M = np.float32([[1, 0, dx], [0, 1, dy]])
        return cv2.warpAffine(
            img,
            M,
            (img.shape[1], img.shape[0]),
            flags=cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_REFLECT,
        )[100:460, 100:740]

    lit = moved(floor, *shift_floor) * (
        1.0 + 0.5 * (2.0 * moved(web, *np.add(shift_floor, shift_web)) - 0.3)
    )
    return np.clip(lit, 0, 255).astype(np.uint8)


@pytest.fixture(scope="module")
def frames():
    rng = np.random.default_rng(5)
    floor = cv2.cvtColor(
        texture.seafloor(rng, size=1024, m_per_px=0.03), cv2.COLOR_BGR2GRAY
    ).astype(np.float32)
    # the web at the renderer's scale (its texture's pixel is 1.5 cm of floor; here a pixel is 3 cm)
    web = np.tile(
        cv2.resize(texture.caustics(rng, size=512), (256, 256), interpolation=cv2.INTER_AREA),
        (4, 4),
    )
    return _frame(floor, web, (0.0, 0.0), (0.0, 0.0)), _frame(
        floor, web, FLOOR_SHIFT_PX, WEB_SHIFT_PX
    )


def _median_flow(a, b):
    corners = cv2.goodFeaturesToTrack(
        a, maxCorners=200, qualityLevel=0.01, minDistance=12, blockSize=7
    )
    moved, ok, _ = cv2.calcOpticalFlowPyrLK(a, b, corners, None, **_LK)
    inside = (ok.ravel() == 1) & np.all(
        (corners.reshape(-1, 2) > 40) & (corners.reshape(-1, 2) < [600, 320]), axis=1
    )
    return np.median((moved - corners).reshape(-1, 2)[inside], axis=0)


def test_floor_marks_follow_the_floor_not_the_caustics(frames):
    a, b = frames
    raw = _median_flow(a, b)
    # 7 px: CAUSTIC_WEB_M at 3 cm a pixel
    marks = _median_flow(floor_marks(a, 7), floor_marks(b, 7))
    # the raw image's corners are the web's: they move with it (the floor's shift plus the web's drift, 5 px)
    assert np.linalg.norm(raw - FLOOR_SHIFT_PX) > 3.0
    assert np.linalg.norm(marks - FLOOR_SHIFT_PX) < 0.4  # measured 0.25

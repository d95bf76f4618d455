"""A time code a camera can film: the station clock's milliseconds as three ArUco markers.

The time in whole milliseconds modulo 10⁹ (11.6 days) is written as three groups
of three decimal digits, most significant on the left, each group the ID of a
marker of OpenCV's 5×5 dictionary of 1000 (``DICT_5X5_1000``). The page that
``skyfix latency`` serves draws the same markers from :func:`marker_cells`, and
:func:`read_timecode` finds them in a filmed frame whatever its perspective
(left-to-right order, or right-to-left for an upside-down camera, whichever
lies nearer the time the frame was received).
"""

from __future__ import annotations

import cv2
import numpy as np

MODULUS_MS = 1_000_000_000
DICTIONARY = cv2.aruco.DICT_5X5_1000
CELLS = 7  # a marker is 5×5 data cells inside a one-cell black border
_dictionary = cv2.aruco.getPredefinedDictionary(DICTIONARY)
_detector = cv2.aruco.ArucoDetector(_dictionary, cv2.aruco.DetectorParameters())


def marker_ids(t_ms: int) -> list[int]:
    """The three marker IDs showing ``t_ms`` (UNIX milliseconds)."""
    t = int(t_ms) % MODULUS_MS
    return [t // 1_000_000, t // 1000 % 1000, t % 1000]


def marker_cells() -> list[list[int]]:
    """Every marker of the dictionary as CELLS×CELLS cells, row-major, 1 = white (for the page)."""
    return [
        (cv2.aruco.generateImageMarker(_dictionary, i, CELLS).ravel() > 127).astype(int).tolist()
        for i in range(1000)
    ]


def render_timecode(t_ms: int, width: int, height: int) -> np.ndarray:
    """The time code as the page draws it: a white BGR image with the three markers in a row."""
    img = np.full((height, width, 3), 255, np.uint8)
    side = min(width // 4, int(height * 0.8)) // CELLS * CELLS
    gap = (width - 3 * side) // 4
    top = (height - side) // 2
    for k, marker in enumerate(marker_ids(t_ms)):
        left = gap + k * (side + gap)
        img[top : top + side, left : left + side] = cv2.aruco.generateImageMarker(
            _dictionary, marker, side
        )[..., None]
    return img


def read_timecode(image: np.ndarray, near_unix: float) -> float | None:
    """The time (UNIX s) the filmed code shows, the one of its two readings nearer ``near_unix``; None without
    exactly three markers."""
    gray = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image
    corners, ids, _ = _detector.detectMarkers(gray)
    if ids is None or len(ids) != 3:
        return None
    ids = np.asarray(ids).ravel()
    order = np.argsort([np.asarray(c).reshape(-1, 2)[:, 0].mean() for c in corners])
    groups = [int(ids[i]) for i in order]
    near_ms = near_unix * 1000.0
    base = near_ms - (near_ms % MODULUS_MS)
    best = None
    for g in (groups, groups[::-1]):
        t = g[0] * 1_000_000 + g[1] * 1000 + g[2]
        for candidate in (base + t - MODULUS_MS, base + t, base + t + MODULUS_MS):
            if best is None or abs(candidate - near_ms) < abs(best - near_ms):
                best = candidate
    return best / 1000.0

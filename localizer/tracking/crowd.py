"""Several UUVs' trackers in one video: two trackers on one vehicle.

A tracker that loses its UUV while another passes over it may re-lock onto the other (the other is where it
predicted its own); from then on two trackers follow one vehicle and one of them sends the other vehicle's
position to its autopilot. Their boxes are then centred on one spot. :class:`Crowd` keeps each UUV's recent
boxes (pixels x, y, w, h, with their frame index) and says ``same_vehicle`` for a box centred on another UUV's
(:func:`same_spot`) within :data:`NEAR_FRAMES` frames: which tracker is right is not known, so neither gives a
fix until they part or the operator selects again. Two UUVs
passing right over each other look the same, and also get no fix while they overlap; which one is which when
they part, the boxes cannot tell (docs/explanation/tracking.md, "Several UUVs").
"""

from __future__ import annotations

import math
from collections import deque

SAME_SPOT = 0.25  # boxes whose centres are closer than this share of the smaller one's shorter side: one vehicle
NEAR_FRAMES = 2  # boxes this many frames apart are compared
HISTORY = 60  # boxes kept per UUV (frames): one UUV's pipeline may run behind another's
STATUS = "same_vehicle"


def same_spot(a, b) -> bool:
    """Whether boxes ``a`` and ``b`` (x, y, w, h, pixels) are centred on one spot: their centres closer than
    :data:`SAME_SPOT` of the smaller box's shorter side. Two trackers on one vehicle centre on it (their boxes may
    differ in size: a drawn box, a tracker's own); two vehicles side by side are a vehicle's width apart."""
    (ax, ay, aw, ah), (bx, by, bw, bh) = a, b
    apart_px = math.hypot(ax + aw / 2 - bx - bw / 2, ay + ah / 2 - by - bh / 2)
    return apart_px <= SAME_SPOT * min(aw, ah, bw, bh)


class Crowd:
    """The UUVs' recent boxes; :meth:`vet` each one as it is tracked.

    Each UUV's pipeline tracks the frames on its own, so one may be frames behind another: a box is compared with
    the other UUVs' boxes of frames within :data:`NEAR_FRAMES` of its own (from their last :data:`HISTORY`), and
    two UUVs found on one vehicle stay so (both told, whichever is ahead) until such a comparison finds them apart
    or one of them has no box.
    """

    def __init__(self):
        self._boxes: dict[str, deque[tuple[int, tuple]]] = {}
        self._same: set[frozenset[str]] = set()

    def vet(self, uuv_id: str, frame: int, box) -> str | None:
        """Note UUV ``uuv_id``'s box on ``frame`` (None: it has none, lost or released); :data:`STATUS` while it is
        on the same vehicle as another UUV, else None."""
        if box is None:
            self._boxes.pop(uuv_id, None)
            self._same = {pair for pair in self._same if uuv_id not in pair}
            return None
        box = tuple(box)
        self._boxes.setdefault(uuv_id, deque(maxlen=HISTORY)).append((frame, box))
        for other, boxes in self._boxes.items():
            near = [b for f, b in boxes if abs(f - frame) <= NEAR_FRAMES] if other != uuv_id else []
            if near:
                pair = frozenset((uuv_id, other))
                if any(same_spot(box, b) for b in near):
                    self._same.add(pair)
                else:
                    self._same.discard(pair)
        return STATUS if any(uuv_id in pair for pair in self._same) else None

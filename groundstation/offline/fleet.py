"""Several UUVs of one recording through their gates together, as the live service runs them.

Each UUV of the session (``uuvs/<id>/``) is located as ``skyfix process --uuv ID`` does (its pixels from its own
track.csv or from tracking the video from its own first box, its own depth), then every UUV's fixes go through its
own :class:`~localizer.fix_gate.FixGate`, the gates joined to one :class:`~localizer.exchange.Fleet`, frame by
frame in time order (:func:`~localizer.fix_gate.gate_together`): which fixes the live service would send as valid,
and why not the others (``exchanged``: the target came near another UUV's and is not told apart yet).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from groundstation.offline.process import frame_pixels, locate_frames
from groundstation.runtime.gps_input import LOSS_STATUSES
from groundstation.session.read import load_session, uuv_ids
from localizer.exchange import Fleet
from localizer.fix import Fixes
from localizer.fix_gate import FixGate, gate_together


@dataclass
class Gated:
    """One UUV's fixes and what its gate said of each (None: valid; a reason; "": no fix)."""

    fixes: Fixes
    words: np.ndarray

    @property
    def valid(self) -> np.ndarray:
        return np.array([w is None for w in self.words], dtype=bool)


def gate_fleet(
    path: Path, use_track: bool = False, tracker: str = "default", joined: bool = True
) -> dict[str, Gated]:
    """Every UUV of the session at ``path`` located and gated together (see the module doc), by UUV id; not
    ``joined``: each gate alone, as before the gates compared the UUVs."""
    fixes = {}
    for uuv in uuv_ids(path):
        session = load_session(path, uuv=uuv)
        fixes[uuv] = locate_frames(session, frame_pixels(session, use_track, tracker, motion=False))
    fleet = Fleet() if joined else None
    gates = {k: FixGate(fleet=fleet, uuv_id=k) for k in fixes}
    lost = {k: np.isin(f.status, LOSS_STATUSES) for k, f in fixes.items()}
    words = gate_together(fixes, lost, gates)
    return {k: Gated(fixes[k], words[k]) for k in fixes}

"""Offline, through waves: the frames without the UUV traced back from a frame it is followed in standing out of the
seafloor (``groundstation.offline.track``, ``UuvTrack._trace_when_sure``), on a scripted forward pass: which frames
start a trace, which ones it reports, where it stops. The tracking itself is a stand-in (each frame says whether a
tracker stepping back finds the UUV there); ``tests/test_tracking_waves.py`` steps a real copy back through waves."""

from __future__ import annotations

import math
from collections import deque
from types import SimpleNamespace

import numpy as np

from groundstation.offline.track import SURE_DISTINCT, SURE_WITHIN_S, UuvTrack
from localizer.tracking import TrackResult
from localizer.tracking.target import TargetState

PERIOD_S = 1.0 / 30.0


class _Back:
    """A tracker stepping back: finds the UUV in the frames ``seen`` marks, loses it at the first other one."""

    def __init__(self, seen: dict):
        self.seen, self.state = seen, TargetState.TRACKING

    def step(self, image, pose, row: int, chroma=None) -> TrackResult:
        if not self.seen.get(row, False):
            self.state = TargetState.LOST
            return TrackResult("lost")
        return TrackResult("ok", 100.0 + row, 50.0, sigma_px=1.0, confidence=0.7)


def _forward(script, seen: dict, proving=(), refuted_from: int | None = None):
    """A UuvTrack fed ``script`` [(ok, the follow's distinct)] frame by frame, its track a restart by colour not yet
    proven on the rows ``proving`` and refuted from row ``refuted_from`` on; the rows it traced back (bridged) and
    the rows each trace started from."""
    n = len(script)
    track = object.__new__(UuvTrack)
    starts = []

    def back_from(image, pose, row):
        starts.append(row)
        return _Back(seen)

    track.tracking = SimpleNamespace(
        target=SimpleNamespace(distinct=math.nan), back_from=back_from, refuted=0
    )
    track.tracking.unproven = lambda t: round(t / PERIOD_S) in proving
    track.pose, track.t = None, PERIOD_S * np.arange(n)
    track.status = np.array(["ok" if ok else "lost" for ok, _ in script], dtype=object)
    track.u, track.v, track.conf, track.sigma, track.u_unfiltered, track.v_unfiltered = (
        np.full(n, np.nan) for _ in range(6)
    )
    track.bridged, track.causal_words, track.timings = np.zeros(n, bool), {}, {"backward": 0.0}
    track.behind, track.missed_t, track.unproven = deque(maxlen=90), -math.inf, None
    for row, (ok, distinct) in enumerate(script):
        track.tracking.target.distinct = distinct
        track.tracking.refuted = int(refuted_from is not None and row >= refuted_from)
        result = TrackResult("ok", 1.0, 1.0) if ok else TrackResult("lost")
        track._trace_when_sure(row, (np.zeros(1), None), result)  # a kept frame: (image, chroma)
    return list(np.flatnonzero(track.bridged)), starts, track


def test_traced_back_from_the_first_frame_the_uuv_stands_out_in_until_lost():
    sure, weak = SURE_DISTINCT + 0.1, SURE_DISTINCT - 0.1
    # ok 0-2, without the UUV 3-7, ok 8 (not standing out), 9 (standing out)
    script = [(True, sure)] * 3 + [(False, math.nan)] * 5 + [(True, weak), (True, sure)]
    seen = {r: True for r in range(10)} | {3: False}
    bridged, starts, track = _forward(script, seen)
    assert starts == [9]
    assert bridged == [
        4,
        5,
        6,
        7,
    ]  # the frames it finds the UUV in, not 8 (ok already), until lost at 3
    assert set(track.status[4:8]) == {"ok"} and track.status[3] == "lost"
    assert all(track.causal_words[r] == "lost" for r in bridged)
    assert np.array_equal(track.u[4:8], 100.0 + np.arange(4, 8))


def test_not_traced_without_a_frame_the_uuv_stands_out_in_soon_after():
    seen = {r: True for r in range(40)}
    # on a still surface (no distinct) nothing is traced back from a frame that merely follows
    bridged, starts, _ = _forward(
        [(True, math.nan)] * 3 + [(False, math.nan)] * 4 + [(True, math.nan)] * 5, seen
    )
    assert bridged == [] and starts == []
    # standing out only later than SURE_WITHIN_S after the last frame without it
    late = math.ceil(SURE_WITHIN_S / PERIOD_S) + 2
    script = [(True, 2.0)] * 3 + [(False, math.nan)] * 4 + [(True, 0.5)] * late + [(True, 2.0)]
    bridged, starts, _ = _forward(script, seen)
    assert bridged == [] and starts == []


def test_traced_back_from_a_restart_by_colour_bridged_once_it_is_proven():
    sure = SURE_DISTINCT + 0.1
    # ok 0-2, without the UUV 3-7 (a restart by colour on 7), standing out 8-12, the restart proven from 11 on
    script = [(True, sure)] * 3 + [(False, math.nan)] * 5 + [(True, sure)] * 5
    seen = {r: True for r in range(13)} | {3: False}
    bridged, starts, _ = _forward(script, seen, proving=range(7, 11))
    assert starts == [8] and bridged == [4, 5, 6, 7]  # traced from 8, bridged on 11
    for last in (9, 10):  # the recording ends before the restart is proven
        bridged, starts, _ = _forward(script[: last + 1], seen, proving=range(7, 11))
        assert starts == [8] and bridged == []


def test_traced_back_from_a_restart_by_colour_dropped_when_the_colour_refutes_it():
    sure = SURE_DISTINCT + 0.1
    # as above, the colour refuting the restart on 10 (the track back to what it was: the UUV lost again)
    script = [(True, sure)] * 3 + [(False, math.nan)] * 5 + [(True, sure)] * 2
    script += [(False, math.nan)] * 3 + [(True, sure)] * 2
    seen = {r: True for r in range(15)} | {3: False}
    bridged, starts, _ = _forward(script, seen, proving=range(7, 10), refuted_from=10)
    # not 4-7 (traced from 8, refuted), but 10-12 from 13, through the frames since
    assert starts == [8, 13] and bridged == [10, 11, 12], (starts, bridged)

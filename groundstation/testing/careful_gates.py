"""A gate's streams for the careful-gate tests and bench/careful_gates.py: an object at rest offered to a gate, a
gate tracking one, a gate kept across a restart by its TrackMemory (the real file), a clock step with the tracker on a
look-alike."""

from __future__ import annotations

import json
import math
import time

import numpy as np
import pytest

from groundstation.live.track_memory import TrackMemory, remember, track_path, write_track
from groundstation.testing.gate_streams import HZ, LAT0, LON0, M_PER_DEG, NOISE_M, T0, fix_at
from localizer.fix_gate import MAX_REACH_M, Arrival, FixGate

LATENCY_S = 0.12  # exposure to arrival


def still(
    gate: FixGate,
    t0: float,
    seconds: float,
    north_m: float = 0.0,
    east_m: float = 0.0,
    h_acc_m: float = 0.4,
    seed: int = 0,
) -> list[bool]:
    """``seconds`` of fixes of an object at rest at (north, east) offered to ``gate``: which were valid."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(round(seconds * HZ)):
        n, e = rng.normal(0.0, NOISE_M, 2)
        f = fix_at(t0 + i / HZ, north_m + n, east_m + e, h_acc_m)
        out.append(gate.check(f, f.t_unix + 0.05) is None)
    return out


def tracked(h_acc_m: float = 0.4) -> FixGate:
    """A gate that tracks a UUV at rest at the origin (2 s of fixes from T0)."""
    gate = FixGate()
    assert still(gate, T0, 2.0, h_acc_m=h_acc_m)[-1] and gate.state == "tracking"
    return gate


def kept_gate(tmp_path, h_acc_m: float = 0.4, down_s: float = 3.0) -> tuple[FixGate, float]:
    """A tracked UUV's gate kept by its TrackMemory (the real file), the process gone, a new gate started from the
    file as if ``down_s`` later; the time the new one's fixes start at."""
    gate = FixGate()
    assert still(gate, time.time() - 2.1, 2.0, h_acc_m=h_acc_m)[-1] and gate.state == "tracking"
    path = track_path(tmp_path, "uuv1")
    keeper = TrackMemory(gate, path)
    keeper.write()
    keeper.write()  # unchanged: not written again
    # no temporary left
    assert keeper.written == 1 and path.exists() and not list(tmp_path.glob(".track-*"))
    kept = json.loads(path.read_text())
    kept["age_s"] += down_s  # the time the service was down
    write_track(
        path,
        {k: kept[k] for k in ("t", "lat", "lon", "vn_mps", "ve_mps", "P", "C", "common", "age_s")},
    )
    new = FixGate()
    read = remember(new, path, max_age_s=300.0)
    assert read is not None and read["age_s"] == pytest.approx(kept["age_s"], abs=0.5)
    assert new.state == "acquiring" and new.track is not None
    return new, new.track.t + down_s


def stepped_stream(step_s: float, wrong_m: float, follows: bool, h_acc_m: float = 0.4):
    """4 s of a UUV at rest tracked at 30 Hz; after 2 s the station clock steps ``step_s``. From the step on the
    tracker is on a look-alike ``wrong_m`` east (0: still the UUV). ``follows``: the exposure times step with the
    station clock (stamped on it), else they keep their course (a clock mapping that did not follow). Yields
    (fix, now, arrival, truth east)."""
    rng = np.random.default_rng(5)
    mono0 = 1000.0
    for i in range(round(4.0 * HZ)):
        t_true = T0 + i / HZ
        after = t_true >= T0 + 2.0
        step = step_s if after else 0.0
        east = (wrong_m if after else 0.0) + rng.normal(0.0, NOISE_M)
        f = fix_at(t_true + (step if follows else 0.0), rng.normal(0.0, NOISE_M), east, h_acc_m)
        recv_mono = mono0 + (t_true - T0) + LATENCY_S
        now_mono = recv_mono + 0.03
        arrival = Arrival(t_true + LATENCY_S + step, recv_mono, now_mono)
        yield f, t_true + LATENCY_S + 0.03 + step, arrival, 0.0


def off_valid(
    step_s, wrong_m, follows, h_acc_m, with_arrival=True, max_reach_m=MAX_REACH_M
) -> tuple[int, FixGate]:
    """How many valid fixes are more than 3 h_acc off the truth (without the arrival: the exposure times alone)."""
    gate, bad = FixGate(max_reach_m=max_reach_m), 0
    for f, now, arrival, truth_e in stepped_stream(step_s, wrong_m, follows, h_acc_m):
        ok = gate.check(f, now, None, arrival if with_arrival else None) is None
        east_m = (f.lon - LON0) * M_PER_DEG * math.cos(math.radians(LAT0))
        bad += ok and abs(east_m - truth_e) > 3 * h_acc_m
    return bad, gate

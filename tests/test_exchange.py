"""Two UUVs that pass near or over each other never swap into a valid fix (localizer/exchange.py, the gates joined).

Streams of 30 Hz fixes of two vehicles crossing head on under a UAV hovering 10 m over the water to one side (so that
a ray met at another depth lands elsewhere), built here without the localizer: for each frame each UUV's tracker
follows a vehicle (its own, the other, or none: lost), and the fix it gives is where that vehicle's ray meets *its
own UUV's* pressure depth — Snell's law as angles, the surface crossing solved by SciPy's brentq. Each fix knows the
vehicle it came from, so a valid fix of the other vehicle is counted exactly.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.optimize import brentq

from groundstation.messages import GateStatus
from groundstation.testing.gate_streams import HZ, NOISE_M, T0, fix_at
from localizer.exchange import NEAR_M, Fleet
from localizer.fix import Fixes
from localizer.fix_gate import FixGate, gate_together

UAV_NE = np.array([-4.0, -3.0])  # the UAV's position (m north, east), HEIGHT_M over the water
HEIGHT_M = 10.0
N_WATER = 1.34
CROSS_S = 5.0  # the vehicles are nearest this long after the start ...
SECONDS = 12.0  # ... of this many
H_ACC_M = 0.3
IDS = ("uuv1", "uuv2")


def seen_at(p_ne: np.ndarray, depth_m: float, at_depth_m: float) -> np.ndarray:
    """Where the ray to a vehicle at ``p_ne`` (m), ``depth_m`` deep, meets ``at_depth_m``: the surface crossing ``x``
    from ``x + depth·tan(asin(sin(atan(x/h))/n)) = rho``, then ``x + at_depth·tan`` of the same angle."""
    r = p_ne - UAV_NE
    rho = float(np.hypot(*r))

    def water_tan(x):
        s = math.sin(math.atan2(x, HEIGHT_M)) / N_WATER
        return s / math.sqrt(1.0 - s * s)

    x = brentq(lambda x: x + depth_m * water_tan(x) - rho, 0.0, rho)
    return UAV_NE + r / rho * (x + at_depth_m * water_tan(x))


def vehicles(t: np.ndarray, speed_mps: float, miss_m: float) -> dict[str, np.ndarray]:
    """Positions (n, 2) of the two vehicles crossing head on along east, ``miss_m`` apart north, nearest at CROSS_S."""
    along = speed_mps * (t - CROSS_S)
    return {
        "uuv1": np.column_stack([np.zeros_like(t), along]),
        "uuv2": np.column_stack([np.full_like(t, miss_m), -along]),
    }


def streams(speed_mps, depths, miss_m, follow, seed=0):
    """Each UUV's :class:`Fixes` and the vehicle each fix came from (None: lost). ``follow(uuv, t, apart_m)``: which
    vehicle that UUV's tracker is on at ``t`` (``apart_m``: how far apart the vehicles are)."""
    t = T0 + np.arange(round(SECONDS * HZ)) / HZ
    pos = vehicles(t - T0, speed_mps, miss_m)
    apart = np.hypot(*(pos["uuv1"] - pos["uuv2"]).T)
    rng = np.random.default_rng(seed)
    out = {}
    for uuv in IDS:
        fixes, source = [], []
        for i, ti in enumerate(t):
            on = follow(uuv, ti - T0, apart[i])
            source.append(on)
            if on is None:
                fixes.append(fix_at(ti, 0.0, 0.0, H_ACC_M, status="lost"))
                continue
            p = seen_at(pos[on][i], depths[on], depths[uuv]) + rng.normal(0.0, NOISE_M, 2)
            f = fix_at(ti, *p, H_ACC_M)
            fixes.append(
                dataclasses.replace(
                    f,
                    depth_m=depths[uuv],
                    north_m=p[0] - UAV_NE[0],
                    east_m=p[1] - UAV_NE[1],
                    height_m=HEIGHT_M,
                )
            )
        cols = {
            k.name: np.array([getattr(f, k.name) for f in fixes])
            for k in dataclasses.fields(fixes[0])
            if k.name not in ("t_unix", "status")
        }
        out[uuv] = (Fixes.of(t, np.array([f.status for f in fixes], dtype=object), **cols), source)
    return out


def gated(speed_mps, depths, miss_m, follow):
    """Both UUVs' streams through their gates joined to one fleet: per UUV (valid mask, source list, gate)."""
    s = streams(speed_mps, depths, miss_m, follow)
    fleet = Fleet()
    gates = {k: FixGate(fleet=fleet, uuv_id=k) for k in IDS}
    words = gate_together(
        {k: s[k][0] for k in IDS},
        {k: s[k][0].status == "lost" for k in IDS},
        gates,
    )
    return {k: (np.array([w is None for w in words[k]]), s[k][1], gates[k], words[k]) for k in IDS}


def other_of(uuv: str) -> str:
    return IDS[1 - IDS.index(uuv)]


def hidden_then(onto: str):
    """The deeper uuv2 hidden while the vehicles are within 0.3 m (its tracker lost), then its tracker on ``onto``
    ("own": uuv2, "other": uuv1) from the crossing on; uuv1's on uuv1 throughout."""

    def follow(uuv, t, apart_m):
        if uuv == "uuv1":
            return "uuv1"
        if apart_m < 0.3:
            return None
        return "uuv1" if onto == "other" and t > CROSS_S else "uuv2"

    return follow


def swap_at_crossing(uuv, t, apart_m):
    """Both trackers follow the other vehicle once they have passed."""
    return uuv if t < CROSS_S else other_of(uuv)


def keep(uuv, t, apart_m):
    return uuv


def after(mask, t0_s):
    return mask & (np.arange(len(mask)) / HZ > t0_s)


@pytest.mark.parametrize("speed_mps", [0.2, 0.5])
def test_the_deeper_uuvs_tracker_on_the_one_over_it_never_gives_a_valid_fix(speed_mps):
    """At 1.0 and 1.6 m, uuv1 passing right over uuv2: uuv2's tracker, lost under it, locks onto uuv1 and stays.
    uuv2: no valid fix of uuv1, ever; uuv1, on top, keeps its valid fixes through the crossing (the depths say the
    one seen there is the shallower)."""
    g = gated(speed_mps, {"uuv1": 1.0, "uuv2": 1.6}, 0.0, hidden_then("other"))
    for uuv, (valid, source, gate, words) in g.items():
        wrong = valid & (np.array(source, dtype=object) != uuv)
        assert not wrong.any(), (uuv, int(wrong.sum()))
    valid1 = g["uuv1"][0]
    assert valid1[round((CROSS_S - 1.0) * HZ) : round((CROSS_S + 1.0) * HZ)].all()
    assert not after(g["uuv2"][0], CROSS_S).any()
    status = g["uuv2"][2].status(T0 + SECONDS)
    GateStatus.model_validate(status)
    assert status["exchange"]["other"] == "uuv1" and status["exchange"]["evidence"] < 0, status


@pytest.mark.parametrize("speed_mps", [0.2, 0.5])
def test_the_deeper_uuv_found_again_is_valid_once_they_part(speed_mps):
    """The same crossing, uuv2's tracker back on uuv2 when it shows again: no valid fix while they are near, valid
    again before the end (its own track moved on, at its own depth, explains its fixes; uuv1's does not)."""
    g = gated(speed_mps, {"uuv1": 1.0, "uuv2": 1.6}, 0.0, hidden_then("own"))
    valid, source, gate, _ = g["uuv2"]
    assert not (valid & (np.array(source, dtype=object) != "uuv2")).any()
    parted_s = CROSS_S + NEAR_M / (2 * speed_mps)
    t = np.arange(len(valid)) / HZ
    assert not valid[(t > CROSS_S - 1.0) & (t < parted_s)].any()
    assert valid[t > SECONDS - 1.0].all() and gate.encounter is None


@pytest.mark.parametrize("speed_mps", [0.2, 0.5])
def test_at_one_depth_swapped_trackers_never_give_a_valid_fix(speed_mps):
    """Both at 1.0 m passing 0.6 m apart, each tracker onto the other vehicle as they pass: neither gives a valid
    fix of the other vehicle, then or later (the fixes follow the other's track); while they are near, no fix."""
    g = gated(speed_mps, {"uuv1": 1.0, "uuv2": 1.0}, 0.6, swap_at_crossing)
    for uuv, (valid, source, gate, words) in g.items():
        assert not (valid & (np.array(source, dtype=object) != uuv)).any(), uuv
        assert not after(valid, CROSS_S).any(), uuv
        assert "exchanged" in set(words[round(CROSS_S * HZ) :]), uuv


@pytest.mark.parametrize("speed_mps", [0.2, 0.5])
def test_at_one_depth_no_fix_while_near_then_valid_when_the_evidence_agrees(speed_mps):
    """Both at 1.0 m passing 0.6 m apart, each tracker on its own: no valid fix while the targets are within NEAR_M
    (which is which is not known there), valid again once they have parted and the fixes follow their own tracks."""
    g = gated(speed_mps, {"uuv1": 1.0, "uuv2": 1.0}, 0.6, keep)
    t = np.arange(round(SECONDS * HZ)) / HZ
    pos = vehicles(t, speed_mps, 0.6)
    near = np.hypot(*(pos["uuv1"] - pos["uuv2"]).T) < NEAR_M - 0.05
    for uuv, (valid, _, gate, words) in g.items():
        assert near.any() and not valid[near].any(), uuv
        parted_s = CROSS_S + math.sqrt(NEAR_M**2 - 0.36) / (2 * speed_mps)
        assert valid[after(np.ones(len(t), dtype=bool), parted_s + 0.5)].all(), uuv


def test_the_operator_confirms_which_is_which():
    """uuv2's tracker back on its own vehicle but the gates not told yet: the operator's confirmation makes its
    fixes valid (a second of consistent fixes later) without the evidence."""
    s = streams(0.2, {"uuv1": 1.0, "uuv2": 1.0}, 0.6, keep)
    fleet = Fleet()
    gates = {k: FixGate(fleet=fleet, uuv_id=k) for k in IDS}
    n = len(s["uuv1"][0])
    mid = round(CROSS_S * HZ)  # the vehicles are near: exchanged
    words = {k: [] for k in IDS}
    for i in range(n):
        if i == mid:
            assert gates["uuv2"].encounter is not None
            assert gates["uuv2"].confirm()["confirmed"]
        for k in IDS:
            words[k].append(gates[k].check(s[k][0][i], float(s[k][0].t_unix[i])))
    assert words["uuv2"][mid + round(1.2 * HZ)] is None
    assert words["uuv1"][mid + round(0.2 * HZ)] == "exchanged"

"""The fuser's output gate cannot be dragged: three configured drones over a hovering UUV agree for 2 s; then two
lose it for 8 s while the third, compromised, walks its fixes east at 0.5 m/s (each step within the UUV's
dynamics, its own gate passes it). The fused fix follows it no further than the reach (1.5 m, as the live
gate's) and is off_track beyond; when the two come back at the truth the fused fix is there again. The control,
the reach unbounded, follows the fake 4 m away."""

from __future__ import annotations

import math

import numpy as np
from test_fusion import fix, geodetic

from groundstation.fuse.fuser import Fuser
from localizer.fix_gate import GATE_SIGMAS, MAX_REACH_M, FixGate

WALK_MPS = 0.5


def _run(max_reach_m: float) -> list:
    """(seconds, fused fix) of the scenario in the module doc; the truth is at (0, 0)."""
    fuser = Fuser(
        lambda: FixGate(max_age_s=0.5), 3.0, sources=("a", "b", "c"), max_reach_m=max_reach_m
    )
    rng = np.random.default_rng(5)
    out = []
    for k in range(round(14.0 * 30)):
        for i, name in enumerate("abc"):
            s = k / 30.0 + 0.004 * i
            if name != "c" and 2.0 <= s < 10.0:
                continue  # a and b lost the UUV
            east = WALK_MPS * min(max(0.0, s - 2.0), 8.0) if name == "c" else 0.0
            n, e = rng.normal(0.0, 0.02, 2)
            fused = fuser.on_fix(name, fix(1000.0 + s, n, east + e, 0.1), 1000.0 + s + 0.08)
            if fused is not None:
                out.append((s, fused))
    return out, fuser.status(2000.0)


def _error_m(f) -> float:
    lat0, lon0 = geodetic(0.0, 0.0)
    dn = (f.lat - lat0) * 111_000.0
    de = (f.lon - lon0) * 111_000.0 * math.cos(math.radians(lat0))
    return math.hypot(dn, de)


def test_a_walking_fake_drags_the_fused_fix_no_further_than_the_reach():
    fused, status = _run(MAX_REACH_M)
    ok = [(s, f) for s, f in fused if f.ok]
    worst = max(_error_m(f) for s, f in ok)
    alone = [f.status for s, f in fused if 2.0 <= s < 10.0]
    back = [_error_m(f) for s, f in ok if s > 11.5]
    print(
        f"reach {MAX_REACH_M} m: worst ok error {worst:.2f} m; while the fake was alone "
        f"{alone.count('ok')} ok, {alone.count('off_track')} off_track; after the two came back "
        f"{len(back)} ok, max error {max(back):.3f} m; status off_track {status['off_track']}, "
        f"output_restarts {status['output_restarts']}"
    )
    # beyond the reach by at most the gate's sigmas of both claims: the fake's 0.1 m per axis (its track's growth
    # over a frame adds about a centimetre) and the agreed position's 0.1 / sqrt(3)
    assert worst < MAX_REACH_M + GATE_SIGMAS * math.hypot(0.1, 0.1 / math.sqrt(3)) + 0.1
    assert alone.count("off_track") > 100
    assert len(back) > 30 and max(back) < 0.15


def test_the_control_without_a_reach_follows_the_fake():
    fused, _ = _run(math.inf)
    worst = max(_error_m(f) for s, f in fused if f.ok)
    print(f"reach unbounded: worst ok error {worst:.2f} m")
    assert worst > 3.5


def test_the_track_starts_again_where_all_the_drones_agree():
    """The three drones' fixes jump 3 m north together (their own gates here judge accuracy and age only, as after
    each drone's operator confirmed the UUV there): the fused fix is off_track until they have agreed there for a
    second, then the track starts again there (output_restarts 1); never ok in between."""
    fuser = Fuser(lambda: FixGate(max_age_s=0.5, judge_track=False), 3.0, sources=("a", "b", "c"))
    rng = np.random.default_rng(7)
    fused = []
    for k in range(round(6.0 * 30)):
        for i, name in enumerate("abc"):
            s = k / 30.0 + 0.004 * i
            n, e = rng.normal(0.0, 0.02, 2) + (3.0 if s >= 2.0 else 0.0, 0.0)
            f = fuser.on_fix(name, fix(1000.0 + s, n, e, 0.1), 1000.0 + s + 0.08)
            if f is not None:
                fused.append((s, f))
    lat0, _ = geodetic(0.0, 0.0)
    north = [(s, (f.lat - lat0) * 111_000.0) for s, f in fused if f.ok and s >= 2.0]
    first_there = min(s for s, n in north if n > 2.8)
    restarts = fuser.status(2000.0)["output_restarts"]
    off = sum(f.status == "off_track" for s, f in fused)
    print(
        f"first ok there {first_there - 2.0:.2f} s after the jump; {off} off_track; {restarts} restart"
    )
    # the old place (a frame or two) or the new, nothing between
    assert all(n < 0.5 or n > 2.8 for s, n in north)
    assert first_there - 2.0 >= 1.0 and restarts == 1 and off > 20

"""Safety gates on what goes out as a valid fix: the rules alone, then real GPS_INPUT at a pymavlink endpoint."""

from __future__ import annotations

import asyncio
import math
import time

import pytest
from live_helpers import free_port

from groundstation.mavlink_io import mavutil
from groundstation.sinks.gps_input import GpsInputSink, mavlink_gps_link
from localizer.fix import Fix
from localizer.fix_gate import CONFIRM, K_SIGMA, FixGate, distance_m

LAT0, LON0 = 63.44, 10.40
M_PER_DEG_LAT = math.pi / 180 * 6_371_000.0
T0 = 1_763_800_000.0
DT = 1 / 30


def fix_at(t: float, north_m: float = 0.0, east_m: float = 0.0, h_acc_m: float = 0.3, status: str = "ok") -> Fix:
    lat = LAT0 + north_m / M_PER_DEG_LAT
    lon = LON0 + east_m / (M_PER_DEG_LAT * math.cos(math.radians(LAT0)))
    return Fix(t_unix=t, status=status, u=1.0, v=1.0, lat=lat, lon=lon, alt_amsl_m=-1.0, depth_m=1.0,
               h_acc_m=h_acc_m, v_acc_m=0.5)


def feed(gate: FixGate, fixes) -> list[str | None]:
    return [gate.check(f, f.t_unix + 0.05) for f in fixes]


def test_distance_matches_the_offsets():
    assert distance_m(fix_at(T0), fix_at(T0, 3.0, 4.0)) == pytest.approx(5.0, rel=1e-3)


def test_first_fix_needs_confirming():
    gate = FixGate()
    out = feed(gate, [fix_at(T0 + i * DT, 0.01 * i) for i in range(5)])
    assert out == ["unconfirmed"] * (CONFIRM - 1) + [None] * (5 - CONFIRM + 1)
    assert gate.rejected["unconfirmed"] == CONFIRM - 1 and gate.accepted == 5 - CONFIRM + 1


def test_a_single_stray_fix_is_never_sent():
    """Good, good, stray 8 m away, good: the stray one alone breaks the chain and never confirms."""
    gate = FixGate()
    feed(gate, [fix_at(T0 + i * DT) for i in range(CONFIRM)])
    out = feed(gate, [fix_at(T0 + 3 * DT, 8.0), fix_at(T0 + 4 * DT)])
    assert out == ["jump", None]


def test_jump_limit_is_speed_times_time_plus_the_accuracies():
    gate = FixGate(max_speed_mps=1.5)
    feed(gate, [fix_at(T0 + i * DT) for i in range(CONFIRM)])
    t_ref = T0 + (CONFIRM - 1) * DT
    dt = 0.5
    limit = 1.5 * dt + K_SIGMA * math.hypot(0.3, 0.3)
    assert gate.check(fix_at(t_ref + dt, 0.98 * limit), t_ref + dt) is None
    t_ref += dt
    assert gate.check(fix_at(t_ref + dt, 0.98 * limit + 1.02 * limit), t_ref + dt) == "jump"


def test_accuracy_age_and_order():
    gate = FixGate(max_h_acc_m=2.5, max_age_s=0.5)
    feed(gate, [fix_at(T0 + i * DT) for i in range(CONFIRM)])
    t = T0 + CONFIRM * DT
    assert gate.check(fix_at(t, h_acc_m=2.6), t) == "h_acc"
    assert gate.check(fix_at(t, h_acc_m=float("nan")), t) == "h_acc"
    assert gate.check(fix_at(t), t + 0.51) == "age"
    assert gate.check(fix_at(T0), t) == "out_of_order"
    assert gate.check(fix_at(t), t) is None
    assert dict(gate.rejected) == {"h_acc": 2, "age": 1, "out_of_order": 1, "unconfirmed": CONFIRM - 1}


def test_loss_and_long_gaps_need_confirming_again():
    gate = FixGate(reference_s=1.0)
    feed(gate, [fix_at(T0 + i * DT) for i in range(CONFIRM)])
    gate.reset()
    assert feed(gate, [fix_at(T0 + 1.0)]) == ["unconfirmed"]
    gate = FixGate(reference_s=1.0)
    feed(gate, [fix_at(T0 + i * DT) for i in range(CONFIRM)])
    assert feed(gate, [fix_at(T0 + 2.0)]) == ["unconfirmed"]  # 2 s later, even at the same place


def test_a_wrong_reference_is_given_up_after_a_confirmed_chain():
    """Confirmed at a wrong place (0 m), the vehicle really 6 m away: CONFIRM consistent fixes move the reference."""
    gate = FixGate()
    feed(gate, [fix_at(T0 + i * DT) for i in range(CONFIRM)])
    out = feed(gate, [fix_at(T0 + (CONFIRM + i) * DT, 6.0) for i in range(CONFIRM + 1)])
    assert out == ["jump"] * (CONFIRM - 1) + [None, None]


def test_gps_input_never_carries_a_rejected_fix():
    """Real GPS_INPUT at a pymavlink endpoint: confirmed fixes go out, a jump, a poor and an old fix never do."""
    port = free_port()
    uuv = mavutil().mavlink_connection(f"udpin:127.0.0.1:{port}")
    offered: list[tuple[Fix, bool]] = []  # (fix, whether it may go out)

    async def scenario() -> GpsInputSink:
        sink = GpsInputSink(mavlink_gps_link(f"udpout:127.0.0.1:{port}"), hz=10.0, max_age_s=0.5)
        task = asyncio.create_task(sink.run())
        t0 = time.time()
        plan = [(0.0, 0.3, True)] * 12 + [(9.0, 0.3, False)] + [(0.0, 0.3, True)] * 3 + [(0.0, 4.0, False)] \
            + [(0.0, 0.3, True)] * 3
        for i, (north, h_acc, good) in enumerate(plan):
            t = t0 + i * DT
            await asyncio.sleep(max(0.0, t - time.time()))
            f = fix_at(time.time(), north + 0.002 * i, 0.0, h_acc)
            offered.append((f, good and i >= CONFIRM - 1))
            sink.on_fix(f, type("I", (), {"t_recv": f.t_unix})())
        old = fix_at(time.time() - 2.0, -5.0)
        offered.append((old, False))
        sink.on_fix(old, type("I", (), {"t_recv": time.time()})())
        await asyncio.sleep(0.3)
        await sink.stop()
        await task
        return sink

    try:
        sink = asyncio.run(scenario())
        got = []
        while (m := uuv.recv_match(type="GPS_INPUT", blocking=True, timeout=0.3)) is not None:
            got.append(m)
    finally:
        uuv.close()
    valid = {(m.lat, m.lon, m.time_usec) for m in got if m.fix_type == 3}
    allowed = {(round(f.lat * 1e7), round(f.lon * 1e7), int(f.t_unix * 1e6)) for f, ok in offered if ok}
    refused = {(round(f.lat * 1e7), round(f.lon * 1e7), int(f.t_unix * 1e6)) for f, ok in offered if not ok}
    assert valid, "no valid GPS_INPUT at all"
    assert not valid & refused, "a GPS_INPUT carried a fix the gates refused"
    assert valid <= allowed
    rejected = sink.status(time.time())["gates"]["rejected"]
    assert rejected == {"h_acc": 1, "age": 1, "out_of_order": 0, "jump": 1, "unconfirmed": CONFIRM - 1}, rejected

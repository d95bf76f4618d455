"""GPS_INPUT as ArduSub's AP_GPS_MAV reads it: fields, GPS time, and the sender over a real pymavlink link."""

from __future__ import annotations

import asyncio
import time
from datetime import UTC, datetime, timedelta

import pytest
from live_helpers import free_port, until, wait_for

from groundstation.mavlink.ingest import mavutil
from groundstation.runtime.gps_input import (
    IGNORE_ALL,
    GpsInputSink,
    gps_input_fields,
    gps_time,
    mavlink_gps_link,
)
from localizer.fix import Fix
from localizer.fix_gate import FixGate


@pytest.mark.parametrize("t_unix", [1763800000.0, 1763800000.2504, 1_700_000_000.999, 1483228800.0])
def test_gps_time_matches_calendar(t_unix):
    gps_epoch = datetime(1980, 1, 6, tzinfo=UTC)
    # 18 leap s since 2017
    elapsed = datetime.fromtimestamp(t_unix, UTC) + timedelta(seconds=18) - gps_epoch
    week, ms = gps_time(t_unix)
    assert week == elapsed.days // 7
    assert ms == pytest.approx(
        ((elapsed.days % 7) * 86400 + elapsed.seconds) * 1000 + elapsed.microseconds / 1000, abs=1
    )


def _fix(t, **kw):
    base = {
        "t_unix": t,
        "status": "ok",
        "u": 100.0,
        "v": 200.0,
        "lat": 63.44,
        "lon": 10.4,
        "alt_amsl_m": -0.7,
        "depth_m": 1.1,
        "h_acc_m": 0.3,
        "v_acc_m": 0.5,
    }
    return Fix(**{**base, **kw})


def _info(t_recv):
    return type("I", (), {"t_recv": t_recv})()


def _sink(link, max_age_s: float) -> GpsInputSink:
    """A sink whose gate confirms a target over 3 frames, not a second: these tests are about the sender."""
    return GpsInputSink(
        link,
        hz=10.0,
        max_age_s=max_age_s,
        gate=FixGate(max_age_s=max_age_s, confirm_s=0.05, confirm_fixes=3),
    )


def _offer_confirmed(sink, t, **kw):
    """The fix at ``t`` after the two frames before it at the same place: the confirmation of :func:`_sink`'s gate."""
    for dt in (2 / 30, 1 / 30, 0.0):
        sink.on_fix(_fix(t - dt, **kw), info=_info(t - dt))


def test_fresh_fix_fields():
    t = 1763800000.0
    f = gps_input_fields(_fix(t), t + 0.05, max_age_s=0.5)
    assert f["fix_type"] == 3
    assert (f["lat"], f["lon"]) == (634400000, 104000000)
    assert f["alt"] == pytest.approx(-0.7)
    assert f["horiz_accuracy"] == pytest.approx(0.3) and f["vert_accuracy"] == pytest.approx(0.5)
    assert f["hdop"] == pytest.approx(0.3) and f["vdop"] == pytest.approx(0.5)
    assert f["satellites_visible"] >= 6
    assert f["ignore_flags"] == 8 | 16 | 32  # velocities and speed accuracy only
    assert (f["time_week"], f["time_week_ms"]) == gps_time(t)


@pytest.mark.parametrize("fix,dt", [(None, 0.0), ("stale", 0.8), ("lost", 0.0), ("nan", 0.0)])
def test_no_fix_is_explicit(fix, dt):
    t = 1763800000.0
    f = {
        None: None,
        "stale": _fix(t),
        "lost": _fix(t, status="lost"),
        "nan": _fix(t, lat=float("nan")),
    }[fix]
    out = gps_input_fields(f, t + dt, max_age_s=0.5)
    assert out["fix_type"] == 1 and out["ignore_flags"] == IGNORE_ALL
    assert out["lat"] == 0 and out["lon"] == 0 and out["satellites_visible"] == 0


class _Received:
    """The GPS_INPUT messages a UDP endpoint got so far: (system, component, fix_type, time_usec in s)."""

    def __init__(self, port: int):
        self.conn = mavutil().mavlink_connection(f"udpin:127.0.0.1:{port}")
        self.got: list[tuple[int, int, int, float]] = []

    def __call__(self) -> list[tuple[int, int, int, float]]:
        while (m := self.conn.recv_match(type="GPS_INPUT", blocking=False)) is not None:
            self.got.append(
                (m.get_srcSystem(), m.get_srcComponent(), m.fix_type, m.time_usec / 1e6)
            )
        return self.got

    def types(self) -> list[int]:
        return [ft for _, _, ft, _ in self()]


async def _run_sink(sink, scenario):
    """``scenario()`` while the sink runs; then the sink stopped."""
    task = asyncio.create_task(sink.run())
    try:
        return await scenario()
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)


def test_sender_over_pymavlink_rate_fix_and_expiry():
    port = free_port()
    received = _Received(port)
    sink = _sink(mavlink_gps_link(f"udpout:127.0.0.1:{port}"), max_age_s=0.5)

    async def scenario():
        await until(lambda: len(received()) >= 10, 30.0, "no fix yet: ten no-fix messages")
        t_fix = time.time()
        _offer_confirmed(sink, t_fix)
        types = received.types

        def expired() -> bool:
            return 3 in types() and types()[-1] == 1

        await until(expired, 30.0, lambda: f"the fix sent, then no fix again: {types()}")
        return t_fix

    try:
        t_fix = asyncio.run(_run_sink(sink, scenario))
    finally:
        received.conn.close()
    got = received.got
    assert {(s, c) for s, c, _, _ in got} == {(245, 220)}
    types = [ft for _, _, ft, _ in got]
    first = types.index(3)
    assert first >= 10 and set(types[:first]) == {1}
    valid = [t for _, _, ft, t in got if ft == 3]
    assert 2 <= len(valid) <= 7  # kept at 10 Hz for its 0.5 s of validity (+ the immediate send)
    assert all(t == pytest.approx(t_fix, abs=1e-6) for t in valid)
    expiry = got[first + len(valid)]  # the first no-fix after it, stamped when sent
    assert expiry[2] == 1 and expiry[3] >= t_fix + 0.5 - 1e-3  # not before the fix was 0.5 s old


@pytest.mark.parametrize("status", ["lost", "awaiting_target", "released"])
def test_tracker_loss_ends_the_fix_at_once(status):
    """A lost, dropped or released target must not keep the last position alive for max_age_s."""
    port = free_port()
    received = _Received(port)
    sink = _sink(mavlink_gps_link(f"udpout:127.0.0.1:{port}"), max_age_s=5.0)

    async def scenario():
        await until(lambda: received(), 30.0, "the sender's first message")
        t = time.time()
        _offer_confirmed(sink, t)
        await until(lambda: 3 in received.types(), 30.0, "the fix")
        t_loss = time.time()
        sink.on_fix(_fix(t + 0.03, status=status), info=_info(t + 0.03))

        def after_loss() -> list[int]:  # from the first no-fix sent after the loss on
            got = received()
            k = next((i for i, m in enumerate(got) if m[2] == 1 and m[3] > t_loss), len(got))
            return [ft for _, _, ft, _ in got[k:]]

        await until(lambda: len(after_loss()) >= 4, 30.0, "the no-fix messages after the loss")
        return after_loss()

    try:
        after = asyncio.run(_run_sink(sink, scenario))
    finally:
        received.conn.close()
    assert set(after) == {1}  # no fix after the loss, though the last one was valid for 5 s
    assert 3 in [ft for _, _, ft, _ in received.got]


def test_injection_through_blueos_mavlink_in():
    import json
    import socket

    from groundstation.runtime.zenoh_mavlink import ZenohMavlinkIn
    from groundstation.runtime.zenoh_session import open_session

    ep = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    skyfix_side, blueos_side = open_session(listen=[ep]), open_session(connect=[ep])
    got = []
    sub = blueos_side.declare_subscriber(
        "mavlink/in", lambda s: got.append((str(s.encoding), s.payload.to_string()))
    )

    def types() -> list[int]:
        return [json.loads(p)["message"].get("fix_type") for _, p in got]

    async def scenario():
        probe = skyfix_side.declare_publisher(
            "mavlink/in"
        )  # BlueOS's subscription seen from skyfix
        await until(lambda: probe.matching_status.matching, 30.0, "the subscription at mavlink/in")
        probe.undeclare()
        sink = _sink(ZenohMavlinkIn(skyfix_side, "mavlink/in"), max_age_s=0.5)

        async def one_fix():
            await until(lambda: got, 30.0, "the sender's first message at mavlink/in")
            _offer_confirmed(sink, time.time())
            await until(lambda: 3 in types(), 30.0, "the fix at mavlink/in")

        await _run_sink(sink, one_fix)

    def last_is_no_fix() -> (
        bool
    ):  # the stop's no-fix, the newest sample (Zenoh delivers after the put returns)
        return bool(got) and json.loads(got[-1][1])["message"].get("fix_type") == 1

    try:
        asyncio.run(scenario())
        wait_for(last_is_no_fix, 15.0, "the last GPS_INPUT (no fix) at mavlink/in")
    finally:
        sub.undeclare()
        blueos_side.close()
        skyfix_side.close()
    msgs = [json.loads(p) for enc, p in got]
    assert all(enc == "application/json" for enc, _ in got) and len(msgs) >= 4
    assert {(m["header"]["system_id"], m["header"]["component_id"]) for m in msgs} == {(245, 220)}
    assert [m["header"]["sequence"] for m in msgs] == list(range(len(msgs)))
    assert msgs[0]["message"]["type"] == "HEARTBEAT"
    assert msgs[0]["message"]["mavtype"] == {"type": "MAV_TYPE_ONBOARD_CONTROLLER"}
    gps = [m["message"] for m in msgs if m["message"]["type"] == "GPS_INPUT"]
    assert gps[0]["fix_type"] == 1 and gps[0]["ignore_flags"] == {"bits": IGNORE_ALL}
    assert gps[-1]["fix_type"] == 1  # stopping: the last message says no fix
    valid = [m for m in gps if m["fix_type"] == 3]
    assert valid and valid[0]["lat"] == 634400000 and valid[0]["ignore_flags"] == {"bits": 56}


def test_every_reason_for_no_fix_has_plain_words():
    """Each word a no-fix message can be for (a fix status, a gate's refusal, the sink's own) has the operator's
    words; the status's schema lists exactly these."""
    from groundstation.messages import GpsInputStatus
    from groundstation.runtime.no_fix import NO_FIX_WHY
    from localizer.fix_gate import REASONS
    from localizer.status import STATUSES

    words = (
        set(STATUSES) - {"ok"}
        | {f"gate_{r}" for r in REASONS}
        | {"no_frames", "no_new_fix", "stopped"}
    )
    assert set(NO_FIX_WHY) == words and all(NO_FIX_WHY.values())
    schema = GpsInputStatus.model_json_schema()["properties"]["no_fix_reason"]["anyOf"][0]
    assert set(schema["enum"]) == words


def test_the_status_says_what_was_sent_and_why_no_fix():
    """The status names the last message's fix (its h_acc and exposure) or why there was none: no frame yet, a
    fix aged out with nothing after it, the newest frame's status, the gates confirming a new target, stopped."""
    from groundstation.messages import GpsInputStatus

    seen = []

    async def scenario():  # to a port nobody reads: what is sent is the test's business, not what arrives
        sink = _sink(mavlink_gps_link(f"udpout:127.0.0.1:{free_port()}"), max_age_s=0.5)
        task = asyncio.create_task(sink.run())

        async def until(sending, what):
            end = time.monotonic() + 10.0
            while sink.sending() != sending:
                assert time.monotonic() < end, (
                    f"timed out waiting for {what}: {sink.status(time.time())}"
                )
                await asyncio.sleep(0.01)
            seen.append(GpsInputStatus.model_validate(sink.status(time.time())))

        await until((1, "no_frames"), "no fix: no frame yet")
        t = time.time()
        _offer_confirmed(sink, t)
        await until((3, None), "the fix")
        await until((1, "no_new_fix"), "the fix aged out")
        sink.on_fix(_fix(time.time(), status="stale_attitude"), info=_info(time.time()))
        await until((1, "stale_attitude"), "the newest frame's status")
        sink.on_fix(_fix(time.time(), status="lost"), info=_info(time.time()))
        await until((1, "lost"), "the loss")
        sink.on_fix(_fix(time.time()), info=_info(time.time()))
        await until((1, "gate_unconfirmed"), "the gates confirming the target found again")
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
        seen.append(GpsInputStatus.model_validate(sink.status(time.time())))
        return t

    t = asyncio.run(scenario())
    first, fix, aged, stale, lost, unconfirmed, stopped = seen
    assert first.no_fix_why == "no frame tracked yet" and first.sent_h_acc_m is None
    assert (
        fix.no_fix_reason is None and fix.sent_h_acc_m == pytest.approx(0.3) and fix.sent_fix_t == t
    )
    assert t <= fix.last_sent_t <= aged.last_sent_t
    assert aged.no_fix_why == "no new fix: video stopped or stalled" and aged.sent_fix_t is None
    assert (stale.no_fix_why, lost.no_fix_why) == (
        "attitude telemetry stale",
        "tracker lost the UUV",
    )
    assert unconfirmed.no_fix_why == "confirming the target"
    assert (stopped.last_fix_type, stopped.no_fix_reason, stopped.no_fix_why) == (
        1,
        "stopped",
        "skyfix stopped",
    )

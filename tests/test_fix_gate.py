"""Safety gates on what goes out as a valid fix: the track, fix streams replayed, generated sessions, real GPS_INPUT.

The streams (``gate_streams.py``) carry their truth: which fixes are not the UUV (a jump, a
look-alike) and where the UUV really is. The generated sessions are tracked and located by
the real pipeline (``process_session``); every ok fix there is within centimetres of the
truth, so none may be refused once its target has been confirmed.
"""

from __future__ import annotations

import asyncio
import math
import shutil
import time
from pathlib import Path

import numpy as np
import pytest
from live_helpers import free_port, until

from groundstation.mavlink.ingest import mavutil
from groundstation.offline.process import process_session
from groundstation.runtime.gps_input import LOSS_STATUSES, GpsInputSink, mavlink_gps_link
from groundstation.session.read import load_session
from groundstation.testing import gate_streams
from groundstation.testing.gate_streams import (
    BEFORE_S,
    HZ,
    LAT0,
    LON0,
    M_PER_DEG,
    T0,
    accelerate,
    bounded_fit_residual_m,
    crossing,
    fix_at,
    lookalike,
    offer,
    ramp,
    step,
    turn,
    vectored_thrusters,
)
from localizer.fix import Fix
from localizer.fix_gate import CONFIRM_S, DIVERGED_S, MAX_ACCEL_MPS2, MAX_SPEED_MPS, FixGate
from localizer.thrusters import DRAG_LINEAR, DRAG_QUADRATIC, MASS_KG
from localizer.uuv_track import WHITE_FLOOR_M, Scatter, UuvTrack, common_change_share
from sim_fixtures.bundle import BUNDLED_DIR
from sim_fixtures.generate import generate
from sim_fixtures.scenario import load_scenario, with_overrides

V, A = MAX_SPEED_MPS["bluerov2"], MAX_ACCEL_MPS2["bluerov2"]
SCENARIOS = Path(__file__).resolve().parents[1] / "sim_fixtures" / "scenarios"


def gate_on(stream) -> tuple[FixGate, np.ndarray]:
    gate = FixGate()
    return gate, offer(gate, stream, gate.target_lost)


# -- the track, by hand --------------------------------------------------------------------------
def test_distance_by_hand():
    """A track of one fix at rest (white share 0: the floor); 0.1 s later a fix 0.25 m north.

    Top speed: it can be 1.5·0.1 = 0.15 m away; 0.10 m beyond, over √(floor² + floor² + the common
    change 2·(1 − e^(−½(0.1/5)²))·0.01) = √(2.04e-4) m: 7.0 sigma. Acceleration: 0.015 m from the
    point at rest, and the unknown velocity (1-sigma 1.5 m/s) spreads it by 0.15 m: 1.56 sigma.
    """
    C = np.eye(2) * 0.01
    track = UuvTrack(V, A, 0.0, np.zeros(2), C, share=0.0)
    d, radius, _ = track.distance(0.1, np.array([0.25, 0.0]), C, share=0.0)
    change = 2 * (1 - math.exp(-0.5 * (0.1 / 5.0) ** 2)) * 0.01
    assert common_change_share(0.1) * C[0, 0] == pytest.approx(change)
    assert radius == pytest.approx(0.15)
    assert d == pytest.approx(0.10 / math.sqrt(2 * WHITE_FLOOR_M**2 + change), rel=1e-6)
    assert (
        track.sigmas(0.1, np.array([0.25, 0.0]), C, share=0.0) == d
    )  # what the gates compute per fix
    by_accel = (0.25 - 0.5 * A * 0.01) / math.sqrt(
        WHITE_FLOOR_M**2 + 0.01 * V**2 + WHITE_FLOOR_M**2 + change
    )
    assert by_accel < d


def test_scatter_measures_the_white_share_not_the_motion_or_the_common_error():
    """White error 2 cm per axis on fixes claiming 0.2 m per axis: a share of 0.01, whatever the UUV and a slow
    common error do (here a 1 m/s drift and a 0.3 m bias swinging over 10 s)."""
    rng = np.random.default_rng(11)
    C = np.eye(2) * 0.2**2
    scatter = Scatter()
    for i in range(300):
        t = i / HZ
        truth = np.array([1.0 * t, 0.0]) + 0.3 * np.array([math.sin(2 * math.pi * t / 10), 0.0])
        scatter.add(t, truth + rng.normal(0.0, 0.02, 2), C)
    assert scatter.share == pytest.approx(0.02**2 / 0.2**2, rel=0.3)


# -- streams: the failures the issue measured ------------------------------------------------------
@pytest.mark.parametrize("h_acc_m", [0.4, 0.05])
@pytest.mark.parametrize(
    "make",
    [
        lambda h: step(h, 0.8),
        lambda h: step(h, 10.0),
        lambda h: lookalike(h, 3.0, loss_s=1.0, seconds=1.5),
        crossing,
    ],
    ids=["step 0.8 m", "step 10 m", "look-alike 3 m after a loss", "a vehicle crossing"],
)
def test_no_wrong_fix_goes_out(make, h_acc_m):
    stream = make(h_acc_m)
    _, valid = gate_on(stream)
    assert not (valid & stream.wrong).any(), (
        f"{stream.name}: {(valid & stream.wrong).sum()} wrong fixes valid"
    )
    assert valid[stream.real_after(CONFIRM_S)].all()


@pytest.mark.parametrize("h_acc_m", [0.4, 0.05])
def test_a_jump_leaves_the_gate_diverged_until_the_target_is_lost(h_acc_m):
    """After a 0.8 m jump every fix is refused: ``diverged`` once the track has gone HOLD_S without one, for
    DIVERGED_S; a lost target ends it, and the UUV found again where it was is valid a second later."""
    stream = step(h_acc_m, 0.8, seconds=3.0)
    gate, valid = gate_on(stream)
    assert (
        gate.state == "diverged" and gate.rejected["diverged"] > 0 and not valid[stream.wrong].any()
    )
    gate.target_lost()
    t_back = stream.fixes[-1].t_unix + 0.5
    back = [fix_at(t_back + i / HZ, 0.0, 0.0, h_acc_m) for i in range(round(1.5 * HZ))]
    ok = [gate.check(f, f.t_unix + 0.05) is None for f in back]
    first = ok.index(True)
    assert back[first].t_unix - t_back == pytest.approx(CONFIRM_S, abs=1.5 / HZ) and all(ok[first:])
    assert gate.state == "tracking"


def test_diverged_ends_after_its_time():
    stream = step(0.05, 0.8, seconds=DIVERGED_S + 2.0)
    _, valid = gate_on(stream)
    t = np.array([f.t_unix for f in stream.fixes])
    refused_for = t[valid & stream.wrong].min() - t[stream.wrong].min()
    # then acquired again: 0.8 m is in reach
    assert DIVERGED_S <= refused_for <= DIVERGED_S + CONFIRM_S + 0.1


def test_the_gate_does_not_forget_where_the_uuv_was():
    """A look-alike 3 m away found after a 1 s loss: the UUV (1.5 m/s) cannot be there, so that lock is not the
    UUV — refused for DIVERGED_S, even once the UUV could have got there; then the tracker loses it, finds the UUV
    where it was, and that is valid a second later."""
    stream = lookalike(0.05, 3.0, loss_s=1.0, seconds=4.0)
    gate = FixGate()
    reasons = [gate.check(f, f.t_unix + 0.05) if f.ok else gate.target_lost() for f in stream.fixes]
    wrong = [r for r, w in zip(reasons, stream.wrong, strict=True) if w]
    assert set(wrong) == {"diverged"} and gate.state == "diverged", set(wrong)
    assert "not the UUV" in gate.status(stream.fixes[-1].t_unix)["last_refusal"]
    gate.target_lost()
    t_back = stream.fixes[-1].t_unix + 0.2
    back = [fix_at(t_back + i / HZ, 0.0, 0.0, 0.05) for i in range(round(1.5 * HZ))]
    ok = [gate.check(f, f.t_unix + 0.05) is None for f in back]
    assert back[ok.index(True)].t_unix - t_back == pytest.approx(CONFIRM_S, abs=1.5 / HZ) and all(
        ok[ok.index(True) :]
    )


def test_a_look_alike_where_the_uuv_could_be_is_taken():
    """The honest limit: 1 m away after a 1 s loss the UUV could be there; consistent for a second, it is taken."""
    stream = lookalike(0.05, 1.0, loss_s=1.0, seconds=2.0)
    _, valid = gate_on(stream)
    t = np.array([f.t_unix for f in stream.fixes])
    assert t[valid & stream.wrong].min() - t[stream.wrong].min() == pytest.approx(
        CONFIRM_S, abs=1.5 / HZ
    )


def test_an_abrupt_start_at_top_speed_is_refused_until_the_uuv_could_have_caught_up():
    """A fix stream at rest that moves at top speed from one frame to the next (a lock jumping onto something
    passing by; any motion within the bounds is 7 cm off it): from its third frame on it is refused, until the
    track's UUV, accelerating at its bound from the track's last fix, could be there (½·a·Δ² and the velocity's
    uncertainty: 0.4–0.6 s)."""
    assert bounded_fit_residual_m(V, A) > 0.05
    for h_acc_m in (0.4, 0.05):
        stream = ramp(h_acc_m, V, seconds=1.0)
        _, valid = gate_on(stream)
        start = round(BEFORE_S * HZ)
        assert (
            valid[start : start + 2].all() and not valid[start + 2 : start + round(0.4 * HZ)].any()
        ), h_acc_m


def test_the_issue_ramp_is_a_real_start_to_within_millimetres():
    """Why the issue's ramp (0.35 m/s from one frame to the next, 0.7 m in 2 s) is not refused: a BlueROV2
    accelerating within its bound follows it to 4 mm — the 3 mm white error of the cleanest stream. The gate
    passes it, as it must pass the real start; a drift is for the tracker to catch."""
    assert bounded_fit_residual_m(0.35, A) < 0.004
    stream = ramp(0.05)
    _, valid = gate_on(stream)
    assert valid[stream.wrong].all()


# -- real motion at the bounds ---------------------------------------------------------------------
def _path_from_acceleration(accel, v0, hz: float, seconds: float = 5.0) -> np.ndarray:
    """Positions at ``hz`` of a point whose acceleration is ``accel(t, v)`` (integrated at 1 kHz), held within V."""
    dt, step_every = 1e-3, round(1.0 / (hz * 1e-3))
    p, v, out = np.zeros(2), np.array(v0, float), []
    for k in range(round(seconds / dt)):
        if k % step_every == 0:
            out.append(p.copy())
        v = v + accel(k * dt, v) * dt
        v *= min(1.0, V / max(np.hypot(*v), 1e-12))
        p = p + v * dt
    return np.array(out)


MANOEUVRES = {
    "stop from top speed": (
        [V, 0.0],
        lambda t, v: np.array([-A, 0.0]) if t > 2 and v[0] > 0 else np.zeros(2),
    ),
    "zigzag ±a every 0.3 s": (
        [1.0, 0.0],
        lambda t, v: np.array([0.0, A if int(t / 0.3) % 2 else -A]) * (t > 2),
    ),
    "bang-bang from rest": (
        [0.0, 0.0],
        lambda t, v: np.array([A if int(t / 0.5) % 2 == 0 else -A, 0.0]) * (t > 2),
    ),
    "turning at top speed": (
        [V, 0.0],
        lambda t, v: A * np.array([-v[1], v[0]]) / max(np.hypot(*v), 1e-9),
    ),
}


@pytest.mark.parametrize("hz", [10.0, 30.0, 60.0])
@pytest.mark.parametrize("name", list(MANOEUVRES))
def test_real_motion_at_the_bounds_is_never_refused(name, hz, monkeypatch):
    monkeypatch.setattr(gate_streams, "HZ", hz)
    v0, accel = MANOEUVRES[name]
    path = _path_from_acceleration(accel, v0, hz)
    for h_acc_m in (0.4, 0.05):
        stream = gate_streams._stream(name, path, path, h_acc_m, seed=7)
        _, valid = gate_on(stream)
        late = stream.real_after(CONFIRM_S)
        assert valid[late].all(), (
            f"{name} at {hz:g} Hz, h_acc {h_acc_m}: {(~valid[late]).sum()} refused"
        )


@pytest.mark.parametrize("h_acc_m", [0.4, 0.05])
def test_accelerating_from_rest_to_top_speed_and_turning_are_never_refused(h_acc_m):
    for stream in (accelerate(h_acc_m, A, V), turn(h_acc_m, V, A)):
        _, valid = gate_on(stream)
        assert valid[stream.real_after(CONFIRM_S)].all(), stream.name


# -- the thrusters' word --------------------------------------------------------------------------
def gate_with_thrusters(
    stream, pushing=lambda t: False, outputs_hz: float = 10.0
) -> tuple[FixGate, np.ndarray]:
    gate = FixGate(thrusters=vectored_thrusters())
    return gate, offer(gate, stream, gate.target_lost, gate.thrusters, pushing, outputs_hz)


def offset_m(stream) -> np.ndarray:
    """Each fix's distance from the truth (m), on the streams' own spherical Earth."""
    seen = np.array(
        [
            [(f.lat - LAT0) * M_PER_DEG, (f.lon - LON0) * M_PER_DEG * math.cos(math.radians(LAT0))]
            for f in stream.fixes
        ]
    )
    return np.linalg.norm(seen - stream.truth_ne, axis=1)


@pytest.mark.parametrize("h_acc_m", [0.4, 0.05])
def test_the_issue_ramp_with_the_thrusters_idle_is_refused(h_acc_m):
    """The issue's ramp (0.7 m in 2 s) while ArduSub's horizontal thrusters stay at 1500 µs: what the water can do
    (0.05 m/s²) follows it for a few frames only. Nothing more than 6 cm off goes out (the first 5 frames), and
    within HOLD_S more the gate is ``diverged``: the rest of the ramp is refused."""
    stream = ramp(h_acc_m)
    gate, valid = gate_with_thrusters(stream)
    off = offset_m(stream)
    start = round(BEFORE_S * HZ)
    assert valid[:start][
        stream.real_after(CONFIRM_S)[:start]
    ].all()  # the UUV at rest before it: taken
    assert off[valid & stream.wrong].max() <= 0.06, off[valid & stream.wrong]
    assert not valid[start + 6 :].any() and gate.state == "diverged", gate.last_refusal
    assert (
        "diverged" in gate.rejected and gate.status(stream.fixes[-1].t_unix)["thrusters"] == "idle"
    )


def test_the_same_ramp_with_the_thrusters_pushing_passes_as_a_real_start():
    """The same fixes while the thrusters push: the UUV starting, as far as the fixes can tell."""
    stream = ramp(0.05)
    _, valid = gate_with_thrusters(stream, pushing=lambda t: t >= T0 + BEFORE_S - 0.1)
    assert valid[stream.wrong].all()


@pytest.mark.parametrize("late_s", [-0.1, 0.0, 0.1])
@pytest.mark.parametrize("name", list(MANOEUVRES))
def test_real_motion_at_the_bounds_with_the_thrusters_pushing_is_never_refused(name, late_s):
    """The manoeuvres at 30 Hz with the thrusters idle until the motion begins (``late_s``: the first pushing
    output arrives that long after the motion's start — one output period late at 10 Hz), pushing after."""
    v0, accel = MANOEUVRES[name]
    path = _path_from_acceleration(accel, v0, HZ)
    moves = 2.0 if name != "turning at top speed" else 0.0
    stream = gate_streams._stream(name, path, path, 0.05, seed=7)
    _, valid = gate_with_thrusters(stream, pushing=lambda t: t >= T0 + moves + late_s)
    late = stream.real_after(CONFIRM_S)
    assert valid[late].all(), f"{name}, outputs {late_s:+g} s: {(~valid[late]).sum()} refused"


@pytest.mark.parametrize("h_acc_m", [0.4, 0.05])
def test_coasting_and_drifting_with_the_thrusters_idle_are_never_refused(h_acc_m):
    """Thrusters idle: a BlueROV2 coasting from top speed, slowed by its drag alone (Wu's surge damping, integrated
    here at 1 kHz), and one carried by a current of 0.3 m/s whose direction turns at the water's 0.05 m/s²."""

    def coast(t, v):
        speed = math.hypot(*v)
        return -(DRAG_LINEAR * speed + DRAG_QUADRATIC * speed**2) / MASS_KG * v / max(speed, 1e-12)

    def current(t, v):
        return 0.05 * np.array([-v[1], v[0]]) / max(math.hypot(*v), 1e-12)

    for name, v0, accel in (("coasting", [V, 0.0], coast), ("current", [0.3, 0.0], current)):
        path = _path_from_acceleration(accel, v0, HZ, seconds=6.0)
        stream = gate_streams._stream(name, path, path, h_acc_m, seed=8)
        gate, valid = gate_with_thrusters(stream)
        late = stream.real_after(CONFIRM_S)
        assert valid[late].all(), f"{name}: {(~valid[late]).sum()} refused: {gate.last_refusal}"


def test_stale_or_unknown_thrusters_leave_the_vehicle_bound():
    """Outputs at 1 Hz (gaps over STALE_S), or a frame whose motors are not known here: no evidence, the ramp
    passes as without them (the fixes alone cannot tell)."""
    stream = ramp(0.05)
    _, valid = gate_with_thrusters(stream, outputs_hz=1.0)
    assert valid[stream.wrong].all()
    gate = FixGate(thrusters=vectored_thrusters())
    gate.thrusters.param("FRAME_CONFIG", 7.0)  # custom
    valid = offer(gate, stream, gate.target_lost, gate.thrusters)
    assert (
        valid[stream.wrong].all() and gate.status(stream.fixes[-1].t_unix)["thrusters"] == "unknown"
    )


# -- the simple gates ------------------------------------------------------------------------------
def test_accuracy_age_order_and_the_prediction_window():
    gate = FixGate(max_h_acc_m=2.5, max_age_s=0.5)
    fixes = [fix_at(T0 + i / HZ, 0.0, 0.0, 0.3) for i in range(round(1.5 * HZ))]
    assert [gate.check(f, f.t_unix) for f in fixes][-1] is None and gate.state == "tracking"
    t = fixes[-1].t_unix + 1 / HZ
    assert gate.check(fix_at(t, 0, 0, 2.6), t) == "h_acc"
    assert gate.check(fix_at(t, 0, 0, float("nan")), t) == "h_acc"
    assert gate.check(fix_at(t, 0, 0, 0.3), t + 0.51) == "age"
    assert gate.check(fixes[0], fixes[0].t_unix) == "out_of_order"
    # pixel (640, 360)
    assert gate.check(fix_at(t, 0, 0, 0.3), t, window=(700.0, 0.0, 100.0, 100.0)) == "prediction"
    assert gate.check(fix_at(t, 0, 0, 0.3), t, window=(600.0, 300.0, 100.0, 100.0)) is None
    assert {k: v for k, v in gate.rejected.items() if v} == {
        "h_acc": 2,
        "age": 1,
        "out_of_order": 1,
        "prediction": 1,
        "unconfirmed": round(CONFIRM_S * HZ),
    }


def test_status_has_the_state_the_reasons_and_the_track():
    stream = accelerate(0.05, A, V, seconds=1.0)
    gate, _ = gate_on(stream)
    s = gate.status(stream.fixes[-1].t_unix + 0.05)
    assert s["state"] == "tracking" and s["chain"] is None and s["reach_m"] is None
    tr = s["track"]
    speed = math.hypot(tr["vn_mps"], tr["ve_mps"])
    # north-east
    assert speed == pytest.approx(V, abs=0.1) and tr["vn_mps"] == pytest.approx(
        tr["ve_mps"], abs=0.1
    )
    last = stream.fixes[-1]
    assert tr["lat"] == pytest.approx(last.lat, abs=0.05 / 111_195) and tr["sigma_n_m"] >= 0.0
    gate.target_lost()
    s = gate.status(last.t_unix + 1.0)
    assert s["state"] == "acquiring" and s["reach_m"] == pytest.approx(V * 1.0)


# -- generated sessions through the real pipeline --------------------------------------------------
@pytest.fixture(scope="module")
def sessions(tmp_path_factory):
    """The bundled occlusion (a loss and a re-acquisition), vehicle_yaw and oblique_2m, and a short dive out of
    sight and back (as tests/test_tracking_dive.py), each tracked and located by the pipeline."""
    out = {
        name: process_session(load_session(BUNDLED_DIR / name), use_track=False)
        for name in ("occlusion", "vehicle_yaw", "oblique_2m")
    }
    if shutil.which("ffmpeg"):
        sc = with_overrides(
            load_scenario(SCENARIOS / "dive.toml"),
            duration_s=5.5,
            site={"attenuation_bgr_per_m": (1.3, 1.2, 2.0), "floor_depth_m": 8.0},
            uuv={"depth_profile": ((0.8, 1.0), (2.2, 4.0), (3.0, 4.0), (4.4, 1.0))},
        )
        path = tmp_path_factory.mktemp("sessions") / "dive"
        generate(sc, path)
        out["dive"] = process_session(load_session(path), use_track=False)
    return out


def test_generated_sessions_no_real_fix_refused_after_the_first_second(sessions):
    assert "dive" in sessions or shutil.which("ffmpeg") is None
    for name, fixes in sessions.items():
        gate = FixGate()
        t_start, refused_late, late = None, [], 0
        for i in range(len(fixes)):
            f = fixes[i]
            if not f.ok:
                if f.status in LOSS_STATUSES:
                    gate.target_lost()
                    t_start = None
                continue
            t_start = f.t_unix if t_start is None else t_start
            late += f.t_unix - t_start > CONFIRM_S + 1e-9
            if gate.check(f, f.t_unix + 0.05) is not None and f.t_unix - t_start > CONFIRM_S + 1e-9:
                refused_late.append((round(f.t_unix - fixes.t_unix[0], 3), gate.last_refusal))
        assert late > 20 and not refused_late, (
            f"{name}: {late} fixes after the first second; {refused_late[:3]}"
        )


# -- real GPS_INPUT --------------------------------------------------------------------------------
def test_gps_input_never_carries_a_refused_fix():
    """Real GPS_INPUT at a pymavlink endpoint: a confirmed UUV goes out; a 9 m jump, a poor and an old fix never
    do, nor anything before the target was confirmed."""
    port = free_port()
    uuv = mavutil().mavlink_connection(f"udpin:127.0.0.1:{port}")
    offered: list[tuple[Fix, bool]] = []  # (fix, whether it may go out)

    async def scenario() -> GpsInputSink:
        sink = GpsInputSink(mavlink_gps_link(f"udpout:127.0.0.1:{port}"), hz=10.0, max_age_s=0.5)
        task = asyncio.create_task(sink.run())
        t0 = time.time()
        plan = [(0.0, 0.3)] * 45 + [(9.0, 0.3)] + [(0.0, 0.3)] * 3 + [(0.0, 4.0)] + [(0.0, 0.3)] * 3
        for i, (north, h_acc) in enumerate(plan):
            await asyncio.sleep(max(0.0, t0 + i / HZ - time.time()))
            f = fix_at(time.time(), north, 0.0, h_acc)
            offered.append((f, north == 0.0 and h_acc < 1 and f.t_unix - t0 > CONFIRM_S + 2 / HZ))
            sink.on_fix(f, type("I", (), {"t_recv": f.t_unix})())
        old = fix_at(time.time() - 2.0, -5.0, 0.0, 0.3)
        offered.append((old, False))
        sent = sink.sent
        sink.on_fix(old, type("I", (), {"t_recv": time.time()})())
        await until(lambda: sink.sent > sent, 30.0, "a message after the old fix")
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

    def key(f):
        return round(f.lat * 1e7), round(f.lon * 1e7), int(f.t_unix * 1e6)

    allowed = {key(f) for f, ok in offered if ok}
    refused = {
        key(f)
        for f, ok in offered
        if f.ok and not ok and f.t_unix - offered[0][0].t_unix > CONFIRM_S + 2 / HZ
    }
    assert valid, "no valid GPS_INPUT at all"
    assert not valid & refused, "a GPS_INPUT carried a fix the gates refused"
    assert valid <= allowed | {key(f) for f, _ in offered[: round((CONFIRM_S + 3 / HZ) * HZ)]}
    rejected = sink.status(time.time())["gates"]["rejected"]
    assert rejected["innovation"] == 1 and rejected["h_acc"] == 1 and rejected["age"] == 1, rejected
    assert rejected["unconfirmed"] >= round(CONFIRM_S * HZ) - 2, rejected

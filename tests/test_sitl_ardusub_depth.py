"""The UUV's depth as ArduSub really reports it: ArduPilot's ArduSub firmware (SITL) dives, rises and gets an EKF
origin mid-run while two ``skyfix run`` read its depth, one over Zenoh as BlueOS's mavlink-server publishes
it (``deploy/field.toml``'s depth settings, through ``blueos_bridge.py`` on SERIAL1) and one over a direct
MAVLink link (SERIAL2). SERIAL0 is the pilot and the observer (:class:`~ardusub_sitl.Observer`): it flies the
vehicle in ALT_HOLD with MANUAL_CONTROL, sets the EKF origin at 120 m (a lake) with SET_GPS_GLOBAL_ORIGIN,
then sends GPS_INPUT as skyfix's fixes would, so ArduSub sets its home (which turns
GLOBAL_POSITION_INT.relative_alt into an altitude above sea level: a depth reader must not follow it), and
reads the simulator's truth (SIM_STATE).

The truth: the simulator's pressure sensor is at SIM_STATE.alt (metres above the simulated sea level, its
water surface: ArduPilot's ``AP_Baro_SITL`` and ``SimpleUnderWaterAtmosphere``: 101325 Pa + 1024 kg/m³ ·
9.80665 m/s² · depth); ArduSub's depth is zero where its ground pressure (BARO{n}_GND_PRESS) was taken,
``(GND_PRESS − 101325) / (1024 · 9.80665)`` m below the surface by that model (the simulated vehicle floats
a few centimetres deep). True depth = −SIM_STATE.alt − that zero, interpolated at each depth sample's time.

Checked, per run, on its 1 Hz status: ``depth.depth_m`` follows the truth within :data:`MAX_ERROR_M` at the
time of its newest sample (``depth.t``) throughout the flight, or is None — never 0 while submerged — and
is None for at most :data:`MAX_WITHOUT_S` of the flight. ArduSub's own DataFlash log of the dive, read as
``skyfix import --depth`` reads it, has its clock within :data:`MAX_CLOCK_ERROR_S` of its live messages' and its
depths within :data:`MAX_ERROR_M` of the truth. The numbers are printed.
"""

from __future__ import annotations

import json
import socket
import sys
import threading
import time
import tomllib
from pathlib import Path

import numpy as np
import pytest
import zenoh
from ardusub_sitl import EXTRA_PARM, ArduSub, Observer, ardusub_files
from live_helpers import ROOT, free_port, skyfix, start, stop, wait_for, wait_until
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from groundstation.session.ardusub_log import read_ardusub_depth

pytestmark = pytest.mark.sitl

LAT, LON = 63.4400, 10.4000
ORIGIN_AMSL_M = 120.0  # SET_GPS_GLOBAL_ORIGIN mid-run: a lake 120 m above the sea
SEA_PA, SEA_PA_PER_M = (
    101325.0,
    1024.0 * 9.80665,
)  # the SITL's water: AP_Baro::SimpleUnderWaterAtmosphere
MAX_ERROR_M = 0.1
# the first status may come before the first depth: at most this much of the flight without
MAX_WITHOUT_S = 2.0
# The vehicle's water is sea water (1024 kg/m³): ArduSub's BARO_SPEC_GRAV says so (else its depths are 2.4 % long);
# arming checks off (no GPS at arming, as under water)
DEPTH_PARM = EXTRA_PARM + "BARO_SPEC_GRAV 1.024\nARMING_CHECK 0\n"
FIX_AGE_S = 0.065  # the GPS_INPUT's age on arrival: EXTRA_PARM's GPS1_DELAY_MS
MAX_CLOCK_ERROR_S = 0.02  # ArduSub's own log on UNIX time against its live messages' clock
KEEP = (*Observer.KEEP, "SIM_STATE", "PARAM_VALUE", "HOME_POSITION")
ALT_HOLD = 2  # ArduSub custom mode
DIVE, HOLD, RISE = 200, 500, 800  # MANUAL_CONTROL z: ~0.5 m/s down, hold the depth, ~0.5 m/s up
FORWARD = 500  # MANUAL_CONTROL x: half ahead
# the flight: (what, seconds); "origin", "gps" and "disarm" happen at the start of their phase
FLIGHT = (
    ("surface", 3.0),
    ("dive", 8.0),
    ("hold", 3.0),
    ("origin", 3.0),
    ("gps", 4.0),
    ("rise", 5.0),
    ("hold", 2.0),
    ("dive", 3.0),
    ("hold", 3.0),
    ("forward", 3.0),
    ("disarm", 3.0),
)
STICK = {
    "surface": HOLD,
    "dive": DIVE,
    "hold": HOLD,
    "origin": HOLD,
    "gps": HOLD,
    "rise": RISE,
    "forward": HOLD,
    "disarm": HOLD,
}


class Pilot:
    """MANUAL_CONTROL at 10 Hz on the observer's link, and GPS_INPUT at 5 Hz once :attr:`gps` is set."""

    def __init__(self, obs: Observer):
        self.obs, self.x, self.z, self.gps = obs, 0, HOLD, False
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="pilot", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        n = 0
        while not self._stop.wait(0.1):
            self.obs.send(mavlink2.MAVLink_manual_control_message(1, self.x, 0, self.z, 0, 0))
            n += 1
            if self.gps and n % 2 == 0:
                exposed = time.time() - FIX_AGE_S  # a fix carries its frame's time, as skyfix's do
                gps_s = exposed - 315964800 + 18  # GPS time: UTC + 18 leap seconds
                week, ms = int(gps_s // 604800), int(gps_s % 604800 * 1000)
                self.obs.send(
                    mavlink2.MAVLink_gps_input_message(
                        int(exposed * 1e6),
                        0,
                        56,
                        ms,
                        week,
                        3,
                        int(LAT * 1e7),
                        int(LON * 1e7),
                        0.0,
                        0.5,
                        0.5,
                        0,
                        0,
                        0,
                        0,
                        0.5,
                        0.5,
                        10,
                    )
                )

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)


def fly(obs: Observer, pilot: Pilot) -> dict[str, float]:
    """The flight (:data:`FLIGHT`); returns when each phase began (UNIX s) and its end."""
    obs.send(
        mavlink2.MAVLink_set_mode_message(1, mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, ALT_HOLD)
    )
    marks = {}
    for what, seconds in FLIGHT:
        marks.setdefault(what, time.time())
        if what == "dive" and "armed" not in marks:
            obs.send(
                mavlink2.MAVLink_command_long_message(
                    1, 1, mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0
                )
            )
            marks["armed"] = time.time()
        if what == "origin":
            obs.send(
                mavlink2.MAVLink_set_gps_global_origin_message(
                    1, int(LAT * 1e7), int(LON * 1e7), int(ORIGIN_AMSL_M * 1000), 0
                )
            )
        if what == "gps":
            pilot.gps = True
        if what == "disarm":
            obs.send(
                mavlink2.MAVLink_command_long_message(
                    1, 1, mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 0, 0, 0, 0, 0, 0
                )
            )
        pilot.x = FORWARD if what == "forward" else 0
        pilot.z = STICK[what]
        # the flight's own pace (the simulator runs in real time), not a condition
        time.sleep(seconds)
    marks["end"] = time.time()
    return marks


def read_param(obs: Observer, name: str, tries: int = 10) -> float:
    """A parameter's value as the autopilot answers PARAM_REQUEST_READ (asked again each second)."""

    def answer():
        values = [m.param_value for _, m in obs.of("PARAM_VALUE") if m.param_id == name]
        return values[-1] if values else None

    for _ in range(tries):
        obs.send(mavlink2.MAVLink_param_request_read_message(1, 1, name.encode(), -1))
        if wait_until(lambda: answer() is not None, 1.0):
            return answer()
    raise AssertionError(f"ArduSub did not answer PARAM_REQUEST_READ {name}")


class Statuses:
    """Every status message skyfix publishes on the given keys, with its receive time."""

    def __init__(self, endpoint: str, keys: list[str]):
        conf = zenoh.Config()
        conf.insert_json5("mode", '"peer"')
        conf.insert_json5("scouting/multicast/enabled", "false")
        conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
        self.session = zenoh.open(conf)
        self.got: dict[str, list[dict]] = {k: [] for k in keys}
        self.subs = [self.session.declare_subscriber(k, self._on) for k in keys]

    def _on(self, sample) -> None:
        self.got[str(sample.key_expr)].append(json.loads(sample.payload.to_bytes()))

    def close(self) -> None:
        for s in self.subs:
            s.undeclare()
        self.session.close()


def truth_depth(obs: Observer, zero_m: float) -> tuple[np.ndarray, np.ndarray]:
    """The simulator's depth of the pressure sensor below ArduSub's zero: (receive times, metres)."""
    sim = obs.of("SIM_STATE")
    return np.array([t for t, _ in sim]), np.array([-m.alt - zero_m for _, m in sim])


def depth_errors(statuses: list[dict], t_truth, d_truth, t0: float, t1: float) -> dict:
    """Each status's newest depth against the truth at its sample's time, over the flight ``[t0, t1]``."""
    errors, without, samples = [], 0.0, []
    period = 1.0
    for st in statuses:
        if not t0 <= st["t"] <= t1:
            continue
        d = st["depth"]
        if d["depth_m"] is None or d["t"] is None:
            without += period
            continue
        truth = float(np.interp(d["t"], t_truth, d_truth))
        errors.append(d["depth_m"] - truth)
        samples.append((round(st["t"] - t0, 1), d["depth_m"], round(truth, 3), d.get("source")))
    e = np.abs(np.array(errors)) if errors else np.array([np.inf])
    return {
        "n": len(errors),
        "max_m": float(e.max()),
        "median_m": float(np.median(e)),
        "without_s": without,
        "samples": samples,
        "signed": errors,
    }


def depth_settings() -> dict:
    """The depth keys of ``deploy/field.toml``."""
    field = tomllib.loads((ROOT / "deploy" / "field.toml").read_text())
    return {
        k: v
        for k, v in field.items()
        if k.startswith("depth_") or k == "uuv_max_vertical_speed_mps"
    }


def run_command(config: Path, name: str, endpoint: tuple[str, str], *extra: str) -> list[str]:
    return skyfix(
        "run",
        "--config",
        str(config),
        "--calibration",
        str(ROOT / "deploy" / "calibration.toml"),
        "--mavlink",
        f"udpin:127.0.0.1:{free_port()}",
        "--video",
        "none",
        "--gps-input",
        "none",
        "--no-ui",
        endpoint[0],
        endpoint[1],
        "--status-key",
        f"test/{name}/status",
        "--fix-key",
        f"test/{name}/fix",
        "--alive-key",
        f"test/{name}/alive",
        "--control-prefix",
        f"test/{name}/cmd",
        *extra,
    )


def test_ardusub_depth_through_blueos_and_mavlink(tmp_path):
    binary, sub_parm = ardusub_files()
    sitl = ArduSub(
        binary,
        sub_parm,
        tmp_path / "ardusub",
        home=(LAT, LON, 0.0, 0.0),
        extra_parm=DEPTH_PARM,
        keep=KEEP,
    )
    port = free_port(socket.SOCK_STREAM)
    listen, connect = (
        ("--zenoh-listen", f"tcp/127.0.0.1:{port}"),
        ("--zenoh-connect", f"tcp/127.0.0.1:{port}"),
    )
    config = tmp_path / "depth.toml"
    config.write_text("".join(f"{k} = {json.dumps(v)}\n" for k, v in depth_settings().items()))
    procs, statuses, pilot = {}, None, None
    keys = {"blueos": "test/blueos/status", "mavlink": "test/mavlink/status"}
    try:
        sitl.start()
        obs = sitl.observer
        obs.request_interval(mavlink2.MAVLINK_MSG_ID_SIM_STATE, 10.0)
        procs["blueos"] = start(run_command(config, "blueos", listen), tmp_path / "blueos.log")
        procs["mavlink"] = start(
            run_command(
                config,
                "mavlink",
                connect,
                "--depth-source",
                "mavlink",
                "--depth-mavlink",
                f"tcp:127.0.0.1:{sitl.ports['serial2']}",
            ),
            tmp_path / "mavlink.log",
        )
        procs["bridge"] = start(
            [
                sys.executable,
                str(ROOT / "tests" / "blueos_bridge.py"),
                f"tcp:127.0.0.1:{sitl.ports['serial1']}",
                f"tcp/127.0.0.1:{port}",
            ],
            tmp_path / "bridge.log",
        )
        statuses = Statuses(f"tcp/127.0.0.1:{port}", list(keys.values()))
        wait_for(
            lambda: (
                all(s and s[-1]["depth"]["depth_m"] is not None for s in statuses.got.values())
                or any(p.poll() is not None for p in procs.values())
            ),
            60,
            "a depth in both skyfix statuses",
        )
        assert all(p.poll() is None for p in procs.values()), {
            n: (tmp_path / f"{n}.log").read_text()[-3000:] for n in procs
        }
        pilot = Pilot(obs)
        marks = fly(obs, pilot)
        zero_m = (
            read_param(obs, "BARO1_GND_PRESS") - SEA_PA
        ) / SEA_PA_PER_M  # SITL: BARO_PRIMARY 0
    finally:
        if pilot:
            pilot.close()
        for p in procs.values():
            stop(p, 5.0)
        if statuses:
            statuses.close()
        sitl.stop()
    logs = {n: (tmp_path / f"{n}.log").read_text() for n in procs}
    t_truth, d_truth = truth_depth(obs, zero_m)
    texts = [m.text for _, m in obs.of("STATUSTEXT")]
    homes = obs.of("HOME_POSITION")
    gpi = [(t, m) for t, m in obs.of("GLOBAL_POSITION_INT") if t > marks["gps"] + 1.0]
    print(
        f"\nArduSub SITL {binary}: max depth {d_truth.max():.2f} m below its zero ({zero_m:.3f} m below the "
        f"simulated surface); EKF origin {'set' if any('origin set' in s for s in texts) else 'NOT set'}, "
        f"home {'set' if homes else 'not set'}; relative_alt after the home "
        f"{np.median([m.relative_alt for _, m in gpi]) / 1000 if gpi else float('nan'):.2f} m"
    )
    results = {}
    for name, key in keys.items():
        r = results[name] = depth_errors(
            statuses.got[key], t_truth, d_truth, marks["armed"], marks["end"]
        )
        sources = sorted({s[3] for s in r["samples"]})
        print(
            f"{name}: {r['n']} status samples during the {marks['end'] - marks['armed']:.0f} s flight, depth "
            f"error max {r['max_m']:.3f} m, median {r['median_m']:.3f} m, without depth {r['without_s']:.0f} s, "
            f"sources {sources}"
        )
    for name, r in results.items():
        why = f"\n{name}: {r['samples']}\nlog:\n{logs[name][-4000:]}"
        assert r["n"] >= 0.8 * (marks["end"] - marks["armed"]) - MAX_WITHOUT_S, why
        assert r["max_m"] <= MAX_ERROR_M, why
        assert r["without_s"] <= MAX_WITHOUT_S, why
        assert {s[3] for s in r["samples"]} == {"ardusub_pressure"}, (
            why
        )  # the sensor's parameters read at once
        last = statuses.got[keys[name]][-1]["depth"]
        check = [
            abs(st["depth"]["ardusub"]["disagreement_m"])
            for st in statuses.got[keys[name]]
            if st["depth"]["ardusub"]["disagreement_m"] is not None
        ]
        print(
            f"{name}: ArduSub EKF vs pressure depth, {len(check)} status samples: max |difference| "
            f"{max(check):.3f} m; rates {last['rates_hz']}; requests {last['rate_requests']}; jumps {last['jumps']}"
        )
        # after the home: the EKF's depth from the origin's altitude, agreeing with the pressure's
        assert (
            last["ardusub"]["ekf_origin_amsl_m"] == ORIGIN_AMSL_M
            and last["ardusub"]["ekf_depth_m"] is not None
        )
        assert max(check) <= 0.2 and last["jumps"] == 0, why
        assert (
            min(last["rates_hz"][k] for k in ("GLOBAL_POSITION_INT", "SCALED_PRESSURE")) >= 4.0
        ), last
    assert any(m.relative_alt > 50_000 for _, m in gpi), (
        "ArduSub's home did not turn relative_alt into an altitude"
    )
    thrusters_follow_the_pilot(statuses.got, keys, marks)
    own_log_follows_the_truth(sitl.dir, obs, t_truth, d_truth, marks)


def own_log_follows_the_truth(
    sitl_dir: Path, obs: Observer, t_truth, d_truth, marks: dict[str, float]
) -> None:
    """ArduSub's own DataFlash log of the flight as ``skyfix import --depth`` reads it: its clock against the clock
    of ArduSub's live messages (the earliest arrival of GLOBAL_POSITION_INT against its time_boot_ms), its depths
    against the truth at their times."""
    logs = sorted((sitl_dir / "logs").glob("*.BIN"))
    assert logs, f"ArduSub wrote no DataFlash log in {sitl_dir / 'logs'}"
    warnings: list[str] = []
    records, found = read_ardusub_depth(logs[-1], 0.05, warnings)
    live = [(t, t - m.time_boot_ms / 1000) for t, m in obs.of("GLOBAL_POSITION_INT")]
    # the simulator's clock may drift from the station's
    live_clock = min(c for t, c in live if t >= marks["gps"])
    drift_ms = [
        round(1000 * (min(c for t, c in live if t0 <= t < t0 + 5) - live_clock), 1)
        for t0 in np.arange(live[0][0], live[-1][0] - 5, 5)
    ]
    flight = [r for r in records if marks["armed"] <= r["t"] <= marks["end"]]
    errors = np.array([r["depth_m"] - np.interp(r["t"], t_truth, d_truth) for r in flight])
    print(
        f"ArduSub's own log {logs[-1].name}: {found}; clock {1000 * (found['unix_minus_boot_s'] - live_clock):+.1f} "
        f"ms against its live messages'; {len(flight)} depths in the flight, error max {np.abs(errors).max():.3f} m, "
        f"median {np.median(np.abs(errors)):.3f} m; the simulator's clock against the station's by 5 s (ms) {drift_ms}; "
        f"warnings {warnings}"
    )
    assert abs(found["unix_minus_boot_s"] - live_clock) <= MAX_CLOCK_ERROR_S, (found, live_clock)
    assert len(flight) >= 8 * (marks["end"] - marks["armed"]) - 10, found  # BARO at 10 Hz
    assert np.abs(errors).max() <= MAX_ERROR_M, errors
    assert {r["source"] for r in records} == {"ardusub_pressure"}


def thrusters_follow_the_pilot(
    got: dict[str, list[dict]], keys: dict[str, str], marks: dict[str, float]
) -> None:
    """ArduSub's horizontal thrusters as both skyfix read them (SERVO_OUTPUT_RAW, FRAME_CONFIG, SERVOn_FUNCTION):
    pushing while the pilot asks for half ahead, idle once disarmed (1500 µs), from a second into each."""

    def states(key: str, phase: str, until: str) -> list[str]:
        return [
            st["depth"]["thrusters"]["state"]
            for st in got[key]
            if marks[phase] + 1.0 <= st["t"] <= marks[until]
        ]

    for name, key in keys.items():
        forward, disarmed = states(key, "forward", "disarm"), states(key, "disarm", "end")
        last = got[key][-1]["depth"]["thrusters"]
        print(
            f"{name}: thrusters {last['frame']=} {last['channels']=}: half ahead {forward}, disarmed {disarmed}; "
            f"SERVO_OUTPUT_RAW {got[key][-1]['depth']['rates_hz'].get('SERVO_OUTPUT_RAW')} Hz"
        )
        assert last["frame"] == 1 and last["channels"] == [1, 2, 3, 4], last
        assert forward and set(forward) == {"pushing"}, (name, forward, last)
        assert disarmed and set(disarmed) == {"idle"}, (name, disarmed, last)

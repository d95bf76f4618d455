"""The UUV's depth from ArduSub's messages (localizer/depth.py), worked by hand: ArduSub's pressure formula, its
EKF depth before and after an origin and a home, the cross-check, recalibrations, reboots, the jump gate, the
sigma's growth with age, the depth's source per frame, and garbage from BlueOS's Zenoh."""

from __future__ import annotations

import json
import logging
import math
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import T0_UNIX

from groundstation.live import config
from groundstation.live.sources.depth_ardusub import ArduSubZenoh, autopilot_prefix
from groundstation.mavlink.ingest import BadMessage, ingest_ardusub
from localizer.calibration import ConfigError
from localizer.depth import ArduSubDepth, DepthGate, depth_from_pressure_m, ekf_depth_m
from localizer.fix import locate
from localizer.pose import camera_pose
from localizer.telemetry import Telemetry

BOOT0_S = 100.0  # the autopilot's uptime at T0_UNIX
LATENCY_S = 0.05


def feed(depth: ArduSubDepth, kind: str, t: float, **fields):
    """One message sent at ``t`` s after T0_UNIX and received at once."""
    if kind != "PARAM_VALUE" and kind != "GPS_GLOBAL_ORIGIN":
        fields["time_boot_ms"] = round((BOOT0_S + t) * 1000)
    return ingest_ardusub(depth, kind, fields, T0_UNIX + t)


def gpi(depth, t, relative_alt_mm, alt_mm=0, vz_cms=0):
    return feed(
        depth,
        "GLOBAL_POSITION_INT",
        t,
        relative_alt=relative_alt_mm,
        alt=alt_mm,
        vz=vz_cms,
        lat=0,
        lon=0,
    )


def calibrated(primary=1, ground_pa=98188.3, spec_grav=1.0) -> ArduSubDepth:
    d = ArduSubDepth(sigma_m=0.05, latency_s=LATENCY_S)
    feed(d, "PARAM_VALUE", 0.0, param_id="BARO_PRIMARY", param_value=float(primary))
    feed(d, "PARAM_VALUE", 0.0, param_id="BARO_SPEC_GRAV", param_value=spec_grav)
    feed(d, "PARAM_VALUE", 0.0, param_id=f"BARO{primary + 1}_GND_PRESS", param_value=ground_pa)
    return d


def test_pressure_depth_is_ardusubs_formula_worked_by_hand():
    # AP_Baro::update, water sensor: altitude = (ground - pressure) / 9800 / BARO_SPEC_GRAV; depth = -altitude
    # 3.54201 m
    assert depth_from_pressure_m(132900.0, 98188.3, 1.0) == pytest.approx(34711.7 / 9800.0)
    # sea water
    assert depth_from_pressure_m(132900.0, 98188.3, 1.024) == pytest.approx(3.542010204 / 1.024)
    d = calibrated(primary=1, spec_grav=1.024)
    # the onboard barometer: not the depth sensor
    assert feed(d, "SCALED_PRESSURE", 1.0, press_abs=1329.0) is None
    s = feed(d, "SCALED_PRESSURE2", 1.0, press_abs=1329.0)  # hPa
    assert s.source == "ardusub_pressure" and s.depth_m == pytest.approx(3.45899434)
    # boot clock → station clock, minus the latency
    assert s.t == pytest.approx(T0_UNIX + 1.0 - LATENCY_S)
    assert d.pressure_message == "SCALED_PRESSURE2" and d.wanted_params() == []


def test_ekf_depth_stands_in_until_the_parameters_come():
    d = ArduSubDepth(sigma_m=0.05, latency_s=LATENCY_S)
    # no origin (alt exactly 0): depth = -relative_alt
    s = gpi(d, 0.0, relative_alt_mm=-1234, vz_cms=20)
    assert (s.depth_m, s.source, s.sigma_m, s.vspeed_mps) == (1.234, "ardusub_ekf", 0.05, 0.2)
    assert d.wanted_params() == ["BARO_PRIMARY", "BARO_SPEC_GRAV"]
    # param_id as mavlink-server writes it (a string), as older versions did (a list of characters), as bytes
    feed(d, "PARAM_VALUE", 0.1, param_id="BARO_PRIMARY", param_value=1.0)
    feed(d, "PARAM_VALUE", 0.1, param_id=list("BARO_SPEC_GRAV"), param_value=1.0)
    assert d.wanted_params() == ["BARO2_GND_PRESS"]
    assert feed(d, "SCALED_PRESSURE2", 0.15, press_abs=1108.9) is None  # no ground pressure yet
    feed(d, "PARAM_VALUE", 0.2, param_id=b"BARO2_GND_PRESS\x00", param_value=98188.3)
    s = feed(d, "SCALED_PRESSURE2", 0.25, press_abs=1108.9)
    # 1.29609 m
    assert s.source == "ardusub_pressure" and s.depth_m == pytest.approx(12701.7 / 9800.0)
    # cross-checked against the EKF 0.25 s before, moving 0.2 m/s down: 1.234 + 0.05 = 1.284, 0.012 apart
    assert d.disagreement_m == pytest.approx(1.29609 - 1.284, abs=1e-4) and s.sigma_m == 0.05
    assert gpi(d, 0.3, relative_alt_mm=-1300) is None  # the pressure is the measurement now
    # and stays so when it pauses: no silent switch to the EKF
    assert gpi(d, 5.0, relative_alt_mm=-1300) is None


def test_a_home_turns_relative_alt_into_an_altitude_which_is_never_taken_as_depth():
    """ArduSub SITL, measured: at 4.06 m with the origin at 120 m, relative_alt = 115.94 once home is set."""
    d = calibrated(primary=0, ground_pa=102104.7, spec_grav=1.024)
    press = 1021.047 + 4.06 * 9800 * 1.024 / 100  # hPa at 4.06 m by ArduSub's formula
    gpi(d, 0.0, relative_alt_mm=-4060)
    assert feed(d, "SCALED_PRESSURE", 0.1, press_abs=press).depth_m == pytest.approx(4.06)
    # origin and home: EKF depth unknown
    assert gpi(d, 1.0, relative_alt_mm=115939, alt_mm=115939) is None
    assert d.ekf is None and d.wants_origin
    s = feed(d, "SCALED_PRESSURE", 1.1, press_abs=press)
    assert (
        s.depth_m == pytest.approx(4.06)
        and s.source == "ardusub_pressure"
        and d.disagreement_m is None
    )
    feed(d, "GPS_GLOBAL_ORIGIN", 1.2, altitude=120000, latitude=0, longitude=0)
    gpi(d, 1.3, relative_alt_mm=115939, alt_mm=115939)
    assert d.ekf[1] == pytest.approx(120.0 - 115.939) and not d.wants_origin  # origin - alt
    assert ekf_depth_m(-2.5, 0.0, None) == 2.5 and ekf_depth_m(115.9, 116.0, None) is None


def test_a_disagreement_is_one_warning_and_goes_into_the_sigma():
    d = calibrated(primary=0, ground_pa=100000.0)
    gpi(d, 0.0, relative_alt_mm=-3000)
    # 4.00 m against the EKF's 3.00 m
    s = feed(d, "SCALED_PRESSURE", 0.1, press_abs=1000.0 + 4.0 * 98.0)
    assert s.depth_m == pytest.approx(4.0) and s.sigma_m == pytest.approx(math.hypot(0.05, 1.0))
    assert len(d.notices) == 1 and "4.00 m and its EKF's 3.00 m disagree by +1.00 m" in d.notices[0]
    gpi(d, 0.2, relative_alt_mm=-3000)
    feed(d, "SCALED_PRESSURE", 0.3, press_abs=1000.0 + 4.0 * 98.0)
    assert len(d.notices) == 1  # the same disagreement: said once
    gpi(d, 0.4, relative_alt_mm=-3950)
    s = feed(d, "SCALED_PRESSURE", 0.5, press_abs=1000.0 + 4.0 * 98.0)
    assert s.sigma_m == 0.05 and "agree again" in d.notices[-1]


def test_a_recalibration_at_the_surface_is_followed_one_under_water_is_not():
    d = calibrated(primary=0, ground_pa=100000.0)
    # 0.1 m: weather
    feed(d, "PARAM_VALUE", 0.0, param_id="BARO1_GND_PRESS", param_value=100000.0 + 980.0)
    assert d.ground_pa[0] == 100980.0 and "the depth zero moved +0.10 m" in d.notices.pop()
    assert feed(d, "SCALED_PRESSURE", 0.1, press_abs=1009.8 + 3.0 * 98.0).depth_m == pytest.approx(
        3.0
    )
    # a preflight calibration at 3 m: ArduSub's zero is now there; skyfix keeps the surface's
    feed(d, "PARAM_VALUE", 0.2, param_id="BARO1_GND_PRESS", param_value=100980.0 + 3.0 * 9800.0)
    assert d.ground_pa[0] == 100980.0 and "3.00 m below the old one" in d.notices.pop()
    # read again
    feed(d, "PARAM_VALUE", 30.0, param_id="BARO1_GND_PRESS", param_value=100980.0 + 3.0 * 9800.0)
    assert not d.notices and d.zero_not_followed_pa == 100980.0 + 3.0 * 9800.0
    gpi(d, 30.05, relative_alt_mm=0)  # ArduSub's EKF now says 0 m: on its new zero, not compared
    s = feed(d, "SCALED_PRESSURE", 30.1, press_abs=1009.8 + 3.0 * 98.0)
    assert s.depth_m == pytest.approx(3.0) and s.sigma_m == 0.05 and d.disagreement_m is None
    # zeroed at the surface again
    feed(d, "PARAM_VALUE", 60.0, param_id="BARO1_GND_PRESS", param_value=100980.0)
    assert d.zero_not_followed_pa is None and not d.notices


def test_a_reboot_is_confirmed_before_it_is_taken_and_the_parameters_are_read_again():
    d = calibrated(primary=0, ground_pa=100000.0)
    for k in range(5):
        gpi(d, 0.1 * k, relative_alt_mm=-2000)
    assert d.wanted_params() == []
    # rebooted: uptime back to 2 s while the station clock goes on
    refused = []
    for k in range(6):
        t = 1.0 + 0.1 * k
        fields = {"time_boot_ms": 2000 + 100 * k, "relative_alt": -2000, "alt": 0, "vz": 0}
        refused.append(
            ingest_ardusub(d, "GLOBAL_POSITION_INT", fields, T0_UNIX + t) is None
            and d.refusal is not None
        )
        d.refusal = None
    assert refused[:3] == [True, True, True] and d.reboots == 1
    assert "rebooted (time_boot_ms went back from 100.4 s to 2.0 s)" in d.notices[-1]
    assert d.wanted_params() == ["BARO_PRIMARY", "BARO_SPEC_GRAV", "BARO1_GND_PRESS"]


def test_bad_fields_are_one_line_naming_the_value():
    d = ArduSubDepth(sigma_m=0.05, latency_s=LATENCY_S)
    for kind, fields, text in [
        (
            "SCALED_PRESSURE",
            {"time_boot_ms": 1, "press_abs": "1013"},
            "SCALED_PRESSURE.press_abs = '1013'",
        ),
        (
            "GLOBAL_POSITION_INT",
            {"time_boot_ms": 1, "relative_alt": float("nan"), "alt": 0, "vz": 0},
            "GLOBAL_POSITION_INT.relative_alt = nan",
        ),
        ("PARAM_VALUE", {"param_id": 7, "param_value": 1.0}, "PARAM_VALUE.param_id = 7"),
        ("GPS_GLOBAL_ORIGIN", {"altitude": None}, "GPS_GLOBAL_ORIGIN.altitude = None"),
    ]:
        with pytest.raises(BadMessage) as e:
            ingest_ardusub(d, kind, fields, T0_UNIX)
        assert str(e.value).startswith(text) and "\n" not in str(e.value)


def test_the_gate_refuses_a_dive_faster_than_the_vehicle_and_confirms_a_new_level():
    gate = DepthGate(max_vertical_speed_mps=1.5, sigma_m=0.05)
    assert gate.check(0.0, 2.0) is None
    assert gate.check(0.1, 2.3) is None  # 0.3 m ≤ 1.5 m/s × 0.1 s + 3 × √2 × 0.05 m = 0.362 m
    why = gate.check(0.2, 3.0)  # 0.7 m in 0.1 s
    assert why == (
        "depth 3.00 m refused: 0.70 m from 2.30 m +0.10 s before, faster than the vehicle can dive "
        "(uuv_max_vertical_speed_mps = 1.5)"
    )
    assert gate.check(0.3, 2.35) is None  # the old level goes on
    for t in (0.4, 0.7, 0.95, 1.2):  # a new level, held: refused until 5 samples over 1 s agree
        assert gate.check(t, 5.0) is not None
    assert gate.check(1.45, 5.0) is None and "stepped from 2.35 m to 5.00 m" in gate.notices.pop()
    assert gate.check(1.5, 11001.0) == "depth_m = 11001.0 outside [-5, 11000]"
    assert gate.refused == 5


def test_the_sigma_grows_with_age_by_the_vertical_speed_and_the_source_reaches_the_fix(
    make_cal, make_telemetry
):
    cal = make_cal()
    tel = make_telemetry(duration_s=3.0)
    tel.depth.clear()
    for k in range(11):  # 0 .. 2 s at 5 Hz, diving at 0.5 m/s
        t = T0_UNIX + 0.2 * k
        assert tel.add_autopilot_depth(t, 2.0 + 0.1 * k, 0.05, "ardusub_pressure", 0.5)
    tel.add_depth(T0_UNIX + 2.1, 3.05, T0_UNIX + 2.15)  # skyfix's JSON: the calibration's sigma
    t = T0_UNIX + 2.1 + 0.8  # 0.8 s past the newest (within depth_hold_s = 1)
    pose = camera_pose(cal, tel, [T0_UNIX + 1.0, T0_UNIX + 1.9, t])
    assert list(pose.depth_source) == ["ardusub_pressure", "ardusub_pressure", "skyfix"]
    assert pose.sigma_depth_m[0] == pytest.approx(0.05)  # between samples
    # held: its own last rate (0.05 m in 0.1 s = 0.5 m/s) × 0.8 s = 0.4 m, the vertical speed unknown
    assert pose.sigma_depth_m[2] == pytest.approx(math.hypot(cal.sigmas.depth_m, 0.4))
    tel.depth.clear()
    tel.add_autopilot_depth(T0_UNIX + 2.0, 3.0, 0.05, "ardusub_pressure", 1.2)
    pose = camera_pose(cal, tel, [T0_UNIX + 2.0, T0_UNIX + 2.5])
    assert pose.sigma_depth_m == pytest.approx([0.05, math.hypot(0.05, 1.2 * 0.5)])
    fixes = locate(cal, pose, [960.0, 960.0], [540.0, 540.0])
    assert list(fixes.depth_source) == ["ardusub_pressure"] * 2
    assert fixes.h_acc_m[1] > fixes.h_acc_m[0]


def test_garbage_from_blueos_is_one_line_each_and_nothing_breaks(caplog):
    tel = Telemetry()
    src = ArduSubZenoh(None, "mavlink/1/1", tel, DepthGate(), 0.05)
    caplog.set_level(logging.WARNING)
    now = time.time()
    payloads = [
        ("mavlink/1/1/SCALED_PRESSURE", b"\xff\x00not json"),
        ("mavlink/1/1/SCALED_PRESSURE", b"[1, 2]"),
        ("mavlink/1/1/SCALED_PRESSURE", b'{"message": 5}'),
        (
            "mavlink/1/1/SCALED_PRESSURE",
            json.dumps({"message": {"type": "VFR_HUD", "alt": -1.2}}).encode(),
        ),
        (
            "mavlink/1/1/SCALED_PRESSURE",
            (b'{"message": {"type": "SCALED_PRESSURE", "time_boot_ms": 5, "press_abs": NaN}}'),
        ),
        (
            "mavlink/1/1/GLOBAL_POSITION_INT",
            json.dumps({"message": {"type": "GLOBAL_POSITION_INT", "time_boot_ms": "x"}}).encode(),
        ),
        (
            "mavlink/1/1/PARAM_VALUE",
            json.dumps(
                {"message": {"type": "PARAM_VALUE", "param_id": {"a": 1}, "param_value": 1}}
            ).encode(),
        ),
        ("mavlink/1/1/SCALED_PRESSURE", b"[" * 100_000),
        ("mavlink/1/1/SCALED_PRESSURE", b'{"message": "' + b"x" * 2_000_000 + b'"}'),
    ]
    for key, data in payloads:
        src._on_payload(key, data, now)
    lines = [r.getMessage() for r in caplog.records]
    assert src.reader.bad == len(payloads) and len(lines) == len(payloads)
    assert all("\n" not in line and len(line) < 400 for line in lines)
    assert "message type 'VFR_HUD' on the key of SCALED_PRESSURE" in lines[3]
    assert "SCALED_PRESSURE.press_abs = nan" in lines[4] and "time_boot_ms = 'x'" in lines[5]
    assert "param_id = {'a': 1}" in lines[6]
    assert len(tel.depth) == 0 and src.status(now)["depth_m"] is None


def test_old_blueos_settings_say_what_to_write(tmp_path):
    import argparse

    def cfg(text):
        (tmp_path / "f.toml").write_text('calibration = "c.toml"\n' + text)
        p = argparse.ArgumentParser()
        config.add_arguments(p)
        return config.run_config(p.parse_args(["--config", str(tmp_path / "f.toml")]))

    with pytest.raises(ConfigError) as e:
        cfg('depth_source = "blueos"\ndepth_key = "mavlink/1/1/VFR_HUD"\n')
    assert str(e.value).startswith(
        f"{tmp_path / 'f.toml'}: depth_key = 'mavlink/1/1/VFR_HUD': VFR_HUD is not ArduSub's depth"
    ) and str(e.value).endswith("e.g. mavlink/1/1")
    # old configs without the key
    assert cfg('depth_source = "blueos"\n').depth_input_key == "mavlink/1/1"
    assert (
        cfg('depth_source = "blueos"\ndepth_key = "mavlink/2/1"\n').depth_input_key == "mavlink/2/1"
    )
    with pytest.raises(ConfigError, match="needs the link"):
        cfg('depth_source = "mavlink"\n')
    with pytest.raises(ConfigError, match="used only with depth_source"):
        cfg('depth_mavlink = "tcp:127.0.0.1:5760"\n')
    assert autopilot_prefix("mavlink/1/1/") == (1, 1)
    assert autopilot_prefix("rov1/mavlink/2/1") == (
        2,
        1,
    )  # under a vehicle's Zenoh namespace (a fleet)


def test_a_recording_keeps_each_depth_s_source_and_sigma_for_process(tmp_path):
    """depth.jsonl's extra keys as the recorder writes them are used offline; another tool's are ignored."""
    import shutil

    from groundstation.session.read import load_session

    session = tmp_path / "s"
    shutil.copytree(
        Path(__file__).resolve().parents[1] / "sim_fixtures" / "bundled" / "nadir_hover", session
    )
    lines = [json.loads(x) for x in (session / "depth.jsonl").read_text().splitlines()]
    half = len(lines) // 2
    for i, rec in enumerate(lines):
        rec |= (
            {"source": "ardusub_pressure", "sigma_m": 0.2}
            if i < half
            else {"source": "sonar", "sigma_m": "x"}
        )
    (session / "depth.jsonl").write_text("".join(json.dumps(r) + "\n" for r in lines))
    s = load_session(session)
    t_mid = lines[half]["t"]
    frames = [t for t in s.frames["t"] if abs(t - t_mid) > 0.2]
    pose = camera_pose(s.calibration, s.telemetry, frames)
    for t, word, sigma in zip(frames, pose.depth_source, pose.sigma_depth_m, strict=True):
        if t < t_mid:
            assert (word, sigma) == ("ardusub_pressure", pytest.approx(0.2, abs=0.01))
        else:
            assert (word, sigma) == (
                "session",
                pytest.approx(s.calibration.sigmas.depth_m, abs=0.01),
            )


def test_the_watchdog_says_when_the_depth_is_only_ardusubs_ekf():
    from groundstation.live.sources.uav_mavlink import UavMavlink
    from groundstation.live.watchdog import problems
    from groundstation.messages import InputsStatus

    src = ArduSubZenoh(None, "mavlink/1/1", Telemetry(), DepthGate(), 0.05)
    now = time.time()
    message = {
        "type": "GLOBAL_POSITION_INT",
        "time_boot_ms": 5000,
        "relative_alt": -1500,
        "alt": 0,
        "vz": 0,
    }
    src._on_payload(
        "mavlink/1/1/GLOBAL_POSITION_INT", json.dumps({"message": message}).encode(), now
    )
    # not opened: its status only
    uav = UavMavlink("udpin:127.0.0.1:14550", Telemetry(), {"ATTITUDE": 25.0})
    status = InputsStatus.model_validate({"uav": uav.status(now), "depth": src.status(now)})
    assert status.depth.source == "ardusub_ekf" and status.depth.depth_m == 1.5
    assert problems(status, ("ATTITUDE",), 1)["depth"] == (
        "depth: ArduSub's EKF only, unchecked: BARO_PRIMARY, "
        "BARO_SPEC_GRAV not received yet on Zenoh key mavlink/1/1"
    )


def test_a_buoy_heard_before_the_drone_is_not_taken_for_the_uav(tmp_path):
    """A reference's GPS_RAW_INT (its own system) recorded before the drone's first message leaves the UAV the drone."""
    import shutil
    import struct

    from groundstation.mavlink.ingest import mavutil
    from groundstation.session.read import load_session

    session = tmp_path / "s"
    shutil.copytree(
        Path(__file__).resolve().parents[1] / "sim_fixtures" / "bundled" / "nadir_hover", session
    )
    tlog = session / "uav.tlog"
    data = tlog.read_bytes()
    first_us = struct.unpack(">Q", data[:8])[0]
    buoy = mavutil().mavlink.MAVLink(None, srcSystem=42, srcComponent=1)
    report = buoy.gps_raw_int_encode(0, 6, 455_000_000, 137_000_000, 0, 65535, 65535, 0, 65535, 12)
    tlog.write_bytes(struct.pack(">Q", first_us - 1_000_000) + report.pack(buoy) + data)

    loaded = load_session(session)
    ok = load_session(
        shutil.copytree(
            Path(__file__).resolve().parents[1] / "sim_fixtures" / "bundled" / "nadir_hover",
            tmp_path / "twin",
        )
    )
    assert any("1 messages from systems other than the UAV (sysid 1)" in w for w in loaded.warnings)
    assert len(loaded.telemetry.attitude) == len(ok.telemetry.attitude) > 0
    assert np.array_equal(loaded.telemetry.attitude.values, ok.telemetry.attitude.values)

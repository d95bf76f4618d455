"""ArduSub's own DataFlash log as the UUV's depth (``skyfix import --depth UUV.BIN``), on logs written here record by
record so every value and time is known by construction; ArduSub's real log of a dive is checked against the
simulator's truth in test_sitl_ardusub_depth.py."""

from __future__ import annotations

import json
import math

import pytest

from groundstation.offline.import_flight import depth_records
from groundstation.session import SessionError
from groundstation.session.ardusub_log import read_ardusub_depth
from groundstation.testing.dataflash_log import DataflashWriter

WEEK, WEEK_MS = 2447, 316_382_800  # a GPS_INPUT's time: the fix's frame exposure ...
# (GPS epoch + weeks + ms − 18 leap seconds)
UNIX_FIX = 315964800 + WEEK * 604800 + WEEK_MS / 1000 - 18
# ... reaching ArduSub at 10.1 s after its boot, GPS1_DELAY_MS = 100 after the exposure:
ARRIVED_BOOT_S = 10.1
UNIX_AT_BOOT_0 = UNIX_FIX + 0.1 - ARRIVED_BOOT_S  # so ArduSub booted at UNIX_FIX − 10 s


def depth_at(boot_s: float) -> float:
    return 0.5 * boot_s  # diving at 0.5 m/s


def write_dive(path, gps: bool = True, ekf_off_m: float = 0.0, regrounded: bool = False) -> None:
    """BARO 0 (an air sensor's altitude, not the depth), BARO 1 the primary water sensor with a 0.2 m altitude offset,
    at 10 Hz from boot 11 s to 14 s; CTUN the EKF's altitude, ``ekf_off_m`` off between 12 and 13 s; GPS_INPUT's
    fixes at 5 Hz; the simulator's SIM with other values."""
    w = DataflashWriter(path)
    for name, value in (
        ("BARO_PRIMARY", 1),
        ("GPS1_TYPE", 14),
        ("GPS1_DELAY_MS", 100),
        ("BARO2_GND_PRESS", 101000),
    ):
        w.write("PARM", 1_000_000, name.encode(), value)
    for k in range(31):
        boot = 11.0 + k / 10
        us = round(boot * 1e6) + 300  # written 0.3 ms after the sample
        depth = depth_at(boot)
        w.write("BARO", us, 0, 35.0, 97000.0, 0.0, round(boot * 1000), 0.0, 1)
        w.write(
            "BARO",
            us,
            1,
            -depth + 0.2,
            101000.0 + 9800 * depth,
            -0.5,
            round(boot * 1000),
            0.2,
            int(k != 7),
        )
        w.write("CTUN", us, -depth + (ekf_off_m if 12.0 <= boot < 13.0 else 0.0))
        w.write("SIM", us, 0, 0, 0, -99.0, 0, 0, 1.0, 0.0, 0.0, 0.0)
        if gps and k % 2 == 0:
            arrived_ms = round((ARRIVED_BOOT_S + k / 10) * 1000)
            w.write(
                "GPS",
                arrived_ms * 1000,
                0,
                3,
                WEEK_MS + k * 100,
                WEEK,
                10,
                50,
                0,
                0,
                0,
                0.0,
                0.0,
                0.0,
                0.0,
                1,
            )
            w.write("GPA", arrived_ms * 1000, 0, arrived_ms)
        if regrounded and k == 20:
            w.write("PARM", us, b"BARO2_GND_PRESS", 101000 + 9800 * 1.5)
    w.close()


def test_the_primary_water_sensor_is_the_depth_on_the_fixes_clock(tmp_path):
    write_dive(tmp_path / "dive.BIN")
    warnings: list[str] = []
    records, found = read_ardusub_depth(tmp_path / "dive.BIN", 0.05, warnings)
    assert found["baro_primary"] == 1 and found["gps_delay_s_added"] == 0.1
    assert found["unix_minus_boot_s"] == pytest.approx(UNIX_AT_BOOT_0, abs=1e-6)
    assert len(records) == 30  # the unhealthy record (k = 7) skipped
    assert any("1 BARO records of sensor 1 unhealthy" in w for w in warnings), warnings
    first = records[0]
    # the sample's time, not the record's
    assert first["t"] == pytest.approx(UNIX_AT_BOOT_0 + 11.0, abs=1e-6)
    # −(Alt − Offset), not the air sensor's 35 m
    assert first["depth_m"] == pytest.approx(5.5, abs=1e-4)
    assert first["vspeed_mps"] == pytest.approx(0.5) and first["source"] == "ardusub_pressure"
    # the EKF agrees: the calibration's sigma stands
    assert all("sigma_m" not in r for r in records)
    assert all(abs(r["depth_m"] - depth_at(r["t"] - UNIX_AT_BOOT_0)) < 1e-4 for r in records)
    json.dumps(records)  # as depth.jsonl holds them


def test_an_ekf_that_disagrees_goes_into_those_depths_sigma(tmp_path):
    write_dive(tmp_path / "dive.BIN", ekf_off_m=0.5)
    warnings: list[str] = []
    records, _ = read_ardusub_depth(tmp_path / "dive.BIN", 0.05, warnings)
    widened = {round(r["t"] - UNIX_AT_BOOT_0, 1): r["sigma_m"] for r in records if "sigma_m" in r}
    assert sorted(widened) == [round(12.0 + k / 10, 1) for k in range(10)]
    # the EKF at the sample's time: interpolated between records written 0.3 ms after their samples
    assert all(s == pytest.approx(math.hypot(0.05, 0.5), abs=2e-3) for s in widened.values()), (
        widened
    )
    # of 29: the first sample precedes the first CTUN record
    assert any("disagree in 10 of 29" in w and "+0.50 m" in w for w in warnings), warnings


def test_a_recalibrated_zero_is_named(tmp_path):
    write_dive(tmp_path / "dive.BIN", regrounded=True)
    warnings: list[str] = []
    read_ardusub_depth(tmp_path / "dive.BIN", 0.05, warnings)
    assert any(
        "BARO2_GND_PRESS 101000.0 → 115700.0 Pa at boot 13.0 s" in w and "-1.50 m" in w
        for w in warnings
    ), warnings


def test_a_log_without_gps_time_has_no_clock(tmp_path):
    write_dive(tmp_path / "dive.BIN", gps=False)
    with pytest.raises(
        SessionError, match="no GPS records: ArduSub's clock cannot be put on UNIX time"
    ):
        read_ardusub_depth(tmp_path / "dive.BIN", 0.05, [])


def test_skyfix_import_takes_a_bin_depth_as_ardusubs_log(tmp_path):
    write_dive(tmp_path / "dive.BIN")
    records, found = depth_records(tmp_path / "dive.BIN", ("t", "depth_m"), 0.05, [])
    assert found["baro_primary"] == 1 and records[0]["depth_m"] == pytest.approx(5.5, abs=1e-4)

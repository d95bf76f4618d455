"""The MAVLink messages behind the height, as pymavlink decodes them off the wire: GPS_RAW_INT's altitude,
accuracies and DOPs, the autopilot's HEARTBEAT (armed), a downward DISTANCE_SENSOR and ArduPilot's RANGEFINDER."""

from __future__ import annotations

import math

import numpy as np
import pytest

from groundstation.mavlink.ingest import ingest, mavutil
from localizer.telemetry import Telemetry

T0 = 1_763_800_000.0
BOOT0_MS = 250_000
ROLL, PITCH = math.radians(6.0), math.radians(-4.0)


def _decode(msg, component: int = 1, system: int = 1):
    sender = mavutil().mavlink.MAVLink(None, srcSystem=system, srcComponent=component)
    return mavutil().mavlink.MAVLink(None).parse_buffer(msg.pack(sender))[0]


@pytest.fixture
def tel():
    """2 s of ATTITUDE (leaning 6° and -4°) from the autopilot, 50 Hz, each received 40 ms after it was sampled."""
    mav, tel = mavutil().mavlink, Telemetry()
    for k in range(101):
        ms = BOOT0_MS + 20 * k
        assert ingest(
            tel,
            _decode(mav.MAVLink_attitude_message(ms, ROLL, PITCH, 0.3, 0, 0, 0)),
            T0 + k * 0.02 + 0.04,
        )
    return tel


def distance_sensor(ms, cm, orientation=25, quality=0, covariance=0, lo=20, hi=4000):
    return mavutil().mavlink.MAVLink_distance_sensor_message(
        ms, lo, hi, cm, 0, 0, orientation, covariance, 0, 0, [0, 0, 0, 0], quality
    )


def test_heartbeat_arming_is_seen_only_from_the_autopilot(tel):
    mav = mavutil().mavlink

    def beat(
        base_mode, kind=mav.MAV_TYPE_QUADROTOR, autopilot=mav.MAV_AUTOPILOT_ARDUPILOTMEGA, system=1
    ):
        return _decode(
            mav.MAVLink_heartbeat_message(kind, autopilot, base_mode, 5, 3, 3), 1, system
        )

    armed, disarmed = mav.MAV_MODE_FLAG_SAFETY_ARMED | 1, 1
    ingest(tel, beat(armed), T0 + 0.5)  # already armed when first heard: no arming seen
    assert tel.armed is True and tel.arm_times == []
    ingest(tel, beat(disarmed), T0 + 1.0)
    # a ground station
    ingest(tel, beat(armed, kind=mav.MAV_TYPE_GCS, autopilot=mav.MAV_AUTOPILOT_INVALID), T0 + 1.2)
    assert tel.armed is False and tel.arm_times == []
    ingest(tel, beat(armed), T0 + 1.5)
    assert tel.armed is True and tel.arm_times == [T0 + 1.5]


def test_downward_distance_sensor_becomes_a_height(tel):
    ms = BOOT0_MS + 1000  # sampled at T0 + 1 s
    assert ingest(tel, _decode(distance_sensor(ms, 1250)), T0 + 1.04)
    t, (h, sigma) = (
        tel.height_fixes["rangefinder"].times[0],
        tel.height_fixes["rangefinder"].values[0],
    )
    assert t == pytest.approx(T0 + 1.04, abs=1e-6)  # on the autopilot's clock, as its ATTITUDE
    # read along the tilted body axis
    assert h == pytest.approx(12.5 * math.cos(ROLL) * math.cos(PITCH), abs=1e-6)
    assert sigma == pytest.approx(math.hypot(0.05, 0.125))
    ingest(tel, _decode(distance_sensor(ms + 100, 1250, covariance=16)), T0 + 1.14)  # 16 cm²: 4 cm
    assert tel.height_fixes["rangefinder"].values[1][1] == pytest.approx(0.04)
    assert tel.distance_sensor_seen


@pytest.mark.parametrize(
    ("cm", "orientation", "quality", "why"),
    [
        (4100, 25, 0, "out of range"),  # max + 1 m: ArduPilot's lidar drivers when nothing returns
        (4000, 25, 0, "out of range"),  # at max: out of range high
        (10, 25, 0, "out of range"),  # below min
        (1250, 25, 1, "out of range"),  # signal_quality 1: invalid
        (1250, 0, 0, "not downward"),  # MAV_SENSOR_ROTATION_NONE: looking forward
    ],
)
def test_readings_that_are_not_a_height(tel, cm, orientation, quality, why):
    assert not ingest(
        tel, _decode(distance_sensor(BOOT0_MS + 1000, cm, orientation, quality)), T0 + 1.04
    )
    # not refused: simply no reading
    assert tel.refusal is None and "rangefinder" not in tel.height_fixes
    assert tel.rangefinder_out_of_range == (1 if why == "out of range" else 0)


def test_rangefinder_message_only_without_distance_sensor(tel):
    mav = mavutil().mavlink
    assert ingest(tel, _decode(mav.MAVLink_rangefinder_message(12.5, 0.0)), T0 + 1.0)
    t, (h, _) = (
        tel.height_fixes["rangefinder"].times[-1],
        tel.height_fixes["rangefinder"].values[-1],
    )
    assert t == T0 + 1.0 and h == pytest.approx(12.5 * math.cos(ROLL) * math.cos(PITCH), abs=1e-5)
    ingest(tel, _decode(distance_sensor(BOOT0_MS + 1100, 1250)), T0 + 1.14)
    # its copy: once
    assert not ingest(tel, _decode(mav.MAVLink_rangefinder_message(12.5, 0.0)), T0 + 1.2)
    assert len(tel.height_fixes["rangefinder"]) == 2


def test_another_components_rangefinder_is_not_used(tel):
    assert not ingest(tel, _decode(distance_sensor(5_000, 1250), component=191), T0 + 1.04)
    assert tel.refusal is None and "rangefinder" not in tel.height_fixes


def test_gps_raw_int_altitude_accuracies_and_dops(tel):
    mav = mavutil().mavlink

    def raw(ms, fix, eph, epv, h_acc, v_acc, alt_mm=32_000):
        return _decode(
            mav.MAVLink_gps_raw_int_message(
                ms * 1000,
                fix,
                470000000,
                80000000,
                alt_mm,
                eph,
                epv,
                0,
                0,
                14,
                alt_mm + 40_000,
                h_acc,
                v_acc,
                0,
                0,
                0,
            )
        )

    assert ingest(tel, raw(BOOT0_MS + 900, 6, 70, 120, 14, 25), T0 + 1.0)
    # DOPs unknown, no accuracies
    assert ingest(tel, raw(BOOT0_MS + 1100, 3, 65535, 65535, 0, 0), T0 + 1.2)
    assert ingest(tel, raw(BOOT0_MS + 1300, 2, 90, 65535, 0, 0), T0 + 1.4)  # 2D: no altitude
    t, v = tel.gnss.times, tel.gnss.values  # h_acc, geoid, fix, alt, v_acc, HDOP, VDOP
    # ArduPilot's fix time (boot µs) on the autopilot's clock
    assert t[0] == pytest.approx(T0 + 0.94, abs=1e-6)
    assert np.allclose(v[0], [0.014, 40.0, 6, 32.0, 0.025, 0.7, 1.2])
    assert v[1][2] == 3 and v[1][3] == 32.0 and np.isnan(v[1][[0, 4, 5, 6]]).all()
    assert v[2][2] == 2 and np.isnan(v[2][3]) and v[2][5] == pytest.approx(0.9)


def test_an_absurd_gnss_altitude_is_refused(tel):
    mav = mavutil().mavlink
    msg = _decode(
        mav.MAVLink_gps_raw_int_message(
            (BOOT0_MS + 900) * 1000,
            3,
            470000000,
            80000000,
            2_000_000_000,
            70,
            110,
            0,
            0,
            14,
            0,
            800,
            1600,
            0,
            0,
            0,
        )
    )
    assert not ingest(tel, msg, T0 + 1.0)
    assert tel.refusal == "GNSS altitude 2000000.0 m outside (-1000, 10000) (mm not converted?)"
    assert len(tel.gnss) == 0 and tel.gnss.rejected == 1

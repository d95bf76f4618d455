"""The UUV's horizontal thrusters from ArduSub's outputs (localizer/thrusters.py), by hand: which channels, idle or
pushing, and when an interval counts as idle. ArduSub's own outputs are checked in test_sitl_ardusub_depth.py."""

from __future__ import annotations

import pytest

from groundstation.mavlink.ingest import BadMessage, servo_pulses_us
from groundstation.testing.gate_streams import vectored_thrusters
from localizer.thrusters import MARGIN_S, STALE_S, Thrusters, idle_accel_mps2


def pulses(p1: int, p2: int = 1500, p3: int = 1500, p4: int = 1500) -> dict[int, int]:
    return {1: p1, 2: p2, 3: p3, 4: p4, 5: 1700, 6: 1300}  # 5, 6: vertical, holding depth


def test_channels_come_from_the_frame_and_the_servo_functions():
    th = Thrusters()
    assert th.channels is None and th.why_unknown == "waiting for FRAME_CONFIG"
    th.param("FRAME_CONFIG", 1.0)
    assert th.channels is None and "SERVOn_FUNCTION" in th.why_unknown
    for n, function in (
        (9, 33.0),
        (10, 34.0),
        (3, 35.0),
        (4, 36.0),
    ):  # motors 1-4 on channels 9, 10, 3, 4
        th.param(f"SERVO{n}_FUNCTION", function)
    assert th.channels == (9, 10, 3, 4) and th.why_unknown is None and th.wanted_params() == []
    th.param("FRAME_CONFIG", 7.0)
    assert th.channels is None and th.why_unknown.startswith("FRAME_CONFIG 7")
    th.restarted()
    assert th.frame is None and "FRAME_CONFIG" in th.wanted_params()


def test_idle_is_every_horizontal_motor_within_the_deadband():
    th = vectored_thrusters()
    assert th.outputs(0.0, pulses(1500)) is True
    # ArduSub's heading hold, seen on its SITL
    assert th.outputs(0.1, pulses(1525, 1475, 1475, 1525)) is True
    assert th.outputs(0.2, pulses(1526)) is False
    assert th.outputs(0.3, pulses(0)) is None and th.unusable == 1  # channel 1 not output
    assert Thrusters(deadband_us=0).outputs(0.0, pulses(1501)) is None  # not known: no parameters


def test_an_interval_is_idle_only_when_covered_fresh_and_idle_throughout():
    th = vectored_thrusters()
    for k in range(30):  # idle outputs at 10 Hz, 0.0 … 2.9 s
        th.outputs(k / 10, pulses(1500))
    assert th.idle_since(1.0, 2.95)
    assert not th.idle_since(MARGIN_S / 2, 2.95)  # not covered from MARGIN_S before its start
    assert not th.idle_since(1.0, 2.9 + STALE_S + 0.01)  # the newest output is stale
    th.outputs(3.0, pulses(1600))
    assert not th.idle_since(1.0, 3.05) and th.state(3.05) == "pushing"
    th.outputs(3.1, pulses(1500))
    assert not th.idle_since(2.0, 3.15)  # the push lies in the interval
    gap = vectored_thrusters()
    for t in (0.0, 0.1, 0.2, 0.2 + STALE_S + 0.05, 0.3 + STALE_S + 0.05):
        gap.outputs(t, pulses(1500))
    assert not gap.idle_since(0.5, 0.3 + STALE_S + 0.1)  # a gap longer than STALE_S
    assert gap.idle_since(0.2 + STALE_S + 0.05 + MARGIN_S, 0.3 + STALE_S + 0.1)


def test_idle_acceleration_is_the_water_plus_the_drag():
    """Wu's BlueROV2 surge drag at 1.5 m/s: 4.03·1.5 + 18.18·2.25 = 46.95 N over 17 kg = 2.76 m/s²."""
    assert idle_accel_mps2(0.0, 0.05) == pytest.approx(0.05)
    assert idle_accel_mps2(-1.5, 0.0) == pytest.approx(46.95 / 17.0)


def test_servo_output_raw_fields_are_checked():
    fields = {f"servo{n}_raw": 1500 for n in range(1, 9)}  # MAVLink 1: no extensions
    assert servo_pulses_us(fields)[16] == 0 and servo_pulses_us(fields)[1] == 1500
    for bad in (1500.5, -1, "1500", None, True):
        with pytest.raises(BadMessage, match=r"servo3_raw = "):
            servo_pulses_us(fields | {"servo3_raw": bad})

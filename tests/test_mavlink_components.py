"""MAVLink messages from several components of the UAV, as pymavlink decodes them off the wire.

A MAVLink gimbal (component 154) stamps GIMBAL_DEVICE_ATTITUDE_STATUS with its
own ``time_boot_ms``; the samples must be aligned by its own clock, not be
dropped as "no gimbal" nor make the autopilot's clock believe it rebooted. The
link delay comes from TIMESYNC replies, as ArduPilot answers them.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from groundstation.mavlink.ingest import ingest, mavutil
from localizer.attitude import euler_to_quat
from localizer.calibration import Calibration
from localizer.pose import camera_pose
from localizer.telemetry import Telemetry

T0 = 1_763_800_000.0
AUTOPILOT_BOOT0_MS = 250_000  # the autopilot has been up for 250 s at T0
GIMBAL_BOOT0_MS = 7_300  # the gimbal booted later: its clock is 242.7 s behind
PITCH_RATE_DEG_S = 10.0  # the gimbal tilts steadily, so a time error shows as a pitch error


def _decode(msg, component: int):
    sender = mavutil().mavlink.MAVLink(None, srcSystem=1, srcComponent=component)
    buf = msg.pack(sender)
    parsed = mavutil().mavlink.MAVLink(None).parse_buffer(buf)
    assert parsed and parsed[0].get_srcComponent() == component
    return parsed[0]


def _pitch_deg(t):
    return -80.0 + PITCH_RATE_DEG_S * (t - T0)


def _feed(tel: Telemetry, rng, gimbal_component: int, gimbal_boot0_ms: int, extra=()):
    mav = mavutil().mavlink
    messages = []  # (receive time, decoded message)
    for k in range(150):  # 3 s at 50 Hz
        t = T0 + k * 0.02
        ap_ms = AUTOPILOT_BOOT0_MS + round((t - T0) * 1000)
        g_ms = gimbal_boot0_ms + round((t - T0) * 1000)
        delay = 0.04 + rng.exponential(0.01)
        messages.append(
            (t + delay, _decode(mav.MAVLink_attitude_message(ap_ms, 0.0, 0.0, 0.3, 0, 0, 0), 1))
        )
        q = euler_to_quat(0.0, math.radians(_pitch_deg(t)), 0.3)
        gimbal = mav.MAVLink_gimbal_device_attitude_status_message(
            0, 0, g_ms, 64, [float(x) for x in q], 0, 0, 0, 0
        )
        messages.append((t + delay + 0.001, _decode(gimbal, gimbal_component)))
        if k % 5 == 0:
            pos = mav.MAVLink_global_position_int_message(
                ap_ms, 434000000, 163000000, 30000, 20000, 0, 0, 0, 0
            )
            messages.append((t + delay + 0.002, _decode(pos, 1)))
        if k % 50 == 0:
            st = mav.MAVLink_system_time_message(int(t * 1e6), ap_ms)
            messages.append((t + delay + 0.003, _decode(st, 1)))
            # our TIMESYNC request left at t, reached the autopilot 40 ms later and came back 40 ms after that
            sync = mav.MAVLink_timesync_message(round((ap_ms / 1000 + 0.04) * 1e9), round(t * 1e9))
            messages.append((t + 0.08, _decode(sync, 1)))
    messages.extend(extra)
    for t_recv, msg in sorted(messages, key=lambda m: m[0]):
        ingest(tel, msg, t_recv)
    for k in range(7):
        tel.add_depth(T0 + 0.5 * k, 1.0)


def _cal():
    return Calibration.from_dict(
        {
            "camera": {
                "width": 640,
                "height": 360,
                "fx": 500.0,
                "fy": 500.0,
                "cx": 319.5,
                "cy": 179.5,
            },
            "mount": {"attitude_source": "gimbal_device"},
            "water": {"takeoff_height_above_surface_m": 2.0},
        }
    )


@pytest.mark.parametrize(
    ("gimbal_component", "gimbal_boot0_ms"),
    [
        (1, AUTOPILOT_BOOT0_MS),
        (154, GIMBAL_BOOT0_MS),
    ],  # the autopilot's own mount driver; a MAVLink gimbal
)
def test_gimbal_samples_land_on_the_autopilot_clock(gimbal_component, gimbal_boot0_ms):
    tel = Telemetry()
    _feed(tel, np.random.default_rng(3), gimbal_component, gimbal_boot0_ms)
    assert tel.uav_clock.segments == 0
    # the least delay of 150 samples is 40 ms plus the smallest of their exponential jitters
    assert tel.latency_source == "timesync" and tel.uav_latency_s == pytest.approx(0.04, abs=5e-4)
    times = T0 + np.array([0.5, 1.2, 2.5])
    pose = camera_pose(_cal(), tel, times)
    assert list(pose.status) == ["ok"] * 3
    axis_down = pose.R_ned_from_cv[:, 2, 2]  # the optical axis's down component = -sin(pitch)
    pitch = np.degrees(-np.arcsin(axis_down))
    # a time error of dt shows as PITCH_RATE_DEG_S·dt; 0.05° is 5 ms
    assert pitch == pytest.approx(_pitch_deg(times), abs=0.05)


def test_other_components_attitude_is_not_the_autopilots():
    """An ATTITUDE from another component (e.g. a companion's estimate) must not enter the buffers."""
    tel = Telemetry()
    mav = mavutil().mavlink
    stray = _decode(
        mav.MAVLink_attitude_message(AUTOPILOT_BOOT0_MS + 1510, 0.5, 0.5, 2.0, 0, 0, 0), 191
    )
    _feed(tel, np.random.default_rng(4), 1, AUTOPILOT_BOOT0_MS, extra=[(T0 + 1.55, stray)])
    assert tel.autopilot_component == 1
    assert not np.any(np.isclose(tel.attitude.values[:, 2], 2.0))


def test_a_garbage_frame_cannot_fake_a_reboot_but_a_real_reboot_is_seen():
    """time_boot_ms 0 with a NaN roll is refused before it reaches the clock, and so is a valid-looking one
    among the old clock's messages; a real reboot (the old clock silent, the new one going on for 0.3 s) is
    one, its first samples appended once it is confirmed, and the earlier samples still serve earlier frames."""
    mav = mavutil().mavlink
    tel = Telemetry()
    garbage = _decode(mav.MAVLink_attitude_message(0, float("nan"), 0.0, 0.3, 0, 0, 0), 1)
    stray = _decode(mav.MAVLink_attitude_message(5, 0.4, 0.0, 0.3, 0, 0, 0), 1)
    _feed(
        tel,
        np.random.default_rng(5),
        1,
        AUTOPILOT_BOOT0_MS,
        extra=[(T0 + 1.0, garbage), (T0 + 1.5, stray)],
    )
    assert tel.uav_clock.segments == 0 and tel.attitude.rejected >= 2
    assert not np.any(np.isclose(tel.attitude.values[:, 0], 0.4))
    assert list(camera_pose(_cal(), tel, [T0 + 2.0]).status) == ["ok"]

    n = len(tel.attitude)
    taken = [
        ingest(
            tel,
            _decode(mav.MAVLink_attitude_message(1200 + 20 * i, 0.0, 0.0, 0.3, 0, 0, 0), 1),
            T0 + 3.5 + 0.02 * i,
        )
        for i in range(20)
    ]
    assert taken.index(True) >= 2 and all(taken[taken.index(True) :])  # held back until confirmed
    # then the held ones appended too
    assert tel.uav_clock.segments == 1 and len(tel.attitude) == n + 20
    assert sum("rebooted" in notice for notice in tel.notices) == 1
    assert list(camera_pose(_cal(), tel, [T0 + 2.0]).status) == ["ok"]

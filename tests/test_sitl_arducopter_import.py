"""A drone's own DataFlash log, imported: ArduPilot's ArduCopter (SITL) flies with a gimbal and writes its ``.bin``;
``skyfix import`` turns it into a session, whose telemetry must say what the same autopilot said live over MAVLink.

The flight (GUIDED): take off to 10 m, turn the vehicle, point the gimbal (``mount_brushless.parm``: roll/pitch
in the earth frame, yaw relative to the vehicle) at four attitudes. A ground station on SERIAL0
(:class:`~ardusub_sitl.Observer`) receives ATTITUDE (25 Hz), GLOBAL_POSITION_INT, SYSTEM_TIME and the gimbal's
GIMBAL_DEVICE_ATTITUDE_STATUS meanwhile. Independent paths to the same truth: the live messages are the
autopilot's MAVLink, the session's are rebuilt from its log records (ATT at 10 Hz, POS, GPS week time,
MNT). Compared on the autopilot's own clock (``time_boot_ms``): the attitude (the session's interpolated
to each live message's time), the gimbal (the live quaternion turned into angles with scipy, not with
skyfix's rotations), the position, and the log's clock on UNIX time against SYSTEM_TIME. The numbers are
printed.
"""

from __future__ import annotations

import json
import time

import numpy as np
import pytest
from ardusub_sitl import ArduCopter, Observer, arducopter_files
from live_helpers import ROOT, wait_for, wait_until
from pymavlink.dialects.v20 import ardupilotmega as mavlink2
from scipy.spatial.transform import Rotation

from groundstation.offline.import_flight import import_flight
from groundstation.session.tlog import read_tlog

pytestmark = pytest.mark.sitl

LAT, LON, HOME_AMSL_M = 63.4400, 10.4000, 50.0
EXTRA = "LOG_DISARMED 1\nARMING_CHECK 0\n"  # a log from boot; no pre-arm checks (no RC in SITL)
KEEP = (*Observer.KEEP, "ATTITUDE", "SYSTEM_TIME", "GIMBAL_DEVICE_ATTITUDE_STATUS")
GUIDED = 4
# (pitch, yaw relative to the vehicle) of the gimbal, each held this long (s), while the vehicle turns
GIMBAL = ((-60.0, 30.0), (-90.0, 0.0), (-45.0, -40.0), (-75.0, 15.0))
HOLD_SAMPLES = 60  # each held until this many gimbal reports (20 Hz) said so: 3 s


def command(obs: Observer, cmd: int, *params: float) -> None:
    obs.send(mavlink2.MAVLink_command_long_message(1, 1, cmd, 0, *(list(params) + [0.0] * (7 - len(params)))))


def armed(obs: Observer) -> bool:
    beats = [m for _, m in obs.of("HEARTBEAT") if m.get_srcComponent() == 1]
    return bool(beats) and bool(beats[-1].base_mode & mavlink2.MAV_MODE_FLAG_SAFETY_ARMED)


def fly(obs: Observer) -> None:
    wait_for(lambda: any("is using GPS" in m.text for _, m in obs.of("STATUSTEXT")), 90, "EKF3 using GPS")
    obs.send(mavlink2.MAVLink_set_mode_message(1, mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, GUIDED))
    for _ in range(10):
        command(obs, mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 1)
        if wait_until(lambda: armed(obs), 3.0):
            break
    assert armed(obs), [m.text for _, m in obs.of("STATUSTEXT")][-5:]
    command(obs, mavlink2.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, float("nan"), 0, 0, 10.0)
    wait_for(lambda: any(m.relative_alt > 8000 for _, m in obs.of("GLOBAL_POSITION_INT")), 40, "the take-off")
    for i, (pitch, yaw) in enumerate(GIMBAL):
        since = time.time()
        command(obs, mavlink2.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW, pitch, yaw, float("nan"), float("nan"), 0, 0, 0)
        command(obs, mavlink2.MAV_CMD_CONDITION_YAW, 45.0, 20.0, 1 if i % 2 == 0 else -1, 1)  # relative turn
        wait_for(lambda p=pitch, t=since: gimbal_samples_at(obs, p, t) >= HOLD_SAMPLES, 30, f"the gimbal at {pitch}°")


def gimbal_samples_at(obs: Observer, pitch_deg: float, since: float) -> int:
    """GIMBAL_DEVICE_ATTITUDE_STATUS received since ``since`` with the gimbal within 1° of ``pitch_deg``."""
    q = [m.q for t, m in obs.of("GIMBAL_DEVICE_ATTITUDE_STATUS", since) if m.get_srcComponent() == 1]
    if not q:
        return 0
    w, x, y, z = np.array(q).T
    pitch = Rotation.from_quat(np.column_stack([x, y, z, w])).as_euler("ZYX", degrees=True)[:, 1]
    return int(np.sum(np.abs(pitch - pitch_deg) <= 1.0))


def live(obs: Observer, kind: str) -> list:
    return [m for _, m in obs.of(kind) if m.get_srcComponent() == 1]


def angle_deg(a, b):
    return np.abs((np.asarray(a) - np.asarray(b) + 180.0) % 360.0 - 180.0)


def test_a_dataflash_log_imported_says_what_the_autopilot_said_live(tmp_path):
    binary, parms = arducopter_files()
    sitl = ArduCopter(binary, parms, tmp_path / "copter", home=(LAT, LON, HOME_AMSL_M, 0.0), extra_parm=EXTRA,
                      keep=KEEP)
    try:
        sitl.start()
        obs = sitl.observer
        for msg_id, hz in ((mavlink2.MAVLINK_MSG_ID_ATTITUDE, 25.0), (mavlink2.MAVLINK_MSG_ID_SYSTEM_TIME, 2.0),
                           (mavlink2.MAVLINK_MSG_ID_GIMBAL_DEVICE_ATTITUDE_STATUS, 20.0),
                           (mavlink2.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 10.0)):
            obs.request_interval(msg_id, hz)
        fly(obs)
    finally:
        sitl.stop()
    logs = sorted((sitl.dir / "logs").glob("*.BIN"))
    assert logs, sitl.tail()
    t_live = [m.time_boot_ms for m in live(obs, "ATTITUDE")]
    depth = tmp_path / "depth.jsonl"  # the UUV's depth is not this test's: a constant, on UNIX time
    clock = np.median([m.time_unix_usec / 1e6 - m.time_boot_ms / 1e3 for m in live(obs, "SYSTEM_TIME")
                       if m.time_unix_usec])
    depth.write_text("".join(json.dumps({"t": clock + t / 1e3, "depth_m": 1.0}) + "\n" for t in t_live[::10]))
    cal = tmp_path / "cal.toml"
    cal.write_text((ROOT / "deploy" / "calibration.toml").read_text()
                   .replace('attitude_source = "gimbal_device"', 'attitude_source = "mount_orientation"'))
    report = import_flight(logs[-1], None, depth, cal, tmp_path / "session")
    got = {}
    for _, m in read_tlog(tmp_path / "session" / "uav.tlog"):
        got.setdefault(m.get_type(), []).append(m)

    # the log's clock on UNIX time, against the autopilot's own SYSTEM_TIME
    clock_error_s = report["unix_minus_boot_s"] - clock
    # the attitude: the session's (10 Hz) at each live ATTITUDE's time
    att = got["ATTITUDE"]
    t_imp = np.array([m.time_boot_ms for m in att], float)
    inside = [m for m in live(obs, "ATTITUDE") if t_imp[0] <= m.time_boot_ms <= t_imp[-1]]
    t_l = np.array([m.time_boot_ms for m in inside], float)
    errors = []
    for name in ("roll", "pitch", "yaw"):
        imported = np.degrees(np.interp(t_l, t_imp, np.unwrap([getattr(m, name) for m in att])))
        errors.append(angle_deg(imported, np.degrees([getattr(m, name) for m in inside])))
    att_err = np.max(errors, axis=0)
    # the gimbal: the live quaternion (w, x, y, z; yaw relative to the vehicle or North as its flags say, roll and
    # pitch to the horizon) against the session's MOUNT_ORIENTATION angles (interpolated to its time) made a
    # rotation by scipy (Z-Y-X): the angle between the two
    mnt = got["MOUNT_ORIENTATION"]
    t_m = np.array([m.time_boot_ms for m in mnt], float)
    gim = [m for m in live(obs, "GIMBAL_DEVICE_ATTITUDE_STATUS") if t_m[0] <= m.time_boot_ms <= t_m[-1]]
    w, x, y, z = np.array([m.q for m in gim]).T
    r_live = Rotation.from_quat(np.column_stack([x, y, z, w]))
    flags = {m.flags & mavlink2.GIMBAL_DEVICE_FLAGS_YAW_IN_EARTH_FRAME for m in gim}
    field = "yaw_absolute" if flags == {mavlink2.GIMBAL_DEVICE_FLAGS_YAW_IN_EARTH_FRAME} else "yaw"
    t_g = np.array([m.time_boot_ms for m in gim], float)
    zyx = [np.interp(t_g, t_m, np.unwrap([getattr(m, name) for m in mnt], period=360.0))
           for name in (field, "pitch", "roll")]
    gim_err = (r_live.inv() * Rotation.from_euler("ZYX", np.column_stack(zyx), degrees=True)).magnitude()
    gim_err = np.degrees(gim_err)
    pitch = zyx[1]
    # the position, the session's interpolated to each live message's time
    gpi = got["GLOBAL_POSITION_INT"]
    t_p = np.array([m.time_boot_ms for m in gpi], float)
    near = [m for m in live(obs, "GLOBAL_POSITION_INT") if t_p[0] <= m.time_boot_ms <= t_p[-1]]
    t_n = np.array([m.time_boot_ms for m in near], float)

    def at(name):
        return np.interp(t_n, t_p, [getattr(m, name) for m in gpi]) - np.array([getattr(m, name) for m in near])

    horizontal = np.hypot(at("lat") * 0.0111, at("lon") * 0.0111 * np.cos(np.radians(LAT)))
    vertical = np.abs(at("alt")) / 1000.0
    pairs = near
    print(f"\nArduCopter SITL {binary}: log {logs[-1].name}, {report['messages']}\n"
          f"clock: the log's on UNIX time - SYSTEM_TIME's {clock_error_s * 1000:+.1f} ms "
          f"(± {report['unix_minus_boot_sigma_s'] * 1000:.1f} ms)\n"
          f"attitude: {len(t_l)} live ATTITUDE, worst axis: median {np.median(att_err):.3f}°, "
          f"p99 {np.percentile(att_err, 99):.3f}°, max {att_err.max():.3f}°\n"
          f"gimbal: {len(t_g)} live GIMBAL_DEVICE_ATTITUDE_STATUS ({field}): median {np.median(gim_err):.3f}°, "
          f"p99 {np.percentile(gim_err, 99):.3f}°, max {gim_err.max():.3f}°; pitch range "
          f"{pitch.min():.0f}…{pitch.max():.0f}°\n"
          f"position: {len(pairs)} live GLOBAL_POSITION_INT: horizontal median {np.median(horizontal):.3f} m, max "
          f"{horizontal.max():.3f} m; vertical median {np.median(vertical):.3f} m, max {vertical.max():.3f} m")
    assert abs(clock_error_s) <= 0.01
    assert len(t_l) > 300 and np.median(att_err) <= 0.05 and np.percentile(att_err, 99) <= 0.5
    assert len(t_g) > 200 and pitch.min() < -85 and np.percentile(gim_err, 99) <= 0.5
    assert len(pairs) > 100 and horizontal.max() <= 0.2 and vertical.max() <= 0.2

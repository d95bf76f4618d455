"""A drone's own DataFlash log, imported: ArduPilot's ArduCopter (SITL) flies with a gimbal and writes its ``.bin``;
``skyfix import`` turns it into a session, whose telemetry must say what the same autopilot said live over MAVLink.

ArduCopter boots while the module before this one runs (``tests/ahead.py``): ~40 s from its start to EKF3 using
the GPS. The flight (GUIDED): take off to 10 m, turn the vehicle, point the gimbal (``mount_brushless.parm``:
roll/pitch in the earth frame, yaw relative to the vehicle) at four attitudes. A ground station on SERIAL0
(:class:`~ardusub_sitl.Observer`) receives ATTITUDE (25 Hz), GLOBAL_POSITION_INT, SYSTEM_TIME and the gimbal's
GIMBAL_DEVICE_ATTITUDE_STATUS meanwhile. Independent paths to the same truth: the live messages are the
autopilot's MAVLink, the session's are rebuilt from its log records (ATT at 10 Hz, POS, GPS week time,
MNT). Compared on the autopilot's own clock (``time_boot_ms``): the attitude (the session's interpolated
to each live message's time), the gimbal (the live quaternion turned into angles with scipy, not with
skyfix's rotations), the position, and the log's clock on UNIX time against SYSTEM_TIME. The attitude and the
gimbal are compared from the take-off on (the still vehicle before it, as long as the boot took, would dilute any
percentile), the gimbal leaving out the live reports between two log records across one of its steps (the log
cannot say when in those 0.1 s it jumped). The numbers are printed.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pymap3d
import pytest
from ardusub_sitl import ArduCopter, Booting, Observer, arducopter_files
from live_helpers import ROOT, wait_for, wait_until
from pymavlink.dialects.v20 import ardupilotmega as mavlink2
from scipy.spatial.transform import Rotation, Slerp

from groundstation.mavlink.ingest import (
    mavutil,  # the MAVLink 2 dialect (a plain pymavlink import would load 1.0)
)
from groundstation.offline.import_flight import import_flight
from groundstation.session.tlog import read_tlog

pytestmark = pytest.mark.sitl

LAT, LON, HOME_AMSL_M = 63.4400, 10.4000, 50.0
EXTRA = "LOG_DISARMED 1\nARMING_CHECK 0\n"  # a log from boot; no pre-arm checks (no RC in SITL)
KEEP = (*Observer.KEEP, "ATTITUDE", "SYSTEM_TIME", "GIMBAL_DEVICE_ATTITUDE_STATUS")
GUIDED = 4
# (pitch, yaw relative to the vehicle) of the gimbal, each held this long (s), while the vehicle turns
GIMBAL = ((-60.0, 30.0), (-90.0, 0.0), (-45.0, -40.0), (-75.0, 15.0))
UUV_DEPTH_M = 1.5
VIDEO_LATE_S = 0.77  # the camera's video starts this long into the survey (not told to the import)
# a step of the gimbal between two log records: the mount jumps to each command within one live report (50 ms);
# its commands step by 15° or more, while a held gimbal moves less than 5° per record (0.1 s) even with its yaw
# to North as the vehicle turns (20°/s: 2°)
STEP_DEG = 5.0
HOLD_SAMPLES = 60  # each held until this many gimbal reports (20 Hz) said so: 3 s
# the survey the camera films: the gimbal 10° ahead of nadir while the vehicle turns (heading changes, degrees)
SURVEY_PITCH_DEG, SURVEY_TURNS_DEG, SURVEY_RATE_DPS = -80.0, (30.0, -60.0, 30.0), 10.0


def command(obs: Observer, cmd: int, *params: float) -> None:
    obs.send(
        mavlink2.MAVLink_command_long_message(
            1, 1, cmd, 0, *(list(params) + [0.0] * (7 - len(params)))
        )
    )


def armed(obs: Observer) -> bool:
    beats = [m for _, m in obs.of("HEARTBEAT") if m.get_srcComponent() == 1]
    return bool(beats) and bool(beats[-1].base_mode & mavlink2.MAV_MODE_FLAG_SAFETY_ARMED)


def fly(obs: Observer) -> tuple[float, tuple[float, float]]:
    """The flight; returns the autopilot's clock (``time_boot_ms``) at the take-off and the survey's span (the
    simulator's UNIX s: SYSTEM_TIME's clock)."""
    wait_for(
        lambda: any("is using GPS" in m.text for _, m in obs.of("STATUSTEXT")), 90, "EKF3 using GPS"
    )
    obs.send(
        mavlink2.MAVLink_set_mode_message(1, mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, GUIDED)
    )
    for _ in range(10):
        command(obs, mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 1)
        if wait_until(lambda: armed(obs), 3.0):
            break
    assert armed(obs), [m.text for _, m in obs.of("STATUSTEXT")][-5:]
    takeoff_boot_ms = live(obs, "ATTITUDE")[-1].time_boot_ms
    command(obs, mavlink2.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, float("nan"), 0, 0, 10.0)
    wait_for(
        lambda: any(m.relative_alt > 8000 for _, m in obs.of("GLOBAL_POSITION_INT")),
        40,
        "the take-off",
    )
    for i, (pitch, yaw) in enumerate(GIMBAL):
        since = time.time()
        command(
            obs,
            mavlink2.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
            pitch,
            yaw,
            float("nan"),
            float("nan"),
            0,
            0,
            0,
        )
        # relative turn
        command(obs, mavlink2.MAV_CMD_CONDITION_YAW, 45.0, 20.0, 1 if i % 2 == 0 else -1, 1)
        wait_for(
            lambda p=pitch, t=since: gimbal_samples_at(obs, p, t) >= HOLD_SAMPLES,
            30,
            f"the gimbal at {pitch}°",
        )
    return takeoff_boot_ms, survey(obs)


def heading_deg(obs: Observer) -> float:
    return float(np.degrees(live(obs, "ATTITUDE")[-1].yaw))


def sim_unix(obs: Observer) -> float:
    """The simulator's UNIX time now: the newest SYSTEM_TIME (the video is timed on the log's clock)."""
    return live(obs, "SYSTEM_TIME")[-1].time_unix_usec / 1e6


def survey(obs: Observer) -> tuple[float, float]:
    """The camera at :data:`SURVEY_PITCH_DEG` ahead of the vehicle, which turns by :data:`SURVEY_TURNS_DEG` at
    :data:`SURVEY_RATE_DPS`, each turn awaited until its heading is reached."""
    since = time.time()
    command(
        obs,
        mavlink2.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
        SURVEY_PITCH_DEG,
        0.0,
        float("nan"),
        float("nan"),
        0,
        0,
        0,
    )
    wait_for(
        lambda: gimbal_samples_at(obs, SURVEY_PITCH_DEG, since) >= 20,
        30,
        "the gimbal at the survey's pitch",
    )
    start = sim_unix(obs)
    for turn in SURVEY_TURNS_DEG:
        target = heading_deg(obs) + turn
        command(
            obs,
            mavlink2.MAV_CMD_CONDITION_YAW,
            abs(turn),
            SURVEY_RATE_DPS,
            1 if turn > 0 else -1,
            1,
        )
        wait_for(
            lambda t=target: angle_deg(heading_deg(obs), t) <= 1.0,
            30,
            f"the heading {target % 360:.0f}°",
        )
    return start, sim_unix(obs)


def gimbal_samples_at(obs: Observer, pitch_deg: float, since: float) -> int:
    """GIMBAL_DEVICE_ATTITUDE_STATUS received since ``since`` with the gimbal within 1° of ``pitch_deg``."""
    q = [
        m.q for t, m in obs.of("GIMBAL_DEVICE_ATTITUDE_STATUS", since) if m.get_srcComponent() == 1
    ]
    if not q:
        return 0
    w, x, y, z = np.array(q).T
    pitch = Rotation.from_quat(np.column_stack([x, y, z, w])).as_euler("ZYX", degrees=True)[:, 1]
    return int(np.sum(np.abs(pitch - pitch_deg) <= 1.0))


def live(obs: Observer, kind: str) -> list:
    return [m for _, m in obs.of(kind) if m.get_srcComponent() == 1]


def flying(obs: Observer, kind: str, takeoff_boot_ms: float, t_log: np.ndarray) -> list:
    """The live ``kind`` from the take-off to the log's last record: before it the vehicle sat still on the ground
    for as long as it took to boot, which would dilute the flight's errors in any percentile."""
    return [
        m for m in live(obs, kind) if max(t_log[0], takeoff_boot_ms) <= m.time_boot_ms <= t_log[-1]
    ]


def angle_deg(a, b):
    return np.abs((np.asarray(a) - np.asarray(b) + 180.0) % 360.0 - 180.0)


def request_rates(sitl: ArduCopter) -> None:
    """The live messages compared with the log, from the boot on."""
    for msg_id, hz in (
        (mavlink2.MAVLINK_MSG_ID_ATTITUDE, 25.0),
        (mavlink2.MAVLINK_MSG_ID_SYSTEM_TIME, 2.0),
        (mavlink2.MAVLINK_MSG_ID_GIMBAL_DEVICE_ATTITUDE_STATUS, 20.0),
        (mavlink2.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 10.0),
    ):
        sitl.observer.request_interval(msg_id, hz)


def prepare(tmp: Path, background: bool) -> Booting:
    """ArduCopter booting in ``tmp/copter`` with :func:`request_rates`: ~40 s from its start to EKF3 using the GPS,
    made while the module before this one runs (``tests/ahead.py``)."""
    binary, parms = arducopter_files()
    copter = ArduCopter(
        binary,
        parms,
        tmp / "copter",
        home=(LAT, LON, HOME_AMSL_M, 0.0),
        extra_parm=EXTRA,
        keep=KEEP,
    )
    return Booting(copter, then=request_rates)


@pytest.mark.ahead.with_args(prepare, module_before=True)
def test_a_dataflash_log_imported_says_what_the_autopilot_said_live(tmp_path, prepared):
    sitl = prepared.sitl
    binary = sitl.binary
    try:
        prepared.ready()
        obs = sitl.observer
        takeoff_boot_ms, survey_span = fly(obs)
    finally:
        sitl.stop()
    logs = sorted((sitl.dir / "logs").glob("*.BIN"))
    assert logs, sitl.tail()
    t_live = [m.time_boot_ms for m in live(obs, "ATTITUDE")]
    depth = tmp_path / "depth.jsonl"  # the UUV's depth is not this test's: a constant, on UNIX time
    clock = np.median(
        [
            m.time_unix_usec / 1e6 - m.time_boot_ms / 1e3
            for m in live(obs, "SYSTEM_TIME")
            if m.time_unix_usec
        ]
    )
    depth.write_text(
        "".join(json.dumps({"t": clock + t / 1e3, "depth_m": 1.0}) + "\n" for t in t_live[::10])
    )
    cal = tmp_path / "cal.toml"
    cal.write_text(
        (ROOT / "deploy" / "calibration.toml")
        .read_text()
        .replace('attitude_source = "gimbal_device"', 'attitude_source = "mount_orientation"')
    )
    report = import_flight(logs[-1], None, depth, cal, tmp_path / "session")
    got = {}
    for _, m in read_tlog(tmp_path / "session" / "uav.tlog"):
        got.setdefault(m.get_type(), []).append(m)

    # the log's clock on UNIX time, against the autopilot's own SYSTEM_TIME
    clock_error_s = report["unix_minus_boot_s"] - clock
    # the attitude: the session's (10 Hz) at each live ATTITUDE's time
    att = got["ATTITUDE"]
    t_imp = np.array([m.time_boot_ms for m in att], float)
    inside = flying(obs, "ATTITUDE", takeoff_boot_ms, t_imp)
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
    gim = flying(obs, "GIMBAL_DEVICE_ATTITUDE_STATUS", takeoff_boot_ms, t_m)
    w, x, y, z = np.array([m.q for m in gim]).T
    r_live = Rotation.from_quat(np.column_stack([x, y, z, w]))
    flags = {m.flags & mavlink2.GIMBAL_DEVICE_FLAGS_YAW_IN_EARTH_FRAME for m in gim}
    field = "yaw_absolute" if flags == {mavlink2.GIMBAL_DEVICE_FLAGS_YAW_IN_EARTH_FRAME} else "yaw"
    t_g = np.array([m.time_boot_ms for m in gim], float)
    zyx_m = np.column_stack(
        [
            np.unwrap([getattr(m, name) for m in mnt], period=360.0)
            for name in (field, "pitch", "roll")
        ]
    )
    zyx = np.column_stack([np.interp(t_g, t_m, zyx_m[:, k]) for k in range(3)])
    gim_err = np.degrees((r_live.inv() * Rotation.from_euler("ZYX", zyx, degrees=True)).magnitude())
    pitch = zyx[:, 1]
    # left out: the live samples between two log records across a step of the gimbal, where the log cannot say
    # the angle (it jumps within one live report, 50 ms, and a 10 Hz log interpolated across it is off by up to
    # the step)
    r_m = Rotation.from_euler("ZYX", zyx_m, degrees=True)
    step_deg = np.degrees((r_m[:-1].inv() * r_m[1:]).magnitude())
    k = np.clip(np.searchsorted(t_m, t_g), 1, len(t_m) - 1)  # t_m[k - 1] <= t_g <= t_m[k]
    across = (step_deg[k - 1] > STEP_DEG) & (t_m[k - 1] < t_g) & (t_g < t_m[k])
    steps = int(np.sum(step_deg > STEP_DEG))
    held = gim_err[~across]
    # the position, the session's interpolated to each live message's time
    gpi = got["GLOBAL_POSITION_INT"]
    t_p = np.array([m.time_boot_ms for m in gpi], float)
    near = [m for m in live(obs, "GLOBAL_POSITION_INT") if t_p[0] <= m.time_boot_ms <= t_p[-1]]
    t_n = np.array([m.time_boot_ms for m in near], float)

    def at(name):
        return np.interp(t_n, t_p, [getattr(m, name) for m in gpi]) - np.array(
            [getattr(m, name) for m in near]
        )

    horizontal = np.hypot(at("lat") * 0.0111, at("lon") * 0.0111 * np.cos(np.radians(LAT)))
    vertical = np.abs(at("alt")) / 1000.0
    pairs = near
    print(
        f"\nArduCopter SITL {binary}: log {logs[-1].name}, {report['messages']}\n"
        f"clock: the log's on UNIX time - SYSTEM_TIME's {clock_error_s * 1000:+.1f} ms "
        f"(± {report['unix_minus_boot_sigma_s'] * 1000:.1f} ms)\n"
        f"attitude: {len(t_l)} live ATTITUDE in the flight, worst axis: median {np.median(att_err):.3f}°, "
        f"p99 {np.percentile(att_err, 99):.3f}°, max {att_err.max():.3f}°\n"
        f"gimbal: {len(t_g)} live GIMBAL_DEVICE_ATTITUDE_STATUS ({field}) in the flight, {across.sum()} left out "
        f"(between the two log records of one of its {steps} steps > {STEP_DEG:.0f}°: "
        f"{np.array2string(step_deg[step_deg > STEP_DEG], precision=1)}°, off by up to "
        f"{gim_err[across].max(initial=0.0):.1f}° there); the rest: median {np.median(held):.3f}°, "
        f"p99 {np.percentile(held, 99):.3f}°, max {held.max():.3f}°; pitch range "
        f"{pitch.min():.0f}…{pitch.max():.0f}°\n"
        f"position: {len(pairs)} live GLOBAL_POSITION_INT: horizontal median {np.median(horizontal):.3f} m, max "
        f"{horizontal.max():.3f} m; vertical median {np.median(vertical):.3f} m, max {vertical.max():.3f} m"
    )
    assert abs(clock_error_s) <= 0.01
    assert len(t_l) > 300 and np.median(att_err) <= 0.05 and np.percentile(att_err, 99) <= 0.2
    assert att_err.max() <= 1.0
    assert len(held) > 200 and pitch.min() < -85 and held.max() <= 0.1
    assert steps >= len(GIMBAL) and across.sum() <= 3 * steps
    assert len(pairs) > 100 and horizontal.max() <= 0.2 and vertical.max() <= 0.2
    the_survey_filmed_is_located(tmp_path, logs[-1], clock, survey_span)


def sim_truth(log) -> tuple[np.ndarray, Rotation, np.ndarray]:
    """The simulator's own state in its log (``SIM``: read by this test only, never by the import): boot s, the
    vehicle's attitude, its position (lat, lon deg, alt m AMSL)."""
    reader = mavutil().mavlink_connection(str(log))
    rows = []
    while (m := reader.recv_match(type="SIM")) is not None:
        rows.append((m.TimeUS / 1e6, m.Roll, m.Pitch, m.Yaw, m.Lat, m.Lng, m.Alt))
    reader.close()
    a = np.array(rows)
    return a[:, 0], Rotation.from_euler("ZYX", a[:, [3, 2, 1]], degrees=True), a[:, 4:7]


def the_survey_filmed_is_located(
    tmp_path, log, clock_s: float, survey_span: tuple[float, float]
) -> None:
    """The survey as the camera filmed it: ``sim_fixtures`` renders a UUV 1.5 m deep, 1 m North of where the vehicle
    hovered, seen from the simulator's own vehicle pose (its SIM records) and the gimbal as commanded (a
    self-stabilising gimbal: roll 0 and :data:`SURVEY_PITCH_DEG` to the horizon, yaw with the vehicle); the video
    starts at an offset the import is not told. ``skyfix import`` finds the start from the image's motion against
    the logged attitude, and ``skyfix process`` of the imported session locates the UUV."""
    from groundstation.offline.evaluate import errors_m
    from groundstation.offline.process import process_session
    from groundstation.session.read import load_session
    from sim_fixtures.generate import Encoder, camera_of, generate
    from sim_fixtures.geometry import R_GIMBAL_FROM_CV
    from sim_fixtures.render import Renderer, View
    from sim_fixtures.scenario import load_scenario, with_overrides

    sc = with_overrides(
        load_scenario(ROOT / "sim_fixtures" / "scenarios" / "mount_orientation.toml"),
        site={"lat_deg": LAT, "lon_deg": LON, "surface_amsl_m": HOME_AMSL_M},
        uuv={"depth_m": UUV_DEPTH_M},
    )
    camera, fps = camera_of(sc), sc.fps
    t_sim, R_body, lla = sim_truth(log)
    # on the log's UNIX clock; the frames its SIM records cover (the autopilot stopped, its last records may not
    # have reached the file: CI once lost the survey's end)
    frames_t = np.arange(survey_span[0] + VIDEO_LATE_S, survey_span[1], 1.0 / fps)
    covered = frames_t - clock_s <= t_sim[-1]
    assert covered.mean() >= 0.8, (
        f"the log's SIM records end at boot {t_sim[-1]:.2f} s, {covered.mean():.0%} into the survey"
    )
    frames_t = frames_t[covered]
    boot = frames_t - clock_s
    ned = np.column_stack(
        pymap3d.geodetic2ned(lla[:, 0], lla[:, 1], lla[:, 2], LAT, LON, HOME_AMSL_M)
    )
    vehicle = np.column_stack([np.interp(boot, t_sim, ned[:, k]) for k in range(3)])
    R_ned_from_body = Slerp(t_sim, R_body)(boot)
    camera_ned = vehicle + R_ned_from_body.apply(np.asarray(sc.mount.camera_offset_m))
    heading = R_ned_from_body.as_euler("ZYX", degrees=True)[:, 0]
    R_ned_from_gimbal = Rotation.from_euler(
        "ZYX",
        np.column_stack([heading, np.full_like(heading, SURVEY_PITCH_DEG), np.zeros_like(heading)]),
        degrees=True,
    )
    uuv_ned = np.array([vehicle[:, 0].mean() + 1.0, vehicle[:, 1].mean(), UUV_DEPTH_M])
    renderer, video = Renderer(sc, camera), tmp_path / "camera.mp4"
    encoder, first = Encoder(video, camera.width, camera.height, fps, sc.render.crf), None
    try:
        for i, t in enumerate(frames_t):
            img, box = renderer.render(
                View(
                    R_ned_from_gimbal[i].as_matrix() @ R_GIMBAL_FROM_CV,
                    camera_ned[i],
                    uuv_ned,
                    0.3,
                    True,
                    float(t - frames_t[0]),
                )
            )
            first = first or (box and (box, float(t)))
            encoder.write(img)
    finally:
        encoder.close()
    assert first, "the UUV is never in the rendered survey"
    (x, y, w, h), init_t = first[0], first[1]
    cal_dir = tmp_path / "calibration"
    generate(sc, cal_dir, video=False)  # the scenario's camera, mount and water tables
    cal = tmp_path / "cal.toml"
    cal.write_text(
        (cal_dir / "session.toml").read_text()
        + f"\n[tracker]\ninit_bbox = [{x - 3}, {y - 3}, {w + 6}, {h + 6}]\ninit_t = {init_t}\n"
    )
    depth = tmp_path / "uuv_depth.jsonl"
    depth.write_text(
        "".join(
            json.dumps({"t": t, "depth_m": UUV_DEPTH_M}) + "\n"
            for t in np.arange(frames_t[0] - 5, frames_t[-1] + 5, 0.5)
        )
    )
    out = tmp_path / "survey"
    report = import_flight(log, video, depth, cal, out)
    start_error_s = report["video_start_unix"] - frames_t[0]
    lat, lon, _ = pymap3d.ned2geodetic(*uuv_ned, LAT, LON, HOME_AMSL_M)
    (out / "truth.csv").write_text(
        "t,lat,lon,depth_m\n"
        + "".join(f"{t:.6f},{lat:.10f},{lon:.10f},{UUV_DEPTH_M}\n" for t in frames_t)
    )
    session = load_session(out)
    fixes = process_session(session, use_track=False)
    ok = fixes.status == "ok"
    err = errors_m(fixes, session.truth)[ok]
    err = err[np.isfinite(err)]
    print(
        f"survey: {len(frames_t)} frames rendered from the simulator's pose; video start from its motion "
        f"{start_error_s * 1000:+.1f} ms ± {report['video_start_sigma_s'] * 1000:.1f} ms (contrast "
        f"{report['video_start_contrast']}, {report['video_start_pairs']} pairs); {ok.mean():.1%} of frames fixed, "
        f"MAE {err.mean():.4f} m, max {err.max():.4f} m"
    )
    assert abs(start_error_s) <= 1.0 / fps, report
    assert ok.mean() >= 0.9 and len(err) >= 0.9 * len(ok) and err.mean() <= 0.05

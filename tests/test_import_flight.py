"""``skyfix import`` on DataFlash logs written here, record by record, in ArduPilot's binary layout (FMT records, then
messages), so every value and time is known by construction; ArduCopter's own log is test_sitl_arducopter_import.py.
The log also carries a simulator's ``SIM`` truth with other values: nothing of it may reach the session."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
from fractions import Fraction
from pathlib import Path

import av
import numpy as np
import pytest
from live_helpers import ROOT

from groundstation.cli import main
from groundstation.offline.import_flight import import_flight
from groundstation.session import SessionError
from groundstation.session.read import load_session
from groundstation.session.tlog import read_tlog
from groundstation.testing.dataflash_log import DataflashWriter

WEEK, WEEK_MS = 2447, 316_382_800  # the first GPS fix's time ...
BOOT_AT_FIX_S = 10.0  # ... arriving 10 s after the autopilot booted
# GPS epoch, weeks, ms, minus 18 leap seconds
UNIX_AT_FIX = 315964800 + WEEK * 604800 + WEEK_MS / 1000 - 18


def roll_deg(t):
    return 5.0 * math.sin(t)


def write_flight(
    path: Path,
    seconds: float = 20.0,
    gps_week: int = WEEK,
    trigger_at_s: float | None = None,
    mount: bool = True,
) -> None:
    """ATT and MNT (unless not ``mount``) at 10 Hz, POS at 10 Hz, GPS at 5 Hz (weeks and ms on a clock BOOT_AT_FIX_S
    behind), SIM at 10 Hz with other values, from boot 5 s on. The gimbal: pitch -60° from the horizon, yaw 10° right
    of the vehicle's (90°): 100° from North."""
    w = DataflashWriter(path)
    for k in range(round(seconds * 10)):
        t = 5.0 + k / 10
        us = round(t * 1e6)
        w.write("ATT", us, 0.0, roll_deg(t), 0.0, -2.0, 0.0, 90.0, 0)
        if mount:
            w.write("MNT", us, 0, 0.0, 0.5, -60.0, -60.0, 10.0, 10.0, 100.0, 100.0, float("nan"))
        w.write("POS", us + 500, round(63.44 * 1e7), round(10.4 * 1e7), 60.0 + t / 100, 10.0, 10.0)
        w.write(
            "SIM",
            us,
            3000,
            1000,
            18000,
            99.0,
            round(60.0 * 1e7),
            round(11.0 * 1e7),
            1.0,
            0.0,
            0.0,
            0.0,
        )
        if k % 2 == 0:
            week_ms = WEEK_MS + round((t - BOOT_AT_FIX_S) * 1000)
            w.write(
                "GPS",
                us,
                0,
                6,
                week_ms,
                gps_week,
                12,
                80,
                round(63.44 * 1e7),
                round(10.4 * 1e7),
                6000,
                0.0,
                0.0,
                0.0,
                0.0,
                1,
            )
        if trigger_at_s is not None and abs(t - trigger_at_s) < 1e-6:
            w.write("TRIG", us, 1)
    w.close()


def write_video(
    path: Path, frames: int = 30, fps: int = 30, size: tuple[int, int] = (1920, 1080)
) -> None:
    with av.open(str(path), "w") as out:
        s = out.add_stream("libx264", rate=fps)
        s.width, s.height, s.pix_fmt = *size, "yuv420p"
        s.time_base = Fraction(1, fps)
        for i in range(frames):
            f = av.VideoFrame.from_ndarray(
                np.full((size[1], size[0], 3), i * 8 % 255, np.uint8), format="bgr24"
            )
            f.pts = i
            for p in s.encode(f):
                out.mux(p)
        for p in s.encode():
            out.mux(p)


@pytest.fixture
def field_day(tmp_path):
    log, video, depth, cal = (
        tmp_path / n for n in ("flight.bin", "camera.mp4", "depth.csv", "cal.toml")
    )
    write_flight(log, trigger_at_s=12.0)
    write_video(video)
    start = UNIX_AT_FIX + 2.0  # boot 12 s
    depth.write_text(
        "time_unix,depth\n"
        + "".join(f"{start + i * 0.5:.3f},{1.0 + i * 0.01:.2f}\n" for i in range(20))
    )
    cal.write_text(
        (ROOT / "deploy" / "calibration.toml")
        .read_text()
        .replace('attitude_source = "gimbal_device"', 'attitude_source = "mount_orientation"')
    )
    return log, video, depth, cal, start


def test_a_log_becomes_a_session_on_gps_time_without_the_simulators_truth(field_day, tmp_path):
    log, video, depth, cal, start = field_day
    out = tmp_path / "session"
    report = import_flight(
        log, video, depth, cal, out, video_start_unix=start, depth_columns=("time_unix", "depth")
    )
    assert report["unix_minus_boot_s"] == pytest.approx(UNIX_AT_FIX - BOOT_AT_FIX_S, abs=1e-6)
    # the fixes agree: only the stamps' whole milliseconds
    assert report["unix_minus_boot_sigma_s"] <= 0.0005
    msgs = read_tlog(out / "uav.tlog")
    kinds = {m.get_type() for _, m in msgs}
    assert {
        "ATTITUDE",
        "GLOBAL_POSITION_INT",
        "SYSTEM_TIME",
        "MOUNT_ORIENTATION",
        "GPS_RAW_INT",
    } <= kinds
    for t_rec, m in msgs:  # every record at its own time on UNIX time, the log's values (not SIM's)
        if m.get_type() == "ATTITUDE":
            t = m.time_boot_ms / 1000
            assert t_rec == pytest.approx(UNIX_AT_FIX - BOOT_AT_FIX_S + t, abs=1e-6)
            assert math.degrees(m.roll) == pytest.approx(roll_deg(t), abs=1e-4) and math.degrees(
                m.yaw
            ) == pytest.approx(90.0, abs=1e-4)
        if m.get_type() == "GLOBAL_POSITION_INT":
            assert (m.lat, m.lon) == (634400000, 104000000) and abs(m.alt - 60_050) < 200
        if m.get_type() == "MOUNT_ORIENTATION":
            assert (m.pitch, m.yaw, m.yaw_absolute) == (-60.0, 10.0, 100.0)
        if m.get_type() == "SYSTEM_TIME":
            assert m.time_unix_usec / 1e6 - m.time_boot_ms / 1e3 == pytest.approx(
                UNIX_AT_FIX - BOOT_AT_FIX_S, abs=2e-3
            )
    frames = (out / "video_frames.csv").read_text().splitlines()
    assert frames[0] == "frame,t" and len(frames) == 31
    assert [float(r.split(",")[1]) for r in frames[1:]] == pytest.approx(
        [start + i / 30 for i in range(30)], abs=1e-6
    )
    depth_rows = [json.loads(line) for line in (out / "depth.jsonl").read_text().splitlines()]
    assert depth_rows[3] == {"t": pytest.approx(start + 1.5), "depth_m": 1.03}
    session = load_session(out)  # what process, evaluate, report, export and replay read
    assert session.telemetry.mount_type is None and len(session.frames["t"]) == 30
    assert (
        json.loads((out / "import.json").read_text())["video_start_from"]
        == "given (--video-start-unix)"
    )


def test_the_video_start_from_the_trigger_and_errors_that_name_the_value(field_day, tmp_path):
    log, video, depth, cal, start = field_day
    columns = ("time_unix", "depth")
    report = import_flight(
        log, video, depth, cal, tmp_path / "a", video_start_how="trigger", depth_columns=columns
    )
    assert report["video_start_unix"] == pytest.approx(UNIX_AT_FIX + 2.0, abs=1e-6)
    with pytest.raises(SessionError, match=r"its frames span .* not within the log's attitude"):
        import_flight(
            log,
            video,
            depth,
            cal,
            tmp_path / "b",
            video_start_unix=start + 60.0,
            depth_columns=columns,
        )
    with pytest.raises(
        SessionError, match=r"no column t, depth_m \(header \[.time_unix., .depth.\]\)"
    ):
        import_flight(log, video, depth, cal, tmp_path / "c", video_start_unix=start)
    bare = tmp_path / "bare.bin"
    write_flight(bare, gps_week=0)
    with pytest.raises(SessionError, match=r"no GPS time"):
        import_flight(bare, None, depth, cal, tmp_path / "d", depth_columns=columns)
    no_mount = tmp_path / "no_mount.bin"
    write_flight(no_mount, mount=False)
    with pytest.raises(
        SessionError, match=r"no MNT records, while the calibration's camera is on a gimbal"
    ):
        import_flight(
            no_mount,
            None,
            depth,
            ROOT / "deploy" / "calibration.toml",
            tmp_path / "e",
            depth_columns=columns,
        )
    not_a_log = tmp_path / "video.bin"
    not_a_log.write_bytes(video.read_bytes())
    assert (
        main(
            [
                "import",
                "--dataflash",
                str(not_a_log),
                "--depth",
                str(depth),
                "--depth-columns",
                "time_unix,depth",
                "--calibration",
                str(cal),
                "--out",
                str(tmp_path / "f"),
            ]
        )
        == 2
    )


def test_the_live_calibration_imports_its_log(field_day, tmp_path):
    """deploy/calibration.toml as the live run uses it (``attitude_source = "gimbal_device"``, what ArduCopter sends)
    imports the same drone's log: the MNT records become GIMBAL_DEVICE_ATTITUDE_STATUS, and the camera points where
    they say, as with ``mount_orientation``: its optical axis 60° below the horizon, 100° from North."""
    from localizer.pose import camera_pose

    log, _, depth, mount_cal, start = field_day
    axes = {}
    for name, cal in (
        ("gimbal_device", ROOT / "deploy" / "calibration.toml"),
        ("mount_orientation", mount_cal),
    ):
        import_flight(log, None, depth, cal, tmp_path / name, depth_columns=("time_unix", "depth"))
        kinds = {m.get_type() for _, m in read_tlog(tmp_path / name / "uav.tlog")}
        assert ("GIMBAL_DEVICE_ATTITUDE_STATUS" in kinds) == (name == "gimbal_device")
        assert ("MOUNT_ORIENTATION" in kinds) == (name == "mount_orientation")
        session = load_session(tmp_path / name)
        assert session.calibration.mount.attitude_source == name
        pose = camera_pose(session.calibration, session.telemetry, start + np.arange(0.0, 5.0, 0.5))
        assert set(pose.status) == {"ok"}
        axes[name] = pose.R_ned_from_cv[:, :, 2]  # the optical axis (OpenCV z) in NED
    down, azimuth = math.radians(60.0), math.radians(100.0)
    expected = [
        math.cos(down) * math.cos(azimuth),
        math.cos(down) * math.sin(azimuth),
        math.sin(down),
    ]
    for name, axis in axes.items():
        assert axis == pytest.approx(np.tile(expected, (len(axis), 1)), abs=1e-6), name


def test_a_file_that_is_not_a_log_is_one_line_and_leaves_no_folder(tmp_path):
    """4 KB of noise as --dataflash: one line naming it (pymavlink's 3,570 "bad header" lines never printed) and no
    --out folder left behind."""
    noise = tmp_path / "noise.bin"
    noise.write_bytes(np.random.default_rng(29).integers(0, 256, 4096, dtype=np.uint8).tobytes())
    depth = tmp_path / "depth.jsonl"
    depth.write_text('{"t": 1.0, "depth_m": 1.0}\n')
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "groundstation.cli",
            "import",
            "--dataflash",
            str(noise),
            "--depth",
            str(depth),
            "--calibration",
            str(ROOT / "deploy" / "calibration.toml"),
            "--out",
            str(tmp_path / "new" / "session"),
        ],
        check=False,
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )
    assert out.returncode == 2 and out.stdout == ""
    begins = noise.read_bytes()[:3].hex(" ")
    line = f"skyfix import: error: {noise}: not a DataFlash log (it begins {begins}, a binary log a3 95 80)"
    assert out.stderr.splitlines() == [line]
    assert not (tmp_path / "new").exists()


@pytest.fixture(scope="module")
def generated(tmp_path_factory):
    """A generated flight (``fixed_camera``: the camera rigid on an airframe that tilts, gusts and swings its yaw)
    whose telemetry starts 20 s before its 6 s of video; its own truth says where the UUV was."""
    from sim_fixtures.generate import generate
    from sim_fixtures.scenario import load_scenario, with_overrides

    if shutil.which("ffmpeg") is None:
        pytest.skip("ffmpeg is needed to render the video")
    sc = with_overrides(
        load_scenario(ROOT / "sim_fixtures" / "scenarios" / "fixed_camera.toml"),
        duration_s=6.0,
        telemetry={"lead_s": 20.0},
    )
    out = tmp_path_factory.mktemp("generated") / "flight"
    generate(sc, out)
    return out


def dataflash_of(session: Path, path: Path) -> None:
    """The generated flight's telemetry as its autopilot would have logged it: ATT (and IMU: its rates) from
    ATTITUDE, POS from GLOBAL_POSITION_INT, GPS fixes (week and ms) from SYSTEM_TIME, each at its time_boot_ms."""
    w = DataflashWriter(path, ("ATT", "POS", "GPS", "IMU"))
    for _, m in read_tlog(session / "uav.tlog"):
        us = m.time_boot_ms * 1000 if hasattr(m, "time_boot_ms") else None
        if m.get_type() == "ATTITUDE":
            w.write(
                "ATT",
                us,
                0.0,
                math.degrees(m.roll),
                0.0,
                math.degrees(m.pitch),
                0.0,
                math.degrees(m.yaw) % 360.0,
                0,
            )
            w.write("IMU", us, 0, m.rollspeed, m.pitchspeed, m.yawspeed)
        elif m.get_type() == "GLOBAL_POSITION_INT":
            w.write(
                "POS", us, m.lat, m.lon, m.alt / 1000, m.relative_alt / 1000, m.relative_alt / 1000
            )
        elif m.get_type() == "SYSTEM_TIME" and m.time_unix_usec:
            gps_s = m.time_unix_usec / 1e6 + 18 - 315964800
            week = int(gps_s // 604800)
            w.write(
                "GPS",
                us,
                0,
                6,
                round((gps_s - week * 604800) * 1000),
                week,
                12,
                80,
                0,
                0,
                0,
                0.0,
                0.0,
                0.0,
                0.0,
                1,
            )
    w.close()


def test_the_videos_start_is_found_from_its_motion_and_the_flight_is_located(generated, tmp_path):
    """The generated flight's video given to ``skyfix import`` with no start: the image's motion against the logged
    attitude, searched across the 26 s of log, finds its first frame within one frame of the truth, and ``skyfix
    process`` of the imported session locates the UUV as in the generated one."""
    from groundstation.offline.evaluate import errors_m
    from groundstation.offline.process import process_session

    log = tmp_path / "flight.bin"
    dataflash_of(generated, log)
    out = tmp_path / "imported"
    report = import_flight(
        log, generated / "video.mp4", generated / "depth.jsonl", generated / "session.toml", out
    )
    true_start = float((generated / "video_frames.csv").read_text().splitlines()[1].split(",")[1])
    error_s = report["video_start_unix"] - true_start
    print(
        f"\nvideo start from its motion: {error_s * 1000:+.1f} ms ± {report['video_start_sigma_s'] * 1000:.1f} ms "
        f"(contrast {report['video_start_contrast']}) over {report['video_start_pairs']} pairs, thirds "
        f"{[None if t is None else round((t - true_start) * 1000, 1) for t in report['video_start_thirds_unix']]} ms"
    )
    assert abs(error_s) <= 1 / 30 and report["video_start_from"].startswith("the image's motion")
    session = load_session(out)
    session.truth = load_session(generated).truth
    fixes = process_session(session, use_track=False)
    ok = fixes.status == "ok"
    err = errors_m(fixes, session.truth)[ok]
    err = err[
        np.isfinite(err)
    ]  # the truth is sampled at the true frame times: the ends may fall just outside
    print(
        f"imported: {ok.mean():.1%} of frames fixed, MAE {err.mean():.4f} m, max {err.max():.4f} m"
    )
    assert ok.mean() >= 0.9 and len(err) >= 0.9 * len(ok) and err.mean() <= 0.05


def test_a_video_the_log_cannot_place_is_an_error_naming_both_spans(generated, tmp_path):
    log = tmp_path / "flight.bin"
    dataflash_of(generated, log)
    still = tmp_path / "still.mp4"
    write_video(still, frames=90, size=(640, 360))  # no motion at all
    with pytest.raises(
        SessionError, match=r"still.mp4: .* against the log's attitude \d+\.\d+–\d+\.\d+"
    ):
        import_flight(
            log, still, generated / "depth.jsonl", generated / "session.toml", tmp_path / "s"
        )

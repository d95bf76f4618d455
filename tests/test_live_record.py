"""``skyfix run --record``: the session is written as it goes (flushed every second) and survives a kill -9."""

from __future__ import annotations

import asyncio
import contextlib
import json
import socket
import time
import tomllib

import numpy as np
from live_helpers import free_port, skyfix, start, stop, until, wait_for

from groundstation.live.sinks.recorder import Recorder
from groundstation.mavlink.ingest import ingest, mavutil
from groundstation.runtime.zenoh_session import open_session
from groundstation.session.read import load_session, read_table
from localizer.calibration import Calibration
from localizer.fix import Fix
from localizer.telemetry import Telemetry

CAL = """
[camera]
width = 640
height = 360
fx = 500.0
fy = 500.0
cx = 319.5
cy = 179.5
[mount]
attitude_source = "fixed"
fixed_rpy_deg = [0.0, -90.0, 0.0]
[water]
takeoff_height_above_surface_m = 1.5
"""


def test_recording_is_flushed_and_survives_kill(tmp_path):
    (tmp_path / "cal.toml").write_text(CAL)
    port, ep = free_port(), f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    rec = tmp_path / "rec"
    service = start(
        skyfix(
            "run",
            "--calibration",
            str(tmp_path / "cal.toml"),
            "--mavlink",
            f"udpin:127.0.0.1:{port}",
            "--zenoh-listen",
            ep,
            "--video",
            "none",
            "--gps-input",
            "none",
            "--record",
            str(rec),
            "--duration-s",
            "25",
        ),
        tmp_path / "run.log",
    )
    zs = open_session(connect=[ep])
    seen = []
    sub = zs.declare_subscriber("skyfix/status", lambda s: seen.append(1))
    mav = mavutil()
    uav = mav.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=1, source_component=1)
    sent = 0
    try:
        wait_for(lambda: seen, 15, "the service's status")
        t0 = time.time()
        i = 0
        sizes_while_running = None
        while time.time() - t0 < 3.0:
            boot = 50_000 + 20 * i
            if i % 50 == 0:
                uav.mav.heartbeat_send(2, 3, 0, 0, 4)
                uav.mav.system_time_send(int(time.time() * 1e6), boot)
            uav.mav.attitude_send(boot, 0.0, 0.0, 0.3, 0, 0, 0)
            uav.mav.global_position_int_send(boot, 634400000, 104000000, 5000, 3000, 0, 0, 0, 0)
            sent += 1
            if i % 5 == 0:
                zs.put("uuv/depth", json.dumps({"t": time.time(), "depth_m": 1.0 + 0.001 * i}))
            if i == 125:  # 2.5 s in: everything received until 1.5 s ago must be on disk
                sizes_while_running = {p.name: p.stat().st_size for p in rec.iterdir()}
            i += 1
            time.sleep(0.02)
        time.sleep(0.3)
        service.kill()  # SIGKILL: no chance to flush or close
        service.wait()
    finally:
        if service.poll() is None:
            service.kill()
            service.wait()
        uav.close()
        sub.undeclare()
        zs.close()
    assert sizes_while_running["uav.tlog"] > 1000 and sizes_while_running["depth.jsonl"] > 100
    session = load_session(rec)
    assert sent - 60 <= len(session.telemetry.attitude) <= sent  # at most the last second lost
    assert len(session.telemetry.position) >= sent - 60 and len(session.telemetry.depth) >= 20
    first = json.loads((rec / "depth.jsonl").read_text().splitlines()[0])
    # what the service used: the calibration's sigma
    assert first["source"] == "skyfix" and "sigma_m" not in first
    assert session.calibration.mount.attitude_source == "fixed"
    assert (rec / "positions.csv").read_text().startswith("t,lat,lon,depth_m,h_acc_m,status")


def test_recording_says_when_the_link_delay_was_measured(tmp_path):
    """A UAV whose link delays everything by 30 ms answers TIMESYNC only from 2 s on: the recording's
    [timing] gets the delay measured and the station time it was first measured (updated as the run goes),
    and skyfix process measures the same from the recorded tlog."""
    delay_s = 0.030
    (tmp_path / "cal.toml").write_text(CAL)
    port, ep = free_port(), f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    rec = tmp_path / "rec"
    service = start(
        skyfix(
            "run",
            "--calibration",
            str(tmp_path / "cal.toml"),
            "--mavlink",
            f"udpin:127.0.0.1:{port}",
            "--zenoh-listen",
            ep,
            "--video",
            "none",
            "--gps-input",
            "none",
            "--record",
            str(rec),
            "--duration-s",
            "40",
        ),
        tmp_path / "run.log",
    )
    mav = mavutil()
    uav = mav.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=1, source_component=1)
    t0 = time.time()

    def boot_s(t: float) -> float:  # the autopilot's clock
        return 50.0 + (t - t0)

    def recorded() -> dict:
        try:
            return tomllib.loads((rec / "session.toml").read_text()).get("timing", {})
        except (OSError, tomllib.TOMLDecodeError):
            return {}

    answered_from = t0 + 2.0
    try:
        i = 0
        while "mavlink_latency_measured_s" not in recorded() and time.time() - t0 < 20.0:
            now = time.time()
            sampled = boot_s(now - delay_s)  # what arrives now was sampled delay_s ago
            if i % 50 == 0:
                uav.mav.heartbeat_send(2, 3, 0, 0, 4)
            uav.mav.attitude_send(int(sampled * 1000), 0.0, 0.0, 0.3, 0, 0, 0)
            while (m := uav.recv_match(type="TIMESYNC", blocking=False)) is not None:
                if (
                    m.tc1 == 0 and now >= answered_from
                ):  # a request reached the autopilot delay_s after it left
                    uav.mav.timesync_send(int(boot_s(m.ts1 / 1e9 + delay_s) * 1e9), m.ts1)
            i += 1
            time.sleep(0.02)
        stop(service)
    finally:
        if service.poll() is None:
            service.kill()
            service.wait()
        uav.close()
    assert service.returncode == 0, (tmp_path / "run.log").read_text()[-3000:]
    timing = recorded()
    print(timing)
    assert abs(timing["mavlink_latency_measured_s"] - delay_s) < 0.003
    assert answered_from < timing["mavlink_latency_measured_from_t"] < answered_from + 3.0
    assert "video_latency_s" not in timing and "mavlink_latency_s" not in timing
    # keys of the contract
    cal = Calibration.from_dict(tomllib.loads((rec / "session.toml").read_text()))
    assert cal.timing.mavlink_latency_measured_s == timing["mavlink_latency_measured_s"]
    tel = Telemetry(cal.timing)  # the recorded tlog, as skyfix process reads it
    tlog = mav.mavlink_connection(str(rec / "uav.tlog"))
    while (m := tlog.recv_msg()) is not None:
        ingest(tel, m, m._timestamp)
    tlog.close()
    assert (
        tel.latency_source == "timesync"
        and abs(tel.measured_latency_s - timing["mavlink_latency_measured_s"]) < 1e-3
    )


def test_recorded_tables_keep_their_times_increasing(tmp_path):
    """--video-latency-ms auto applying its estimate moves the frames' times back: fixes not later than the one
    before are left out (as the video writer leaves out such frames), so positions.csv and track.csv stay
    readable; [timing] gets what the run used as plain TOML numbers, and not another recording's."""
    (tmp_path / "cal.toml").write_text(
        CAL + "[timing]\nclock_window_s = 20.0\nmavlink_latency_measured_s = 0.5\n"
    )
    used = {"video_latency_s": np.float64(0.0794), "video_latency_source": "motion"}
    rec = Recorder(str(tmp_path / "rec"), str(tmp_path / "cal.toml"), timing=lambda: used)
    for t, status in (
        (100.000, "latency_unsettled"),
        (100.033, "latency_unsettled"),
        (99.987, "lost"),
        (100.020, "lost"),
        (100.054, "lost"),
    ):
        rec.first.on_fix(Fix(t, status), None)

    def written(name: str) -> int:
        path = tmp_path / "rec" / name
        return path.read_text().count("\n") if path.exists() else 0

    async def record_a_moment():
        task = asyncio.create_task(rec.run())
        # the header and the three fixes (the writer thread flushes every second)
        await until(lambda: written("positions.csv") >= 4, 30.0, "positions.csv written")
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task

    asyncio.run(record_a_moment())
    assert rec.dropped == 2 and rec.fixes == 3
    for name in ("positions.csv", "track.csv"):
        assert list(read_table(tmp_path / "rec" / name, ("t",), allow_empty=("u", "v"))["t"]) == [
            100.0,
            100.033,
            100.054,
        ]
    timing = tomllib.loads((tmp_path / "rec" / "session.toml").read_text())["timing"]
    assert timing == {
        "clock_window_s": 20.0,
        "video_latency_s": 0.0794,
        "video_latency_source": "motion",
    }

"""``skyfix run --record``: the session is written as it goes (flushed every second) and survives a kill -9."""

from __future__ import annotations

import json
import socket
import time

from live_helpers import free_port, skyfix, start, wait_for

from groundstation.mavlink_io import mavutil
from groundstation.session import load_session
from groundstation.zenoh_session import open_session

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
    service = start(skyfix("run", "--calibration", str(tmp_path / "cal.toml"), "--mavlink", f"udpin:127.0.0.1:{port}",
                           "--zenoh-listen", ep, "--record", str(rec), "--duration-s", "25"), tmp_path / "run.log")
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
    assert first["source"] == "skyfix" and "sigma_m" not in first  # what the service used: the calibration's sigma
    assert session.calibration.mount.attitude_source == "fixed"
    assert (rec / "positions.csv").read_text().startswith("t,lat,lon,depth_m,h_acc_m,status")

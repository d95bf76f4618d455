"""ArduSub SITL rebooted under a running ``skyfix run --gps-input tcp:…``: the bug this guards against crashed the
service (pymavlink reconnecting from two threads, then ConnectionRefusedError out of the sink).

ArduSub (the real firmware, see ``test_sitl_ardusub.py``) takes GPS_INPUT on SERIAL1 from ``skyfix run``, which has
no video: it sends "no fix" at 10 Hz, enough for ArduSub to detect a MAVLink GPS. ArduSub is stopped (SIGTERM),
stays away :data:`DOWN_S`, and is started again on the same ports. Checked: the service keeps running, its status
names the GPS_INPUT link down meanwhile, ArduSub sees GPS_INPUT again within 1 s of being back (its first
HEARTBEAT after the restart, by when SERIAL1 listens; measured on the copies it forwards to a ground station on
SERIAL0), and the service stops cleanly (exit 0).
"""

from __future__ import annotations

import json
import socket
import subprocess
import time

import pytest
from live_helpers import ROOT, free_port, skyfix, start, stop, wait_for
from test_sitl_ardusub import LAT, LON, SURFACE_AMSL_M, ArduSub, ardusub_files

from groundstation.runtime.zenoh_session import open_session

pytestmark = pytest.mark.sitl

SESSION = ROOT / "sim_fixtures" / "bundled" / "nadir_hover"
DOWN_S = 3.0  # how long the autopilot is away (a reboot)
RESUME_S = 1.0


def test_ardusub_reboot_under_a_running_service(tmp_path):
    binary, sub_parm = ardusub_files()
    sitl = ArduSub(binary, sub_parm, tmp_path / "ardusub", home=(LAT, LON, SURFACE_AMSL_M, 0.0))
    ep = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    run_log = tmp_path / "run.log"
    statuses: list[dict] = []
    service = watcher = sub = None
    try:
        sitl.start()
        service = start(
            skyfix(
                "run",
                "--calibration",
                str(SESSION / "session.toml"),
                "--mavlink",
                f"udpin:127.0.0.1:{free_port()}",
                "--zenoh-listen",
                ep,
                "--video",
                "none",
                "--gps-input",
                f"tcp:127.0.0.1:{sitl.ports['serial1']}",
                "--duration-s",
                "300",
            ),
            run_log,
        )
        watcher = open_session(connect=[ep])
        sub = watcher.declare_subscriber(
            "skyfix/status", lambda s: statuses.append(json.loads(s.payload.to_bytes()))
        )
        wait_for(
            lambda: len(sitl.observer.of("GPS_INPUT")) >= 10 or service.poll() is not None,
            60,
            "GPS_INPUT forwarded by ArduSub",
        )
        assert service.poll() is None, run_log.read_text()[-3000:]

        sitl.stop()  # SIGTERM: its TCP ports close
        t_down = time.time()
        wait_for(
            lambda: any(
                s["t"] > t_down and s["gps_input"]["link"]["state"] == "down" for s in statuses
            ),
            10,
            "the status naming the GPS_INPUT link down",
        )
        with pytest.raises(subprocess.TimeoutExpired):
            service.wait(DOWN_S)  # the autopilot stays away; the service keeps running

        # returns at its first HEARTBEAT: booted, SERIAL1 listening
        sitl.start(instance=sitl.instance)
        t_back = sitl.observer.of("HEARTBEAT")[0][0]
        wait_for(
            lambda: sitl.observer.of("GPS_INPUT", t_back) or service.poll() is not None,
            30,
            "GPS_INPUT at the restarted ArduSub",
        )
        resumed_s = sitl.observer.of("GPS_INPUT", t_back)[0][0] - t_back
        assert service.poll() is None, run_log.read_text()[-3000:]
        stop(service)
    finally:
        if sub is not None:
            sub.undeclare()
            watcher.close()
        if service is not None:
            stop(service, 5.0)
        sitl.stop()
    log = run_log.read_text()
    down = next(
        s["gps_input"]["link"]
        for s in statuses
        if s["t"] > t_down and s["gps_input"]["link"]["state"] == "down"
    )
    print(
        f"ArduSub away {DOWN_S:g} s: status said {down['state']} ({down['error']}); GPS_INPUT at ArduSub again "
        f"{resumed_s * 1000:.0f} ms after its first HEARTBEAT"
    )
    assert service.returncode == 0 and "Traceback" not in log, log[-3000:]
    assert resumed_s <= RESUME_S, f"GPS_INPUT came back {resumed_s:.3f} s after ArduSub was back"

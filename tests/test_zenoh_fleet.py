"""The fleet configs of ``deploy/zenoh/`` on loopback: two routers stand for two machines (a drone laptop and the
UUV's companion), each a Python Zenoh session in router mode with ``fleet-router.json5``, its own process, the
laptop's connecting to the companion's. ``skyfix run`` and ``skyfix replay`` are clients of the laptop's router
(``fleet-client.json5``); a subscriber on the companion's router must receive the service's fixes through both
routers, and a late joiner there must get the latest fix from the service's queryable. The deploy files are used
as written, only their endpoints replaced."""

from __future__ import annotations

import json
import socket
import subprocess
import sys

import zenoh
from live_helpers import free_port, stop
from test_zenoh_security import ROUTER, deployed, replayed_through

ROUTER_ENDPOINTS = '["tcp/192.168.2.2:7447", "tcp/192.168.2.3:7447"]'


def test_fixes_cross_two_routers_to_the_companion_and_late_joiners_get_the_latest(tmp_path):
    laptop_port, companion_port = free_port(socket.SOCK_STREAM), free_port(socket.SOCK_STREAM)
    laptop_dir, companion_dir = tmp_path / "laptop", tmp_path / "companion"
    laptop_dir.mkdir()
    companion_dir.mkdir()
    companion_router = deployed(
        "fleet-router.json5",
        companion_dir,
        {"tcp/0.0.0.0:7447": f"tcp/127.0.0.1:{companion_port}", ROUTER_ENDPOINTS: "[]"},
    )
    laptop_router = deployed(
        "fleet-router.json5",
        laptop_dir,
        {
            "tcp/0.0.0.0:7447": f"tcp/127.0.0.1:{laptop_port}",
            ROUTER_ENDPOINTS: f'["tcp/127.0.0.1:{companion_port}"]',
        },
    )
    laptop_client = deployed(
        "fleet-client.json5", laptop_dir, {"tcp/127.0.0.1:7447": f"tcp/127.0.0.1:{laptop_port}"}
    )
    companion_client = deployed(
        "fleet-client.json5",
        companion_dir,
        {"tcp/127.0.0.1:7447": f"tcp/127.0.0.1:{companion_port}"},
    )
    routers = [
        subprocess.Popen(
            [sys.executable, "-c", ROUTER, str(cfg)], stdout=subprocess.PIPE, text=True
        )
        for cfg in (companion_router, laptop_router)
    ]
    procs = list(routers)
    fixes: list[dict] = []
    sub = uuv_side = late = None
    try:
        assert [r.stdout.readline().strip() for r in routers] == ["ready", "ready"]
        uuv_side = zenoh.open(zenoh.Config.from_file(str(companion_client)))
        sub = uuv_side.declare_subscriber(
            "skyfix/uuv/fix", lambda s: fixes.append(json.loads(s.payload.to_bytes()))
        )
        service = replayed_through(tmp_path, laptop_client, procs)
        # a console joining at the companion after the flight: the service's latest fix, through both routers
        late = zenoh.open(zenoh.Config.from_file(str(companion_client)))
        replies = [r.ok for r in late.get("skyfix/uuv/fix", timeout=10.0) if r.ok is not None]
        stop(service)
        assert service.returncode == 0, (tmp_path / "run.log").read_text()[-3000:]
    finally:
        if sub is not None:
            sub.undeclare()
        for session in [s for s in (uuv_side, late) if s is not None]:
            session.close()
        for p in procs:
            stop(p, 5.0)
    ok = [f for f in fixes if f["status"] == "ok"]
    print(
        f"fleet: {len(fixes)} fixes at the companion's router, {len(ok)} ok; late joiner got {len(replies)} reply"
    )
    assert len(ok) >= 30, f"only {len(ok)} ok fixes of {len(fixes)} crossed the two routers"
    assert len(replies) == 1, replies
    latest = json.loads(replies[0].payload.to_bytes())
    assert latest["t"] == fixes[-1]["t"] and latest["frame"] == fixes[-1]["frame"], (
        latest,
        fixes[-1],
    )

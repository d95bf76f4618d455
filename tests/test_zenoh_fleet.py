"""The fleet configs of ``deploy/zenoh/`` on loopback: two routers stand for two machines (the topside laptop and the
UUV's companion), each a Python Zenoh session in router mode with ``fleet-router.json5``, its own process, the
laptop's connecting to the companion's over TLS with mutual authentication, each with its machine's certificate
made here by ``deploy/make_certs.sh`` (``skyfix`` and ``blueos``), and each checking the shipped access control.
``skyfix run`` and ``skyfix replay`` are clients of the laptop's router (``fleet-client.json5``, loopback); a
subscriber on the companion's router must receive the service's fixes through both routers, and a late joiner
there must get the latest fix from the service's queryable; what the laptop may not publish (the vehicle's
MAVLink, a drone's fix) never reaches the companion, and a router without the team's certificate cannot join. The
deploy files are used as written, only their endpoints and key paths replaced."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
from pathlib import Path

import zenoh
from live_helpers import ROOT, free_port, stop, wait_for
from test_zenoh_security import ROUTER, deployed, replayed_through

ROUTER_ENDPOINTS = '["tls/192.168.2.2:7447", "tls/192.168.2.3:7447"]'
KEYS = "/etc/skyfix/tls/"


def _machine(
    team: Path, name: str, tls_port: int, local_port: int, connect: str
) -> tuple[Path, Path]:
    """Machine ``name``'s router and client configs in ``team/name`` (its keys there): the router listening on
    loopback (TLS ``tls_port``, its own clients ``local_port``) and connecting to ``connect`` (a JSON list)."""
    d = team / name
    router = deployed(
        "fleet-router.json5",
        d,
        {
            KEYS: f"{d}/",
            "tls/0.0.0.0:7447": f"tls/127.0.0.1:{tls_port}",
            "tcp/127.0.0.1:7448": f"tcp/127.0.0.1:{local_port}",
            ROUTER_ENDPOINTS: connect,
        },
    )
    client = deployed(
        "fleet-client.json5", d, {"tcp/127.0.0.1:7448": f"tcp/127.0.0.1:{local_port}"}
    )
    return router, client


def test_fixes_cross_two_routers_to_the_companion_and_late_joiners_get_the_latest(tmp_path):
    team = tmp_path / "team"
    subprocess.run(
        [str(ROOT / "deploy" / "make_certs.sh"), str(team), "skyfix=127.0.0.1", "blueos=127.0.0.1"],
        check=True,
        capture_output=True,
        timeout=60,
    )
    ports = [free_port(socket.SOCK_STREAM) for _ in range(4)]
    companion_router, companion_client = _machine(team, "blueos", ports[0], ports[1], "[]")
    laptop_router, laptop_client = _machine(
        team, "skyfix", ports[2], ports[3], f'["tls/127.0.0.1:{ports[0]}"]'
    )
    # a router of another team's (its own CA, the same file): it connects to the companion and cannot join
    subprocess.run(
        [str(ROOT / "deploy" / "make_certs.sh"), str(tmp_path / "other"), "skyfix=127.0.0.1"],
        check=True,
        capture_output=True,
        timeout=60,
    )
    stranger_router, stranger_client = _machine(
        tmp_path / "other", "skyfix", free_port(socket.SOCK_STREAM), free_port(socket.SOCK_STREAM),
        f'["tls/127.0.0.1:{ports[0]}"]',
    )  # fmt: skip
    routers = [
        subprocess.Popen(
            [sys.executable, "-c", ROUTER, str(cfg)], stdout=subprocess.PIPE, text=True
        )
        for cfg in (companion_router, laptop_router, stranger_router)
    ]
    procs = list(routers)
    fixes: list[dict] = []
    heard: list[str] = []  # keys the companion heard from the laptop's and the stranger's machines
    sub = uuv_side = late = None
    sessions: list = []
    try:
        assert [r.stdout.readline().strip() for r in routers] == ["ready"] * 3
        uuv_side = zenoh.open(zenoh.Config.from_file(str(companion_client)))
        sub = uuv_side.declare_subscriber(
            "skyfix/uuv/fix", lambda s: fixes.append(json.loads(s.payload.to_bytes()))
        )
        sessions.append(
            uuv_side.declare_subscriber(
                "skyfix/uuv/*/status", lambda s: heard.append(str(s.key_expr))
            )
        )
        sessions.append(
            uuv_side.declare_subscriber("mavlink/**", lambda s: heard.append(str(s.key_expr)))
        )
        sessions.append(
            uuv_side.declare_subscriber(
                "skyfix/uuv/*/drone/**", lambda s: heard.append(str(s.key_expr))
            )
        )
        # the laptop's processes publish what the companion takes from nobody but the vehicle (its MAVLink) or
        # drone a (its fix), and a status key the topside's identity may publish (the control)
        laptop, stranger = (
            zenoh.open(zenoh.Config.from_file(str(c))) for c in (laptop_client, stranger_client)
        )
        sessions += [laptop, stranger]
        wait_for(
            lambda: _put_until_heard(laptop, "laptop", heard),
            20,
            lambda: f"the laptop's status: {heard}",
        )
        service = replayed_through(tmp_path, laptop_client, procs)
        # the stranger's router has tried to join all along: its status, then the laptop's again
        _put_until_heard(stranger, "stranger", heard)
        wait_for(
            lambda: _put_until_heard(laptop, "laptop2", heard),
            20,
            lambda: f"the laptop's again: {heard}",
        )
        # a console joining at the companion after the flight: the service's latest fix, through both routers
        late = zenoh.open(zenoh.Config.from_file(str(companion_client)))
        replies = [r.ok for r in late.get("skyfix/uuv/fix", timeout=10.0) if r.ok is not None]
        stop(service)
        assert service.returncode == 0, (tmp_path / "run.log").read_text()[-3000:]
    finally:
        if sub is not None:
            sub.undeclare()
        for s in sessions:
            if isinstance(s, zenoh.Session):
                s.close()
            else:
                s.undeclare()
        for session in [s for s in (uuv_side, late) if s is not None]:
            session.close()
        for p in procs:
            stop(p, 5.0)
    ok = [f for f in fixes if f["status"] == "ok"]
    print(
        f"fleet: {len(fixes)} fixes at the companion's router, {len(ok)} ok; late joiner got {len(replies)} reply; "
        f"heard {sorted(set(heard))}"
    )
    tried = {"laptop", "laptop2", "stranger"}
    heard_here = {k for k in heard if not k.endswith("/status") or k.split("/")[2] in tried}
    assert heard_here == {"skyfix/uuv/laptop/status", "skyfix/uuv/laptop2/status"}, heard
    assert len(ok) >= 30, f"only {len(ok)} ok fixes of {len(fixes)} crossed the two routers"
    assert len(replies) == 1, replies
    latest = json.loads(replies[0].payload.to_bytes())
    assert latest["t"] == fixes[-1]["t"] and latest["frame"] == fixes[-1]["frame"], (
        latest,
        fixes[-1],
    )


def _put_until_heard(session: zenoh.Session, name: str, heard: list[str]) -> bool:
    """Put the forged keys and ``skyfix/uuv/NAME/status`` once more; whether the companion has heard the status."""
    session.put("mavlink/1/1/SCALED_PRESSURE2", b"{}")
    session.put("skyfix/uuv/rov1/drone/a/fix", b"{}")
    session.put(f"skyfix/uuv/{name}/status", b"{}")
    return f"skyfix/uuv/{name}/status" in heard

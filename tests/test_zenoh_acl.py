"""Nobody on the network is trusted by default: ``deploy/zenoh/peer.json5`` (field.toml's Zenoh) on loopback, with
real TLS sessions and Zenoh's real access control, the file as written with only its endpoints and key paths
replaced, and the team's identities (``skyfix``, ``operator``, ``drone-a``, ``blueos``) made here by
``deploy/make_certs.sh``, each machine's folder standing for its ``/etc/skyfix/tls/``. A peer without a certificate of the team's CA cannot connect; the operator's identity (or this
machine's loopback) commands ``skyfix run``, a drone's cannot; a fuser's source key is taken from its own drone
only; the UUV's ``mavlink/1/1/*`` reaches the depth from the vehicle's identity only. Without TLS beyond loopback
(or with the example password) ``skyfix run`` refuses to start.
"""

from __future__ import annotations

import json
import re
import socket
import subprocess
from pathlib import Path

import pytest
import zenoh
from blueos_bridge import to_json
from live_helpers import ROOT, free_port, skyfix, start, stop, wait_for
from pymavlink.dialects.v20 import ardupilotmega as mavlink2
from test_zenoh_security import deployed

from groundstation.runtime.zenoh_session import make_config, trust_problem

SESSION = ROOT / "sim_fixtures" / "bundled" / "nadir_hover"
IDENTITIES = ("skyfix", "operator", "drone-a", "blueos")


def team(d: Path) -> tuple[Path, int, dict[str, Path]]:
    """The team's keys (``make_certs.sh``; the service's certificate names 127.0.0.1), ``peer.json5`` listening on
    loopback (TLS, and plain TCP for this machine), and each identity's ``client.json5`` (plus ``none``: the client
    file without a certificate): the peer's config, its loopback TCP port, the clients' configs."""
    subprocess.run(
        [
            str(ROOT / "deploy" / "make_certs.sh"),
            str(d / "team"),
            "skyfix=127.0.0.1",
            *IDENTITIES[1:],
        ],
        check=True,
        capture_output=True,
        timeout=60,
    )
    tls, local = free_port(socket.SOCK_STREAM), free_port(socket.SOCK_STREAM)
    peer = deployed(
        "peer.json5",
        d,
        {
            "/etc/skyfix/tls/": f"{d}/team/skyfix/",
            "tls/0.0.0.0:7447": f"tls/127.0.0.1:{tls}",
            "tcp/127.0.0.1:7448": f"tcp/127.0.0.1:{local}",
        },
    )
    clients = {}
    for name in IDENTITIES:
        clients[name] = deployed(
            "client.json5",
            d / "team" / name,
            {
                "/etc/skyfix/tls/": f"{d}/team/{name}/",
                "tls/192.168.2.1:7447": f"tls/127.0.0.1:{tls}",
            },
        )
    clients["none"] = d / "no-cert.json5"
    clients["none"].write_text(
        re.sub(r".*connect_(private_key|certificate).*\n", "", clients["skyfix"].read_text())
    )
    return peer, local, clients


def open_as(config: Path) -> zenoh.Session:
    return zenoh.open(zenoh.Config.from_file(str(config)))


def console(command: str, config: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        skyfix(command, "--zenoh-config", str(config), "--timeout-s", "3"),
        capture_output=True,
        text=True,
        timeout=60,
        cwd=ROOT,
        check=False,
    )


def status_now(local: zenoh.Session) -> dict:
    """The service's status now (the ``status`` command over this machine's loopback)."""
    replies = [r.ok for r in local.get("skyfix/cmd/status", timeout=5.0) if r.ok is not None]
    assert len(replies) == 1, replies
    return json.loads(replies[0].payload.to_bytes())


def pressure(sequence: int) -> str:
    """ArduSub's SCALED_PRESSURE2 as BlueOS's mavlink-server publishes it (system 1, component 1)."""
    msg = mavlink2.MAVLink_scaled_pressure2_message(1000 * sequence, 1113.0, 0.0, 1500, 0)
    msg._header = mavlink2.MAVLink_header(msg.id, srcSystem=1, srcComponent=1, seq=sequence)
    return json.dumps(to_json(msg))


def test_only_the_operator_commands_and_only_the_vehicle_gives_the_depth(tmp_path):
    peer, local_port, clients = team(tmp_path)
    log = tmp_path / "run.log"
    service = start(
        skyfix(
            "run",
            "--calibration",
            str(SESSION / "session.toml"),
            "--zenoh-config",
            str(peer),
            "--mavlink",
            f"udpin:127.0.0.1:{free_port()}",
            "--video",
            f"udp://127.0.0.1:{free_port()}",
            "--gps-input",
            "none",
            "--depth-source",
            "blueos",
            "--duration-s",
            "120",
        ),
        log,
    )
    sessions: list[zenoh.Session] = []
    try:
        wait_for(
            lambda: "skyfix run: UAV" in log.read_text() or service.poll() is not None,
            30,
            "the service",
        )
        assert service.poll() is None, log.read_text()[-3000:]
        stranger = console("release", clients["none"])
        drone = console("release", clients["drone-a"])
        operator = console("release", clients["operator"])
        assert stranger.returncode != 0 and "Unable to connect" in stranger.stderr, stranger
        assert drone.returncode != 0 and "no skyfix service answered" in drone.stderr, drone
        assert (
            operator.returncode == 0
            and json.loads(operator.stdout)["target"]["state"] == "released"
        ), operator

        local = zenoh.open(make_config([f"tcp/127.0.0.1:{local_port}"], mode="client"))
        sessions.append(local)
        assert status_now(local)["control"] | {"prefix": None} == {
            "prefix": None,
            "answered": 1,
            "refused": 0,
        }

        forger, vehicle = open_as(clients["drone-a"]), open_as(clients["blueos"])
        sessions += [forger, vehicle]
        for n in range(3):
            forger.put("mavlink/1/1/SCALED_PRESSURE2", pressure(n))
        # after the forged ones on the same link: they were judged
        list(forger.get("skyfix/uuv/fix", timeout=5.0))
        vehicle.put("mavlink/1/1/SCALED_PRESSURE2", pressure(10))
        wait_for(
            lambda: status_now(local)["depth"]["received"] >= 1,
            15,
            "the vehicle's message at the depth",
        )
        depth = status_now(local)["depth"]
        print(
            f"commands: stranger {stranger.returncode}, drone {drone.returncode}, operator {operator.returncode}; "
            f"depth messages received {depth['received']} (3 forged, 1 the vehicle's)"
        )
        assert depth["received"] == 1, depth
    finally:
        for s in sessions:
            s.close()
        stop(service)
    assert service.returncode == 0, log.read_text()[-3000:]


def test_a_fusers_sources_come_from_their_own_drone_only(tmp_path):
    """A fuser's session with ``peer.json5``: ``skyfix/uuv/ID/drone/a/fix`` from ``drone-a`` only."""
    peer, _, clients = team(tmp_path)
    fuser = open_as(peer)
    got: list[tuple[str, str]] = []
    sub = fuser.declare_subscriber(
        "skyfix/uuv/*/drone/*/fix", lambda s: got.append((str(s.key_expr), s.payload.to_string()))
    )
    sessions = {
        name: open_as(clients[name]) for name in ("drone-a", "operator", "blueos", "skyfix")
    }
    try:
        for name, session in sessions.items():
            for drone in ("a", "b"):
                session.put(f"skyfix/uuv/rov1/drone/{drone}/fix", name)
        sessions["drone-a"].put("skyfix/uuv/rov1/drone/a/fix", "last")
        wait_for(
            lambda: ("skyfix/uuv/rov1/drone/a/fix", "last") in got,
            15,
            lambda: f"drone a's last fix: {got}",
        )
    finally:
        sub.undeclare()
        for s in [*sessions.values(), fuser]:
            s.close()
    print(f"fuser received {got}")
    assert got == [
        ("skyfix/uuv/rov1/drone/a/fix", "drone-a"),
        ("skyfix/uuv/rov1/drone/a/fix", "last"),
    ]


@pytest.mark.parametrize(
    "name",
    ["peer", "client", "tls", "router-tls", "vehicle-router", "fleet-router", "fleet-client"],
)
def test_shipped_configs_trust_nobody_by_default(name):
    assert (
        trust_problem(make_config(config_file=str(ROOT / "deploy" / "zenoh" / f"{name}.json5")))
        is None
    )


def test_shipped_access_control_is_one_and_the_same():
    """The service's peer and the routers check the same rules (the one list deploy/zenoh/README.md explains)."""
    acl = [
        make_config(config_file=str(ROOT / "deploy" / "zenoh" / f"{n}.json5")).get_json(
            "access_control"
        )
        for n in ("peer", "router-tls", "fleet-router")
    ]
    assert acl[0] == acl[1] == acl[2] and json.loads(acl[0])["default_permission"] == "deny"


@pytest.mark.parametrize(
    ("flags", "said"),
    [
        (
            ["--zenoh-connect", "tcp/192.168.2.2:7447"],
            "tcp/192.168.2.2:7447: plain tcp beyond this machine",
        ),
        (["--zenoh-listen", "tcp/0.0.0.0:7447"], "tcp/0.0.0.0:7447: plain tcp beyond this machine"),
        (
            ["--zenoh-config", str(ROOT / "deploy" / "zenoh" / "usrpwd.json5")],
            "the example 'CHANGE-ME'",
        ),
        (["--zenoh-listen", "tcp/127.0.0.1:7447", "--zenoh-multicast"], "multicast scouting"),
    ],
)
def test_run_refuses_zenoh_that_trusts_strangers(flags, said):
    """Refused at start, exit 2, one line naming the value; before any socket is opened (no traffic leaves)."""
    done = subprocess.run(
        skyfix(
            "run",
            "--calibration",
            str(SESSION / "session.toml"),
            "--mavlink",
            "udpin:127.0.0.1:9",
            "--video",
            "none",
            "--gps-input",
            "none",
            *flags,
        ),
        capture_output=True,
        text=True,
        timeout=60,
        cwd=ROOT,
        check=False,
    )
    assert (
        done.returncode == 2 and said in done.stderr and len(done.stderr.strip().splitlines()) == 1
    ), done.stderr

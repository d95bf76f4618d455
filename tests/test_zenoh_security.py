"""The secured Zenoh configs of ``deploy/zenoh/`` on loopback: mutual TLS, and user/password.

For each, the deploy files are used as written, only their paths, endpoints and password
replaced: a throwaway CA and certificates made with ``openssl`` here (or a random password and
its dictionary file), a router (a Python Zenoh session in router mode with ``router-*.json5``, its
own process), ``skyfix run`` and ``skyfix replay`` as clients with the client file (with TLS the replay, which
publishes the UUV's depth, holds the vehicle's certificate: the router's access control takes the depth from it
only), and a subscriber with that same file, which must receive the service's fixes. A client lacking the
credentials (no client certificate; a wrong or no password) is refused by the router.
"""

from __future__ import annotations

import json
import re
import secrets
import socket
import subprocess
import sys
from pathlib import Path

import pytest
import zenoh
from live_helpers import ROOT, free_port, skyfix, start, stop, wait_for

DEPLOY = ROOT / "deploy" / "zenoh"
SESSION = ROOT / "sim_fixtures" / "bundled" / "nadir_hover"

ROUTER = r"""
import sys, time, zenoh
s = zenoh.open(zenoh.Config.from_file(sys.argv[1]))
print("ready", flush=True)
try:
    while True:
        time.sleep(1)
except KeyboardInterrupt:
    pass
finally:
    s.close()
"""


def _openssl(*args: str, cwd: Path) -> None:
    subprocess.run(["openssl", *args], cwd=cwd, check=True, capture_output=True, timeout=60)


def make_certificates(d: Path, names: tuple[str, ...] = ("router", "skyfix")) -> None:
    """A CA, and a certificate it signed for each of ``names`` (its common name; P-256, valid for a day; each names
    127.0.0.1 and localhost, for a server's side and a client's)."""
    key = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:P-256", "-nodes"]
    _openssl(
        "req",
        "-x509",
        *key,
        "-keyout",
        "ca-key.pem",
        "-out",
        "ca.pem",
        "-days",
        "1",
        "-subj",
        "/CN=test CA",
        cwd=d,
    )
    for name in names:
        _openssl(
            "req",
            *key,
            "-keyout",
            f"{name}-key.pem",
            "-out",
            f"{name}.csr",
            "-subj",
            f"/CN={name}",
            cwd=d,
        )
        (d / f"{name}.ext").write_text(
            "subjectAltName=IP:127.0.0.1,DNS:localhost\nbasicConstraints=CA:FALSE\n"
            "extendedKeyUsage=serverAuth,clientAuth\n"
        )
        _openssl(
            "x509",
            "-req",
            "-in",
            f"{name}.csr",
            "-CA",
            "ca.pem",
            "-CAkey",
            "ca-key.pem",
            "-CAcreateserial",
            "-out",
            f"{name}-cert.pem",
            "-days",
            "1",
            "-extfile",
            f"{name}.ext",
            cwd=d,
        )


def deployed(name: str, out: Path, replace: dict[str, str]) -> Path:
    """``deploy/zenoh/NAME`` with the given replacements, each of which must occur in it."""
    text = (DEPLOY / name).read_text()
    for old, new in replace.items():
        assert old in text, f"{name} no longer contains {old!r}"
        text = text.replace(old, new)
    path = out / name
    path.write_text(text)
    return path


def setup_tls(d: Path, port: int) -> tuple[Path, Path, list[Path], Path]:
    make_certificates(d, ("router", "skyfix", "blueos"))
    ep = f"tls/127.0.0.1:{port}"
    paths = {"/etc/skyfix/tls/": f"{d}/"}
    client = deployed("tls.json5", d, {**paths, "tls/router.field.local:7447": ep})
    router = deployed("router-tls.json5", d, {**paths, "tls/0.0.0.0:7447": ep})
    no_cert = d / "no-cert.json5"
    no_cert.write_text(re.sub(r".*connect_(private_key|certificate).*\n", "", client.read_text()))
    assert "skyfix-cert.pem" not in no_cert.read_text()
    vehicle = d / "vehicle.json5"
    vehicle.write_text(client.read_text().replace(f"{d}/skyfix-", f"{d}/blueos-"))
    return client, router, [no_cert], vehicle


def setup_usrpwd(d: Path, port: int) -> tuple[Path, Path, list[Path], Path]:
    password = secrets.token_hex(12)
    users = d / "users.txt"
    users.write_text(f"skyfix:{password}\nblueos:{secrets.token_hex(12)}\n")
    ep = f"tcp/127.0.0.1:{port}"
    client = deployed("usrpwd.json5", d, {"CHANGE-ME": password, "tcp/192.168.2.2:7447": ep})
    router = deployed(
        "router-usrpwd.json5",
        d,
        {"/etc/skyfix/zenoh-users.txt": str(users), "tcp/0.0.0.0:7447": ep},
    )
    wrong = d / "wrong-password.json5"
    wrong.write_text(client.read_text().replace(password, "not-" + password))
    none = d / "no-password.json5"
    none.write_text(re.sub(r"  transport: \{.*?\n  \},\n", "", client.read_text(), flags=re.DOTALL))
    assert "password:" not in none.read_text()
    return client, router, [wrong, none], client


def replayed_through(
    tmp_path: Path, client: Path, procs: list, source: Path | None = None
) -> subprocess.Popen:
    """``skyfix run`` with the Zenoh config ``client``, and the bundled session replayed into it (its Zenoh side, the
    UUV's depth, through ``source``, default the same config) to its end; the service, still running (added to
    ``procs``)."""
    mav, video = free_port(), free_port()
    run_log = tmp_path / "run.log"
    service = start(
        skyfix(
            "run",
            "--calibration",
            str(SESSION / "session.toml"),
            "--zenoh-config",
            str(client),
            "--mavlink",
            f"udpin:127.0.0.1:{mav}",
            "--video",
            f"udp://127.0.0.1:{video}",
            "--video-latency-ms",
            "55",
            "--gps-input",
            "none",
            "--duration-s",
            "120",
        ),
        run_log,
    )
    procs.append(service)
    wait_for(
        lambda: "skyfix run: UAV" in run_log.read_text() or service.poll() is not None,
        30,
        "the service",
    )
    assert service.poll() is None, run_log.read_text()[-3000:]
    replay = start(
        skyfix(
            "replay",
            str(SESSION),
            "--zenoh-config",
            str(source or client),
            "--mavlink-out",
            f"udpout:127.0.0.1:{mav}",
            "--video-out",
            f"udp://127.0.0.1:{video}",
            "--uuv-listen",
            "",
            "--tail-s",
            "1",
        ),
        tmp_path / "replay.log",
    )
    procs.append(replay)
    assert replay.wait(90) == 0, (tmp_path / "replay.log").read_text()[-3000:]
    return service


@pytest.mark.parametrize("kind", ["tls", "usrpwd"])
def test_secured_zenoh_carries_fixes_and_refuses_strangers(tmp_path, kind):
    port = free_port(socket.SOCK_STREAM)
    client, router_cfg, lacking, vehicle = {"tls": setup_tls, "usrpwd": setup_usrpwd}[kind](
        tmp_path, port
    )
    router = subprocess.Popen(
        [sys.executable, "-c", ROUTER, str(router_cfg)], stdout=subprocess.PIPE, text=True
    )
    procs = [router]
    fixes: list[dict] = []
    sub = console = None
    try:
        assert router.stdout.readline().strip() == "ready"
        console = zenoh.open(zenoh.Config.from_file(str(client)))
        sub = console.declare_subscriber(
            "skyfix/uuv/fix", lambda s: fixes.append(json.loads(s.payload.to_bytes()))
        )
        for cfg in lacking:
            with pytest.raises(zenoh.ZError, match="Unable to connect"):
                zenoh.open(zenoh.Config.from_file(str(cfg)))
        service = replayed_through(tmp_path, client, procs, vehicle)
        stop(service)
        assert service.returncode == 0, (tmp_path / "run.log").read_text()[-3000:]
    finally:
        if sub is not None:
            sub.undeclare()
        if console is not None:
            console.close()
        for p in procs:
            stop(p, 5.0)
    ok = [f for f in fixes if f["status"] == "ok"]
    print(f"{kind}: {len(fixes)} fixes over the secured router, {len(ok)} ok")
    assert len(ok) >= 30, f"only {len(ok)} ok fixes of {len(fixes)} reached the subscriber"

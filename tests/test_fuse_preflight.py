"""``skyfix fuse`` checks at start what ``skyfix run`` checks (groundstation.live.preflight): a Zenoh that would let
strangers feed the fuser, credentials others may read, a GPS_INPUT string of no known form are each refused before
anything is opened, exit 2 and one line naming the value; ``--zenoh-insecure`` allows plain TCP on a network of the
team's own, and without ``--zenoh-listen`` the fuser listens on loopback only."""

from __future__ import annotations

import json
import subprocess

import pytest
from live_helpers import ROOT, free_port, skyfix

DEPLOY = ROOT / "deploy" / "zenoh"


def fuse(*extra: str, stats=None) -> subprocess.CompletedProcess:
    return subprocess.run(
        skyfix("fuse", "--uuv", "rov1", "--source", "a", *extra, "--duration-s", "1",
               *(["--stats", str(stats)] if stats else [])),
        check=False, capture_output=True, text=True, timeout=60, cwd=ROOT,
    )  # fmt: skip


def _key_file(tmp_path, mode: int):
    path = tmp_path / "gps.key"
    path.write_text("ab" * 32)
    path.chmod(mode)
    return str(path)


def _tls_config(tmp_path, key_mode: int) -> str:
    """client.json5 with its key paths in ``tmp_path`` (files that exist; the private key of ``key_mode``)."""
    for name in ("ca.pem", "skyfix-cert.pem", "skyfix-key.pem"):
        (tmp_path / name).write_text("not checked here\n")
        (tmp_path / name).chmod(0o644)
    (tmp_path / "skyfix-key.pem").chmod(key_mode)
    text = (DEPLOY / "client.json5").read_text().replace("/etc/skyfix/tls/", f"{tmp_path}/")
    (tmp_path / "client.json5").write_text(text)
    return str(tmp_path / "client.json5")


@pytest.mark.parametrize(
    ("extra", "said"),
    [
        (["--zenoh-connect", "tcp/192.168.2.2:7447"], "--zenoh-connect = 'tcp/192.168.2.2:7447'"),
        (["--zenoh-listen", "tcp/0.0.0.0:7447"], "plain tcp beyond this machine"),
        (["--zenoh-multicast"], "multicast scouting"),
        (["--zenoh-config", str(DEPLOY / "usrpwd.json5")], "the example 'CHANGE-ME'"),
        (["--zenoh-config", "/no/such.json5"], "--zenoh-config = '/no/such.json5': no such file"),
        (["--gps-input", "udpin:nowhere"], "--gps-input = 'udpin:nowhere'"),
        (["--gps-input", "htp://x"], "unknown scheme htp:"),
        ("key 0644", "others may read it (mode 0644)"),
        ("tls key 0644", "skyfix-key.pem"),
    ],
)
def test_fuse_refuses_at_start_in_one_line(tmp_path, extra, said):
    if extra == "key 0644":
        extra = [
            "--gps-input",
            "udpout:127.0.0.1:9",
            "--gps-input-signing-key",
            _key_file(tmp_path, 0o644),
        ]
    elif extra == "tls key 0644":
        extra = ["--zenoh-config", _tls_config(tmp_path, 0o644)]
    done = fuse(*extra)
    assert (
        done.returncode == 2 and said in done.stderr and len(done.stderr.strip().splitlines()) == 1
    ), done.stderr


def test_fuse_starts_with_what_it_may_trust(tmp_path):
    """The same values made safe: loopback only by default, a private signing key, and plain TCP beyond loopback
    when told the network is the team's own; each runs its second and stops cleanly."""
    port = free_port()
    for extra in (
        [],
        [
            "--gps-input",
            f"udpout:127.0.0.1:{port}",
            "--gps-input-signing-key",
            _key_file(tmp_path, 0o600),
        ],
        ["--zenoh-listen", f"tcp/0.0.0.0:{free_port()}", "--zenoh-insecure"],
    ):
        stats = tmp_path / "stats.json"
        done = fuse(*extra, stats=stats)
        assert done.returncode == 0, done.stderr[-2000:]
        assert json.loads(stats.read_text())["fusion"] is not None

"""The CLI as a new user meets it: a wrong output path, a busy port, a replay nobody answered.

Each case is one line on stderr naming the option and the offending value, and an exit code that says so,
found before any long work is done."""

from __future__ import annotations

import socket
import subprocess
import sys
from contextlib import contextmanager
from pathlib import Path

import pytest
from live_helpers import ROOT, free_port

from groundstation.cli import main

BUNDLED = ROOT / "sim_fixtures" / "bundled"


def _errors(capsys) -> list[str]:
    return [ln for ln in capsys.readouterr().err.splitlines() if "error" in ln]


@pytest.mark.parametrize("command", [["process", str(BUNDLED / "oblique_2m"), "--use-track"],
                                     ["evaluate", str(BUNDLED / "oblique_2m"), "--use-track"],
                                     ["sim", str(ROOT / "sim_fixtures" / "scenarios" / "nadir_hover.toml"),
                                      "--no-video"]])
def test_out_naming_an_existing_file(tmp_path, capsys, command):
    target = tmp_path / "positions"
    target.write_text("not a directory\n")
    assert main([*command, "--out", str(target)]) == 2
    lines = _errors(capsys)
    assert len(lines) == 1 and f"--out = '{target}': exists and is not a directory" in lines[0]
    assert target.read_text() == "not a directory\n"  # nothing written over it


def test_record_naming_a_file(tmp_path, capsys):
    target = tmp_path / "rec"
    target.write_text("x")
    argv = ["run", "--calibration", str(BUNDLED / "nadir_hover" / "session.toml"), "--mavlink",
            f"udpin:127.0.0.1:{free_port()}", "--record", str(target), "--duration-s", "5", "--no-ui"]
    assert main(argv) == 2
    lines = _errors(capsys)
    assert len(lines) == 1 and lines[0] == f"skyfix run: error: --record {target}: exists and is not a directory"


@contextmanager
def _busy_tcp_port():
    """A loopback TCP port another program (this test) listens on."""
    busy = socket.socket()
    busy.bind(("127.0.0.1", 0))
    busy.listen()
    try:
        yield busy.getsockname()[1]
    finally:
        busy.close()


def _run_with(*options: str) -> int:
    return main(["run", "--calibration", str(BUNDLED / "nadir_hover" / "session.toml"), "--mavlink",
                 f"udpin:127.0.0.1:{free_port()}", "--duration-s", "5", *options])


def test_a_zenoh_port_in_use_is_one_plain_line(capsys):
    with _busy_tcp_port() as port:
        assert _run_with("--zenoh-listen", f"tcp/127.0.0.1:{port}", "--no-ui") == 2
    lines = _errors(capsys)
    assert len(lines) == 1 and f"Zenoh (listen tcp/127.0.0.1:{port})" in lines[0]
    assert "Address already in use" in lines[0] and ".rs:" not in lines[0] and "cargo" not in lines[0]


def test_replay_that_no_service_answered_exits_1(tmp_path):
    """Nothing runs on the other side: the replay streams the session, gets no GPS_INPUT back and says so."""
    out = subprocess.run(
        [sys.executable, "-m", "groundstation.cli", "replay", str(BUNDLED / "nadir_hover"), "--no-video",
         "--mavlink-out", f"udpout:127.0.0.1:{free_port()}", "--uuv-listen", f"udpin:127.0.0.1:{free_port()}",
         "--uuv-log", str(tmp_path / "uuv.jsonl"), "--lead-s", "0.2", "--tail-s", "0.2", "--duration-s", "2"],
        check=False, capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert out.returncode == 1, out.stderr[-2000:]
    assert "no GPS_INPUT came back on udpin:127.0.0.1:" in out.stderr
    assert Path(tmp_path / "uuv.jsonl").exists()


def test_a_web_page_port_in_use_is_one_line_naming_ui(capsys):
    with _busy_tcp_port() as port:
        assert _run_with("--ui", f"127.0.0.1:{port}") == 2
    lines = _errors(capsys)
    assert lines == [(f"skyfix run: error: --ui 127.0.0.1:{port}: port {port} is already in use (another skyfix "
                     "run?); choose another with --ui HOST:PORT, or --no-ui")], lines

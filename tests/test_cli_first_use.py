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


@pytest.mark.parametrize(
    "command",
    [
        ["process", str(BUNDLED / "oblique_2m"), "--use-track"],
        ["evaluate", str(BUNDLED / "oblique_2m"), "--use-track"],
        ["sim", str(ROOT / "sim_fixtures" / "scenarios" / "nadir_hover.toml"), "--no-video"],
    ],
)
def test_out_naming_an_existing_file(tmp_path, capsys, command):
    target = tmp_path / "positions"
    target.write_text("not a directory\n")
    assert main([*command, "--out", str(target)]) == 2
    lines = _errors(capsys)
    assert len(lines) == 1 and f"--out = '{target}': exists and is not a directory" in lines[0]
    assert target.read_text() == "not a directory\n"  # nothing written over it


@pytest.mark.parametrize("command", ["process", "evaluate"])
def test_a_failed_command_leaves_no_folder_it_made(tmp_path, capsys, command):
    """The folders --out named and the command made are gone when it failed before writing in them; a folder that
    was there stays."""
    not_a_session = tmp_path / "empty"
    not_a_session.mkdir()
    kept = tmp_path / "kept"
    kept.mkdir()
    assert main([command, str(not_a_session), "--out", str(tmp_path / "new" / "out")]) == 2
    assert main([command, str(not_a_session), "--out", str(kept)]) == 2
    assert not (tmp_path / "new").exists() and kept.is_dir()
    assert len(_errors(capsys)) == 2


def test_record_naming_a_file(tmp_path, capsys):
    target = tmp_path / "rec"
    target.write_text("x")
    argv = [
        "run",
        "--calibration",
        str(BUNDLED / "nadir_hover" / "session.toml"),
        "--mavlink",
        f"udpin:127.0.0.1:{free_port()}",
        "--video",
        "none",
        "--gps-input",
        "none",
        "--zenoh-listen",
        "tcp/127.0.0.1:0",
        "--record",
        str(target),
        "--duration-s",
        "5",
        "--no-ui",
    ]
    assert main(argv) == 2
    lines = _errors(capsys)
    assert (
        len(lines) == 1
        and lines[0] == f"skyfix run: error: --record {target}: exists and is not a directory"
    )


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
    return main(
        [
            "run",
            "--calibration",
            str(BUNDLED / "nadir_hover" / "session.toml"),
            "--mavlink",
            f"udpin:127.0.0.1:{free_port()}",
            "--video",
            "none",
            "--gps-input",
            "none",
            "--duration-s",
            "5",
            *options,
        ]
    )


def test_a_zenoh_port_in_use_is_one_plain_line(capsys):
    with _busy_tcp_port() as port:
        assert _run_with("--zenoh-listen", f"tcp/127.0.0.1:{port}", "--no-ui") == 2
    lines = _errors(capsys)
    assert len(lines) == 1 and f"Zenoh (listen tcp/127.0.0.1:{port})" in lines[0]
    assert (
        "Address already in use" in lines[0] and ".rs:" not in lines[0] and "cargo" not in lines[0]
    )


def test_replay_that_no_service_answered_exits_1(tmp_path):
    """Nothing runs on the other side: the replay streams the session, gets no GPS_INPUT back and says so."""
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "groundstation.cli",
            "replay",
            str(BUNDLED / "nadir_hover"),
            "--no-video",
            "--mavlink-out",
            f"udpout:127.0.0.1:{free_port()}",
            "--uuv-listen",
            f"udpin:127.0.0.1:{free_port()}",
            "--uuv-log",
            str(tmp_path / "uuv.jsonl"),
            "--lead-s",
            "0.2",
            "--tail-s",
            "0.2",
            "--duration-s",
            "2",
        ],
        check=False,
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=60,
    )
    assert out.returncode == 1, out.stderr[-2000:]
    assert "no GPS_INPUT came back on udpin:127.0.0.1:" in out.stderr
    assert Path(tmp_path / "uuv.jsonl").exists()


def test_a_web_page_port_in_use_is_one_line_naming_ui(capsys):
    with _busy_tcp_port() as port:
        assert _run_with("--ui", f"127.0.0.1:{port}", "--zenoh-listen", "tcp/127.0.0.1:0") == 2
    lines = _errors(capsys)
    assert lines == [
        (
            f"skyfix run: error: --ui 127.0.0.1:{port}: port {port} is already in use (another skyfix "
            "run?); choose another with --ui HOST:PORT, or --no-ui"
        )
    ], lines


DEPLOY_CAL = ROOT / "deploy" / "calibration.toml"


@pytest.mark.parametrize(
    ("options", "line"),
    [
        (
            ["--video", "/no/such/file.mp4", "--gps-input", "none"],
            "options: --video = '/no/such/file.mp4': no such file",
        ),
        (
            ["--video", "htp://192.168.2.2:5600/x", "--gps-input", "none"],
            "options: --video = 'htp://192.168.2.2:5600/x': unknown scheme htp:// (udp, rtp, rtsp, a file, or one FFmpeg",
        ),
        (
            ["--gps-input", "udpout:192.168.2.2:14660"],
            "options: --video = None: missing: name it, or say none",
        ),
        (
            ["--video", "rtp://0.0.0.0:5600?codec=h264"],
            "options: --gps-input = None: missing: name it, or say none",
        ),
        (
            ["--video", "none", "--gps-input", "udpot:192.168.2.2:14660"],
            "MAVLink 'udpot:192.168.2.2:14660': cannot open: unknown scheme udpot: (expected tcp:, ",
        ),
    ],
)
def test_a_start_up_mistake_is_one_line_and_exit_2(options, line):
    """Refused before anything starts: exit 2 and one line naming the value (bench/restart.py times it)."""
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "groundstation.cli",
            "run",
            "--calibration",
            str(DEPLOY_CAL),
            "--no-ui",
            *options,
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=60,
        check=False,
    )
    assert out.returncode == 2 and out.stdout == ""
    assert len(out.stderr.splitlines()) == 1 and out.stderr.startswith(
        f"skyfix run: error: {line}"
    ), out.stderr


def _check(config: Path, *options: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [
            sys.executable,
            "-m",
            "groundstation.cli",
            "run",
            "--config",
            str(config),
            "--check",
            *options,
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=60,
        check=False,
    )


def test_check_validates_the_shipped_configuration_and_starts_nothing(tmp_path):
    from groundstation.testing.supervisor import field_config

    config, values = field_config(tmp_path, free_port())
    out = _check(config)
    assert out.returncode == 0 and out.stderr == "", out.stderr
    assert (
        out.stdout.startswith(
            f"skyfix run --check: ok: calibration {values['calibration']} (1920x1080, "
            "gimbal_device); video rtp://127.0.0.1:"
        )
        and len(out.stdout.splitlines()) == 1
    )
    mav, zenoh = (
        int(values["mavlink"].rsplit(":", 1)[1]),
        int(values["zenoh_listen"][0].rsplit(":", 1)[1]),
    )
    assert f"recordings {tmp_path / 'recordings'}" in out.stdout and f"udp {mav}" in out.stdout
    assert f"tcp {zenoh}" in out.stdout
    assert not (tmp_path / "recordings").exists()  # nothing started, nothing made
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as busy:
        busy.bind(("127.0.0.1", mav))
        out = _check(config)
    assert out.returncode == 2 and out.stderr.splitlines() == [
        f"skyfix run: error: {config}: mavlink = '{values['mavlink']}': port {mav}: in use by another program"
    ]


def test_check_refuses_a_signing_key_others_may_read(tmp_path):
    from groundstation.testing.supervisor import field_config

    config, _ = field_config(tmp_path, free_port())
    key = tmp_path / "gps_input.key"
    key.write_text("ab" * 32 + "\n")
    key.chmod(0o644)
    out = _check(config, "--gps-input-signing-key", str(key))
    assert out.returncode == 2 and out.stderr.splitlines() == [
        f"skyfix run: error: options: --gps-input-signing-key = '{key}': others may read it (mode 0644): chmod 600"
    ]
    key.chmod(0o600)
    assert _check(config, "--gps-input-signing-key", str(key)).returncode == 0


def test_status_finds_a_local_service_by_default(tmp_path):
    """``skyfix status`` as the README shows it, with no endpoint: it finds ``skyfix run`` started with none."""
    from live_helpers import start, stop, wait_until

    from groundstation.runtime.zenoh_session import LOCAL_ENDPOINT

    host, port = LOCAL_ENDPOINT.removeprefix("tcp/").rsplit(":", 1)
    with socket.socket() as probe:
        if probe.connect_ex((host, int(port))) == 0:
            pytest.skip(f"something listens on {LOCAL_ENDPOINT} already")
    log = tmp_path / "run.log"
    service = start(
        [
            sys.executable,
            "-m",
            "groundstation.cli",
            "run",
            "--calibration",
            str(DEPLOY_CAL),
            "--mavlink",
            f"udpin:127.0.0.1:{free_port()}",
            "--video",
            "none",
            "--gps-input",
            "none",
            "--no-ui",
            "--duration-s",
            "120",
        ],
        log,
    )
    try:
        replies: list[subprocess.CompletedProcess] = []

        def answered() -> bool:  # or the service ended
            if service.poll() is not None:
                return True
            replies.append(
                subprocess.run(
                    [sys.executable, "-m", "groundstation.cli", "status"],
                    capture_output=True,
                    text=True,
                    cwd=ROOT,
                    timeout=60,
                    check=False,
                )
            )
            return replies[-1].returncode == 0

        assert wait_until(answered, 90, poll_s=0.5), replies[-1].stderr
        assert service.poll() is None, log.read_text()[-2000:]
        assert "target awaiting_target" in replies[-1].stdout
    finally:
        stop(service)

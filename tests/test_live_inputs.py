"""Silent inputs are named early and again; ``--require-inputs`` turns them into exit 2.

``skyfix run`` with nothing on the other end of its links: no MAVLink on its UDP port, no depth
publisher, a video URL nobody streams to, no Zenoh peer. Within a few seconds each is one log line,
the status names it, a summary line follows every 10 s, and the service keeps running unless told
to require its inputs."""

from __future__ import annotations

import json
import re
import socket
import subprocess

from live_helpers import ROOT, free_port, skyfix

CAL = ROOT / "sim_fixtures" / "bundled" / "nadir_hover" / "session.toml"


def _run(tmp_path, *extra: str, timeout_s: float = 60.0):
    mav, video = free_port(), free_port()
    zenoh = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    cmd = skyfix(
        "run",
        "--calibration",
        str(CAL),
        "--mavlink",
        f"udpin:127.0.0.1:{mav}",
        "--video",
        f"udp://127.0.0.1:{video}",
        "--zenoh-listen",
        zenoh,
        "--stats",
        str(tmp_path / "s.json"),
        "--gps-input",
        "none",
        *extra,
    )
    out = subprocess.run(
        cmd, check=False, capture_output=True, text=True, cwd=ROOT, timeout=timeout_s
    )
    return out, mav, video


def test_every_silent_input_is_named_and_the_service_keeps_running(tmp_path):
    out, mav, video = _run(tmp_path, "--duration-s", "12")
    log = out.stdout + out.stderr
    assert out.returncode == 0, log[-3000:]
    for line in (
        f"UAV MAVLink: nothing received on udpin:127.0.0.1:{mav}",
        "depth: nothing received on Zenoh key uuv/depth",
        f"video: no frame from udp://127.0.0.1:{video}",
        "Zenoh: no peer or router connected",
    ):
        assert line in log, line
    assert re.search(
        r"skyfix\.inputs INFO: [\d.]+ fps; no frames; no fix yet; UAV never; depth never; video never",
        log,
    ), log[-2000:]
    problems = json.loads((tmp_path / "s.json").read_text())["problems"]
    assert set(problems) == {"uav", "depth", "video", "zenoh"}


def test_require_inputs_stops_with_one_line_and_exit_2(tmp_path):
    out, mav, _ = _run(tmp_path, "--require-inputs", "--duration-s", "40")
    assert out.returncode == 2, (out.stdout + out.stderr)[-3000:]
    errors = [ln for ln in out.stderr.splitlines() if ln.startswith("skyfix run: error:")]
    assert len(errors) == 1
    assert f"UAV MAVLink: nothing received on udpin:127.0.0.1:{mav}" in errors[0]
    assert (
        "depth: nothing received" in errors[0]
        and "video: no frame" in errors[0]
        and "--require-inputs" in errors[0]
    )


def test_require_inputs_is_content_with_a_running_session(tmp_path):
    """With every input flowing (a replayed session), --require-inputs does not stop the service."""
    from live_helpers import read_jsonl, start, stop, wait_for

    mav, video, uuv = free_port(), free_port(), free_port()
    zenoh = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    session = ROOT / "sim_fixtures" / "bundled" / "nadir_hover"
    run = start(
        skyfix(
            "run",
            "--calibration",
            str(CAL),
            "--mavlink",
            f"udpin:127.0.0.1:{mav}",
            "--video",
            f"udp://127.0.0.1:{video}",
            "--video-latency-ms",
            "55",
            "--zenoh-listen",
            zenoh,
            "--gps-input",
            f"udpout:127.0.0.1:{uuv}",
            "--require-inputs",
            "--duration-s",
            "20",
        ),
        tmp_path / "run.log",
    )
    replay = start(
        skyfix(
            "replay",
            str(session),
            "--mavlink-out",
            f"udpout:127.0.0.1:{mav}",
            "--video-out",
            f"udp://127.0.0.1:{video}",
            "--zenoh-connect",
            zenoh,
            "--uuv-listen",
            f"udpin:127.0.0.1:{uuv}",
            "--uuv-log",
            str(tmp_path / "uuv.jsonl"),
            "--lead-s",
            "0.5",
        ),
        tmp_path / "replay.log",
    )
    try:
        wait_for(
            lambda: len(read_jsonl(tmp_path / "uuv.jsonl")) > 20,
            30,
            "GPS_INPUT from the running service",
        )
        assert run.poll() is None, (tmp_path / "run.log").read_text()[-3000:]
    finally:
        stop(replay)
        stop(run)
    assert run.returncode == 0, (tmp_path / "run.log").read_text()[-3000:]

"""What the live benchmarks share: loopback ports, /proc samples, and ``skyfix run`` fed by ``skyfix replay``.

:class:`ServiceRun` starts ``skyfix run`` on loopback (UAV MAVLink on UDP, video as MPEG-TS on
UDP, Zenoh listening on TCP, GPS_INPUT to a UDP port that ``skyfix replay`` listens on and logs),
and :meth:`ServiceRun.replay` re-streams a session into it. :func:`proc_sample` reads a process's
CPU time, resident memory, open file descriptors and threads from /proc.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Self

ROOT = Path(__file__).resolve().parents[1]
CLK_TCK = os.sysconf("SC_CLK_TCK")


def free_port(kind: int = socket.SOCK_DGRAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def proc_sample(pid: int) -> dict:
    """CPU seconds so far, resident memory (MB), open fds and threads of a process."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    status = dict(
        line.split(":", 1)
        for line in Path(f"/proc/{pid}/status").read_text().splitlines()
        if ":" in line
    )
    return {
        "t": time.time(),
        "cpu_s": (int(fields[11]) + int(fields[12])) / CLK_TCK,
        "rss_mb": int(status["VmRSS"].split()[0]) / 1024.0,
        "fds": len(os.listdir(f"/proc/{pid}/fd")),
        "threads": int(status["Threads"]),
    }


def _wait(pred, timeout_s: float, what: str) -> None:
    end = time.time() + timeout_s
    while not pred():
        if time.time() > end:
            raise TimeoutError(f"timed out after {timeout_s} s waiting for {what}")
        time.sleep(0.1)


class ServiceRun:
    """``skyfix run`` on loopback ports of its own; ``with`` stops it (SIGINT) and leaves ``final`` (its --stats)."""

    def __init__(self, session: Path, work: Path, *extra: str, video_latency_ms: float = 55.0):
        self.session, self.work = session, work
        work.mkdir(parents=True, exist_ok=True)
        self.mav, self.video, self.uuv = free_port(), free_port(), free_port()
        self.zenoh = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
        self.stats, self.log, self.uuv_log = (
            work / "stats.json",
            work / "run.log",
            work / "uuv.jsonl",
        )
        for f in (self.stats, self.uuv_log):
            f.unlink(missing_ok=True)
        self.cmd = [
            sys.executable,
            "-m",
            "groundstation.cli",
            "run",
            "--calibration",
            str(session / "session.toml"),
            "--mavlink",
            f"udpin:127.0.0.1:{self.mav}",
            "--video",
            f"udp://127.0.0.1:{self.video}",
            "--video-latency-ms",
            str(video_latency_ms),
            "--zenoh-listen",
            self.zenoh,
            "--no-ui",
            "--gps-input",
            f"udpout:127.0.0.1:{self.uuv}",
            "--stats",
            str(self.stats),
            *extra,
        ]
        self.proc: subprocess.Popen | None = None
        self.final: dict | None = None
        self._replays = 0

    def __enter__(self) -> Self:
        with open(self.log, "w") as f:
            self.proc = subprocess.Popen(
                self.cmd,
                stdout=f,
                stderr=subprocess.STDOUT,
                cwd=ROOT,
                env=dict(os.environ, PYTHONUNBUFFERED="1"),
            )
        _wait(
            lambda: "skyfix run: UAV" in self.log.read_text() or self.proc.poll() is not None,
            60,
            "skyfix run",
        )
        if self.proc.poll() is not None:
            raise RuntimeError("skyfix run exited:\n" + self.log.read_text()[-3000:])
        return self

    def replay(self, *extra: str) -> tuple[subprocess.Popen, Path]:
        """Start ``skyfix replay`` of the session into the service; its process and log."""
        self._replays += 1
        log = self.work / f"replay{self._replays}.log"
        cmd = [
            sys.executable,
            "-m",
            "groundstation.cli",
            "replay",
            str(self.session),
            "--mavlink-out",
            f"udpout:127.0.0.1:{self.mav}",
            "--video-out",
            f"udp://127.0.0.1:{self.video}",
            "--zenoh-connect",
            self.zenoh,
            "--uuv-listen",
            f"udpin:127.0.0.1:{self.uuv}",
            "--uuv-log",
            str(self.uuv_log),
            *extra,
        ]
        with open(log, "w") as f:
            return subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT, cwd=ROOT), log

    @staticmethod
    def shift_s(replay_log: Path, timeout_s: float = 30.0) -> float:
        """The time shift (UNIX − session seconds) a replay printed first."""

        def first():
            lines = [ln for ln in replay_log.read_text().splitlines() if ln.startswith("{")]
            return json.loads(lines[0]) if lines else None

        _wait(lambda: first() is not None, timeout_s, f"{replay_log}'s start line")
        return first()["shift_s"]

    def gps_input(self) -> list[dict]:
        if not self.uuv_log.exists():
            return []
        return [json.loads(ln) for ln in self.uuv_log.read_text().splitlines() if ln.strip()]

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def __exit__(self, *exc) -> None:
        if self.alive():
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if self.stats.exists():
            self.final = json.loads(self.stats.read_text())

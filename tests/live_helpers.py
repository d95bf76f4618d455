"""Shared helpers of the live tests: free loopback ports, the skyfix command, subprocess cleanup."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def free_port(kind: int = socket.SOCK_DGRAM) -> int:
    """A port on 127.0.0.1 that is free right now (UDP or TCP)."""
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def skyfix(*args: str) -> list[str]:
    """The command line of ``skyfix <args>``, as the installed console script runs it."""
    return [sys.executable, "-m", "groundstation.cli", *args]


def start(cmd: list[str], log: Path) -> subprocess.Popen:
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    with open(log, "w") as f:
        return subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT, cwd=ROOT, env=env)


def stop(proc: subprocess.Popen, timeout_s: float = 10.0) -> None:
    """SIGINT, then SIGKILL if it does not exit in time."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def read_jsonl(path: Path) -> list[dict]:
    if not path.exists():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def wait_for(predicate, timeout_s: float, what: str) -> None:
    end = time.time() + timeout_s
    while time.time() < end:
        if predicate():
            return
        time.sleep(0.1)
    raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")


# An independent Zenoh subscriber (run in its own process): every sample on the key
# expression, as one JSON line with its key, encoding, Zenoh timestamp and payload.
SUBSCRIBER = r"""
import json, sys, time, zenoh
endpoint, key, out_path = sys.argv[1:4]
conf = zenoh.Config()
conf.insert_json5("mode", '"peer"')
conf.insert_json5("scouting/multicast/enabled", "false")
conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
session = zenoh.open(conf)
out = open(out_path, "a")
def on_sample(s):
    rec = {"key": str(s.key_expr), "encoding": str(s.encoding), "timestamp": s.timestamp is not None,
           "t_recv": time.time(), "payload": s.payload.to_string()}
    out.write(json.dumps(rec) + "\n")
    out.flush()
sub = session.declare_subscriber(key, on_sample)
try:
    while True:
        time.sleep(0.2)
except KeyboardInterrupt:
    pass
finally:
    sub.undeclare()
    session.close()
"""


def replay_shift(log: Path, timeout_s: float = 15.0) -> float:
    """The time shift ``skyfix replay`` printed first (UNIX s − session s), read from its log."""
    def first_json() -> dict | None:
        for line in log.read_text().splitlines() if log.exists() else ():
            if line.startswith("{"):
                return json.loads(line)
        return None

    wait_for(lambda: first_json() is not None, timeout_s, f"the replay's start line in {log}")
    return first_json()["shift_s"]


def truth_errors_m(session: Path, t_session, lat, lon):
    """Horizontal distance (m) of each position to ``truth.csv`` interpolated at its session time (s)."""
    import numpy as np

    from localizer.geodesy import horizontal_error_m

    truth = np.genfromtxt(session / "truth.csv", delimiter=",", names=True)
    return horizontal_error_m(np.asarray(lat), np.asarray(lon), np.interp(t_session, truth["t"], truth["lat"]),
                              np.interp(t_session, truth["t"], truth["lon"]))

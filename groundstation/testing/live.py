"""Live-service harnesses for the tests and the benches: free loopback ports, a GPS_INPUT endpoint, the skyfix
command, subprocess start and stop, waiting on conditions, an independent Zenoh subscriber, the truth's errors.

They run from a checkout: :data:`ROOT` is the checkout's top folder (the subprocesses' working folder)."""

from __future__ import annotations

import asyncio
import json
import os
import random
import select
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def free_port(kind: int = socket.SOCK_DGRAM) -> int:
    """A port on 127.0.0.1 that is free right now (UDP or TCP), below the kernel's ephemeral range: a port from
    that range (``bind(0)``) may be taken before the service binds it, as the local end of any outgoing
    connection (the service's Zenoh listener refused "Address already in use" once, with two busy processes
    beside the test and a subscriber retrying to connect to it)."""
    low = int(Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()[0])
    for _ in range(200):
        port = random.randrange(10_000, low)
        with socket.socket(socket.AF_INET, kind) as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                continue
            return port
    raise RuntimeError(f"no free port between 10000 and {low}")


class GpsInputEndpoint:
    """A UUV autopilot's MAVLink endpoint on loopback (skyfix's own ``udpin:`` transport, pymavlink's parser): every
    GPS_INPUT it gets, in ``received`` as (t, fields), ``t`` the time the kernel received the datagram (UNIX s). The
    autopilot reads its port at once; this test process, on a loaded machine, may read it hundreds of ms late (a
    thread waiting for the interpreter): the kernel's time is the one the autopilot would see."""

    def __init__(self, port: int = 0):
        from groundstation.mavlink.ingest import mavutil
        from groundstation.mavlink.transport import open_transport

        self.transport = open_transport(f"udpin:127.0.0.1:{port}")
        assert self.transport.kernel_times, (
            "no kernel receive times on this machine's UDP sockets (SO_TIMESTAMPNS)"
        )
        self.port = self.transport.sock.getsockname()[1]
        self.received: list[tuple[float, dict]] = []
        self._mav = mavutil().mavlink.MAVLink(None)
        self._mav.robust_parsing = True
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._listen, daemon=True)
        self._thread.start()

    def _listen(self) -> None:
        while not self._stop.is_set():
            if not select.select(self.transport.filenos(), [], [], 0.2)[0]:
                continue
            data = self.transport.read()
            for msg in self._mav.parse_buffer(data) or []:
                if msg.get_type() == "GPS_INPUT":
                    self.received.append((self.transport.t_received, msg.to_dict()))

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5)
        self.transport.close()


def skyfix(*args: str) -> list[str]:
    """The command line of ``skyfix <args>``, as the installed console script runs it.

    A ``run`` without ``--ui``/``--no-ui`` serves its web page on a free port (``127.0.0.1:0``): the default
    8080 would collide between runs on one machine; without ``--zenoh-listen`` (or a file that may name it) it
    listens for Zenoh on a free port too, not on the default ``tcp/127.0.0.1:7448``.
    """
    if args and args[0] == "run" and "--ui" not in args and "--no-ui" not in args:
        args = (*args, "--ui", "127.0.0.1:0")
    if (
        args
        and args[0] == "run"
        and not {"--zenoh-listen", "--zenoh-config", "--config"} & set(args)
    ):
        args = (*args, "--zenoh-listen", "tcp/127.0.0.1:0")
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


def wait_until(predicate, timeout_s: float, poll_s: float = 0.1) -> bool:
    """Whether ``predicate()`` came true within ``timeout_s``, checked every ``poll_s``."""
    end = time.time() + timeout_s
    while time.time() < end:
        if predicate():
            return True
        time.sleep(poll_s)
    return False


def wait_for(predicate, timeout_s: float, what) -> None:
    """Wait for ``predicate()``; else fail naming ``what`` (a string, or a callable giving one: what was seen)."""
    if not wait_until(predicate, timeout_s):
        raise AssertionError(
            f"timed out after {timeout_s} s waiting for {what() if callable(what) else what}"
        )


async def until(predicate, timeout_s: float, what, poll_s: float = 0.02) -> None:
    """:func:`wait_for` on an event loop: polls ``predicate()`` every ``poll_s`` without blocking the loop."""
    end = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > end:
            raise AssertionError(
                f"timed out after {timeout_s} s waiting for {what() if callable(what) else what}"
            )
        await asyncio.sleep(poll_s)


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
    return horizontal_error_m(
        np.asarray(lat),
        np.asarray(lon),
        np.interp(t_session, truth["t"], truth["lat"]),
        np.interp(t_session, truth["t"], truth["lon"]),
    )

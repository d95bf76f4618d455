"""Shared helpers of the live tests: free loopback ports, a GPS_INPUT endpoint, the skyfix command, subprocess
cleanup."""

from __future__ import annotations

import json
import os
import random
import re
import select
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: Share of the frames that must get a fix, at the least. A loaded machine (CI: two cores, other jobs) gets
#: fewer than a quiet one (0.7-0.8 here; 0.41 once with the decoder at 99 ms a frame, 0.42 with two busy
#: processes beside the test): the service skips frames while its decoder is behind and drops them while the
#: tracker is, rather than send late fixes. The share is bench/live_latency.py's business; here every frame is
#: accounted for and every fix made must be right.
MIN_SHARE = 0.3


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


def ui_url(log: Path, timeout_s: float = 20.0) -> str:
    """The web page's URL (with ``?token=`` when it has one) that ``skyfix run`` logged."""

    def found() -> str | None:
        m = re.search(r"web page: (\S+)", log.read_text()) if log.exists() else None
        return m[1] if m else None

    wait_for(lambda: found() is not None, timeout_s, f"the web page's URL in {log}")
    return found()


def calibration_without_init_bbox(session: Path, tmp_path: Path) -> Path:
    """The session's calibration tables without ``[tracker] init_bbox``: the run awaits a target."""
    stripped = re.sub(r"(?m)^init_(bbox|t) = .*\n", "", (session / "session.toml").read_text())
    assert "init_bbox" not in stripped
    path = tmp_path / "calibration.toml"
    path.write_text(stripped)
    return path


def track_pixel(session: Path, t_session: float) -> tuple[float, float]:
    """The UUV's true pixel at a session time (the simulator's ``track.csv``)."""
    import numpy as np

    tr = np.genfromtxt(session / "track.csv", delimiter=",", names=True)
    return float(np.interp(t_session, tr["t"], tr["u"])), float(
        np.interp(t_session, tr["t"], tr["v"])
    )


class LiveRun:
    """``skyfix run`` without init_bbox, a subscriber to ``skyfix/**`` in its own process, then ``skyfix replay`` of
    ``session`` (at once, or at :meth:`start_replay` with ``replay_now=False``), all on loopback."""

    def __init__(
        self,
        tmp_path: Path,
        session: Path,
        *run_args: str,
        video_latency_ms: float,
        replay_now: bool = True,
    ):
        self.tmp = tmp_path
        self.session = session
        self.replay_now = replay_now
        mav, video, self.uuv = free_port(), free_port(), free_port()
        self.ep = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
        self.sub_out = tmp_path / "zenoh.jsonl"
        self.uuv_log = tmp_path / "uuv.jsonl"
        cal = calibration_without_init_bbox(session, tmp_path)
        self.run_cmd = skyfix(
            "run",
            "--calibration",
            str(cal),
            "--mavlink",
            f"udpin:127.0.0.1:{mav}",
            "--video",
            f"udp://127.0.0.1:{video}",
            "--video-latency-ms",
            str(video_latency_ms),
            "--zenoh-listen",
            self.ep,
            "--gps-input",
            f"udpout:127.0.0.1:{self.uuv}",
            "--duration-s",
            "40",
            *run_args,
        )
        self.replay_cmd = skyfix(
            "replay",
            str(session),
            "--mavlink-out",
            f"udpout:127.0.0.1:{mav}",
            "--video-out",
            f"udp://127.0.0.1:{video}",
            "--zenoh-connect",
            self.ep,
            "--uuv-listen",
            f"udpin:127.0.0.1:{self.uuv}",
            "--uuv-log",
            str(self.uuv_log),
            "--tail-s",
            "1.5",
        )
        self.procs: list[subprocess.Popen] = []

    def __enter__(self):
        self.service = start(self.run_cmd, self.tmp / "run.log")
        self.procs.append(self.service)
        self.procs.append(
            start(
                [sys.executable, "-c", SUBSCRIBER, self.ep, "skyfix/**", str(self.sub_out)],
                self.tmp / "sub.log",
            )
        )
        wait_for(
            lambda: any(r["key"] == "skyfix/status" for r in read_jsonl(self.sub_out)),
            20,
            "skyfix status on Zenoh",
        )
        if self.replay_now:
            self.start_replay()
        return self

    def start_replay(self) -> None:
        self.replay = start(self.replay_cmd, self.tmp / "replay.log")
        self.procs.append(self.replay)
        self.shift = replay_shift(self.tmp / "replay.log")

    def __exit__(self, *exc):
        for p in self.procs:
            if p.poll() is None:
                p.kill()
                p.wait()

    def finish(self) -> None:
        """Wait for the replay to end, then stop the service and the subscriber."""
        self.replay.wait(30)
        stop(self.service)
        stop(self.procs[1])
        log = (self.tmp / "run.log").read_text()
        assert self.service.returncode == 0, log[-3000:]
        assert self.replay.returncode == 0, (self.tmp / "replay.log").read_text()[-3000:]

    def fixes(self) -> list[dict]:
        return [
            json.loads(s["payload"]) | {"t_recv": s["t_recv"]}
            for s in read_jsonl(self.sub_out)
            if s["key"] == "skyfix/uuv/fix"
        ]

    def gps_input(self) -> list[dict]:
        return read_jsonl(self.uuv_log)

    def fix_errors_m(self, fixes: list[dict]):
        import numpy as np

        return truth_errors_m(
            self.session,
            np.array([f["t"] for f in fixes]) - self.shift,
            [f["lat"] for f in fixes],
            [f["lon"] for f in fixes],
        )

    def gps_errors_m(self, valid: list[dict]):
        import numpy as np

        return truth_errors_m(
            self.session,
            np.array([g["time_usec"] / 1e6 for g in valid]) - self.shift,
            [g["lat"] / 1e7 for g in valid],
            [g["lon"] / 1e7 for g in valid],
        )


def as_camera_sends_it(video: Path) -> None:
    """A simulated session's video re-encoded in place as a drone's camera streams it: H.264 without B-frames
    (x264's zerolatency tuning), a keyframe a second. ``skyfix sim`` writes B-frames: a decoder then holds each
    frame until the next two have come (133 ms at 15 fps) and hands them over in bursts, which no field camera
    does and which a live service's two-frame queue partly drops."""
    import av

    with av.open(str(video)) as container:
        fps = container.streams.video[0].average_rate
    tmp = video.with_name("camera" + video.suffix)
    subprocess.run(
        [
            "ffmpeg",
            "-v",
            "error",
            "-y",
            "-i",
            str(video),
            "-an",
            "-c:v",
            "libx264",
            "-preset",
            "veryfast",
            "-tune",
            "zerolatency",
            "-crf",
            "23",
            "-g",
            str(round(fps)),
            "-pix_fmt",
            "yuv420p",
            str(tmp),
        ],
        check=True,
    )
    tmp.replace(video)

"""Shared helpers of the live tests: free loopback ports, a GPS_INPUT endpoint, the skyfix command, subprocess
cleanup."""

from __future__ import annotations

import json
import re
import socket
import subprocess
import sys
from pathlib import Path

from groundstation.testing.live import (  # noqa: F401 (the tests import them from here)
    SUBSCRIBER,
    GpsInputEndpoint,
    free_port,
    read_jsonl,
    replay_shift,
    skyfix,
    start,
    stop,
    truth_errors_m,
    until,
    wait_for,
    wait_until,
)

ROOT = Path(__file__).resolve().parents[1]
#: Share of the frames that must get a fix, at the least. A loaded machine (CI: two cores, other jobs) gets
#: fewer than a quiet one (0.7-0.8 here; 0.41 once with the decoder at 99 ms a frame, 0.42 with two busy
#: processes beside the test): the service skips frames while its decoder is behind and drops them while the
#: tracker is, rather than send late fixes. The share is bench/live_latency.py's business; here every frame is
#: accounted for and every fix made must be right.
MIN_SHARE = 0.3


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

    def finish(self, early: bool = False) -> None:
        """Wait for the replay to end (``early``: what the test measures is in, nothing after it is read: the replay,
        which must not have failed, is stopped there), then stop the service and the subscriber."""
        replay_log = (self.tmp / "replay.log").read_text
        if early:
            assert self.replay.poll() in (None, 0), replay_log()[-3000:]
            stop(self.replay)
        else:
            self.replay.wait(30)
            assert self.replay.returncode == 0, replay_log()[-3000:]
        stop(self.service)
        stop(self.procs[1])
        log = (self.tmp / "run.log").read_text()
        assert self.service.returncode == 0, log[-3000:]

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

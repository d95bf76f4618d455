"""``skyfix latency``: the time code is read back exactly, whatever the camera's view of it, and a stream
of frames that film the code through a known delay gives that delay back within one display frame."""

from __future__ import annotations

import json
import threading
import time
import urllib.request
from fractions import Fraction

import av
import cv2
import numpy as np
import pytest
from live_helpers import free_port, skyfix, start, stop, wait_for

from groundstation.latency.timecode import read_timecode, render_timecode
from groundstation.video.send import MPEGTS_OPTIONS

T_MS = 1_796_151_234_567  # a UNIX time in ms
DISPLAY_HZ = 60.0
FPS = 30


def _filmed(image: np.ndarray, flip: bool = False) -> np.ndarray:
    """The screen seen by a camera: tilted, smaller, blurred, noisy, and upside down if ``flip``."""
    h, w = image.shape[:2]
    src = np.float32([[0, 0], [w, 0], [w, h], [0, h]])
    dst = np.float32([[90, 60], [w - 40, 20], [w - 70, h - 30], [50, h - 80]])
    out = cv2.warpPerspective(
        image, cv2.getPerspectiveTransform(src, dst), (w, h), borderValue=(60, 60, 60)
    )
    out = cv2.GaussianBlur(cv2.resize(out, (w * 2 // 3, h * 2 // 3)), (5, 5), 1.2)
    out = np.clip(
        out.astype(int) + np.random.default_rng(1).normal(0, 6, out.shape), 0, 255
    ).astype(np.uint8)
    return cv2.rotate(out, cv2.ROTATE_180) if flip else out


@pytest.mark.parametrize("flip", [False, True])
def test_timecode_reads_back_exactly(flip):
    image = _filmed(render_timecode(T_MS, 960, 540), flip)
    assert read_timecode(image, near_unix=T_MS / 1000 + 2.0) == pytest.approx(T_MS / 1000, abs=1e-6)
    assert read_timecode(np.full((540, 960, 3), 255, np.uint8), near_unix=T_MS / 1000) is None


def _camera(url: str, delay_s: float, seconds: float, sent: list, stop_: threading.Event) -> None:
    """A camera filming the time code with ``delay_s`` from glass to first packet: frame i is due at
    t_i, shows the code the screen showed at t_i − delay_s (a 60 Hz display), and leaves when encoded."""
    out = av.open(f"{url}?pkt_size=1316", "w", format="mpegts", options=MPEGTS_OPTIONS)
    stream = out.add_stream(
        "libx264", options={"preset": "ultrafast", "tune": "zerolatency", "g": "30"}
    )
    stream.width, stream.height, stream.pix_fmt = 640, 360, "yuv420p"
    stream.codec_context.time_base = Fraction(1, FPS)
    t0 = time.time() + 0.3
    try:
        for i in range(int(seconds * FPS)):
            t_i = t0 + i / FPS
            if stop_.wait(max(0.0, t_i - time.time())):
                return
            glass = t_i - delay_s
            shown_ms = int(np.floor(glass * DISPLAY_HZ) / DISPLAY_HZ * 1000.0)
            frame = av.VideoFrame.from_ndarray(render_timecode(shown_ms, 640, 360), format="bgr24")
            frame.pts = i
            for packet in stream.encode(
                frame
            ):  # the encoder may hand out an earlier frame's packet
                index = packet.pts  # in frames (1/FPS) until muxed
                out.mux(packet)
                # this camera's true glass-to-packet latency (a frame is a few UDP packets, sent at once)
                sent.append(time.time() - (t0 + index / FPS - delay_s))
    finally:
        out.close()


def test_latency_command_recovers_a_known_delay(tmp_path):
    delay_s = 0.120
    port, http = free_port(), free_port(socket_kind())
    log = tmp_path / "latency.log"
    proc = start(
        skyfix(
            "latency",
            "--video",
            f"udp://127.0.0.1:{port}",
            "--port",
            str(http),
            "--duration-s",
            "40",
            "--samples",
            "90",
            "--display-hz",
            str(DISPLAY_HZ),
        ),
        log,
    )
    sent, halt = [], threading.Event()
    camera = threading.Thread(
        target=_camera, args=(f"udp://127.0.0.1:{port}", delay_s, 25.0, sent, halt)
    )
    try:
        wait_for(lambda: "Open http" in log.read_text(), 20, "the command to start")
        page = urllib.request.urlopen(f"http://127.0.0.1:{http}/", timeout=5).read().decode()
        # the markers travel with the page
        assert "requestAnimationFrame" in page and page.count("[") > 1000
        now = json.loads(urllib.request.urlopen(f"http://127.0.0.1:{http}/now", timeout=5).read())[
            "t_unix"
        ]
        assert abs(now - time.time()) < 1.0
        camera.start()
        proc.wait(60)
    finally:
        halt.set()
        if camera.is_alive():
            camera.join(10)
        stop(proc)
    text = log.read_text()
    assert proc.returncode == 0, text[-2000:]
    result = json.loads(text.strip().splitlines()[-1])
    measured_ms = result["latency"]["video_latency_ms"]
    true_ms = float(np.median(sent)) * 1000.0
    print(
        f"latency: measured {measured_ms} ms, true {true_ms:.1f} ms (delay {delay_s * 1000:.0f} ms + encoding); "
        f"{result['latency']}"
    )
    assert result["latency"]["n"] >= 60
    assert abs(measured_ms - true_ms) <= 1000.0 / DISPLAY_HZ
    assert "configure: --video-latency-ms" in text


def socket_kind() -> int:
    import socket

    return socket.SOCK_STREAM

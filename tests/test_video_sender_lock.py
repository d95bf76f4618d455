"""A ``udp://`` / ``rtp://`` video input takes one sender: two real FFmpeg senders on loopback, a red camera and a
blue intruder, each from its own source port, to the same port. Locked to the first (or to the configured
``peer=``), every frame handed over is that sender's colour and the other's datagrams are counted unread;
with ``peer=any`` the intruder's packets get in (the control: the same setup fails the lock's assertions)."""

from __future__ import annotations

import subprocess

import numpy as np
import pytest
from live_helpers import free_port, wait_for
from test_live_video_inputs import SIZE, Receiver

SEND_S = 20  # a sender runs at most this long (killed when the test has seen enough)


def _sender(colour: str, scheme: str, port: int, source_port: int) -> subprocess.Popen:
    """``ffmpeg -re`` sending a plain ``colour`` picture as a camera does (H.264, a keyframe every 0.5 s) from
    127.0.0.1:``source_port``."""
    out = (
        ["-f", "rtp", f"rtp://127.0.0.1:{port}?localrtpport={source_port}"]
        if scheme == "rtp"
        else ["-f", "mpegts", f"udp://127.0.0.1:{port}?pkt_size=1316&localport={source_port}"]
    )
    return subprocess.Popen(
        ["ffmpeg", "-v", "error", "-re", "-f", "lavfi", "-i",
         f"color=c={colour}:size={SIZE[0]}x{SIZE[1]}:rate=30", "-t", str(SEND_S),
         "-c:v", "libx264", "-tune", "zerolatency", "-preset", "ultrafast", "-g", "15",
         "-pix_fmt", "yuv420p", *out],
        stdin=subprocess.DEVNULL,
    )  # fmt: skip


def _colour(frame) -> str:
    """red, blue or mixed: the frame's mean BGR."""
    b, _, r = frame.image.reshape(-1, 3).mean(axis=0)
    return "red" if r > 150 and b < 80 else "blue" if b > 150 and r < 80 else "mixed"


def _two_senders(scheme: str, query: str) -> tuple[list[str], dict, tuple[int, int]]:
    """Red first, then blue while red goes on; the colours of the frames handed over once both sent for a
    while, the input's status, and (red's, blue's) source ports."""
    port, red_port, blue_port = free_port(), free_port(), free_port()
    base = f"rtp://127.0.0.1:{port}?codec=h264" if scheme == "rtp" else f"udp://127.0.0.1:{port}"
    url = base + ("&" if "?" in base else "?") + query.format(blue=blue_port) if query else base
    senders = []
    try:
        with Receiver(url) as rx:
            senders.append(_sender("red", scheme, port, red_port))
            status = rx.status
            wait_for(
                lambda: len(rx.frames) >= 15 or status()["sender"]["foreign_datagrams"] > 30,
                20,
                "15 frames (or 30 refused datagrams) from the first sender",
            )
            first = len(rx.frames)
            senders.append(_sender("blue", scheme, port, blue_port))
            kind = "rtp" if scheme == "rtp" else "mpegts"

            def seen(frames: int, foreign: int, dropped: int) -> bool:
                s = status()
                return (
                    len(rx.frames) >= frames
                    or s["sender"]["foreign_datagrams"] > foreign
                    or s[kind]["dropped_frames"] > dropped
                )

            wait_for(lambda: seen(first + 60, 200, 30), 20, lambda: f"60 more frames: {status()}")
            # both sending: another second and a half of frames (or of refused datagrams, or of broken frames)
            s = status()
            n, foreign, dropped = (
                len(rx.frames),
                s["sender"]["foreign_datagrams"],
                s[kind]["dropped_frames"],
            )
            wait_for(
                lambda: seen(n + 45, foreign + 200, dropped + 45),
                20,
                lambda: f"45 more frames with both senders on: {status()}",
            )
            colours = [_colour(f) for f in rx.frames[first:]]
            return colours, rx.status(), (red_port, blue_port)
    finally:
        for s in senders:
            s.kill()
            s.wait()


@pytest.mark.parametrize("scheme", ["udp", "rtp"])
def test_the_first_sender_keeps_the_port(scheme):
    colours, status, (red_port, _) = _two_senders(scheme, "")
    sender = status["sender"]
    counts = {c: colours.count(c) for c in set(colours)}
    print(f"{scheme}: frames after the intruder started {counts}; sender {sender}; "
          f"{status[scheme if scheme == 'rtp' else 'mpegts']}")  # fmt: skip
    assert sender["peer"] == f"127.0.0.1:{red_port}" and sender["locked"]
    assert sender["foreign_datagrams"] > 0 and sender["relocks"] == 0
    assert counts == {"red": len(colours)} and len(colours) >= 60


def test_a_configured_peer_is_the_only_sender_taken():
    """peer=HOST:PORT: the red sender, first on the port, is refused; blue (the configured camera) is read."""
    colours, status, (_, blue_port) = _two_senders("rtp", "peer=127.0.0.1:{blue}")
    sender = status["sender"]
    print(f"peer=blue: { ({c: colours.count(c) for c in set(colours)}) }; sender {sender}")
    assert sender["peer"] == f"127.0.0.1:{blue_port}" and sender["foreign_datagrams"] > 0
    assert colours and set(colours) == {"blue"}


def test_peer_any_takes_every_sender():
    """The control: without the lock the intruder's packets get in (frames of its colour, or the stream
    broken by its interleaved packets)."""
    colours, status, _ = _two_senders("udp", "peer=any")
    counts = {c: colours.count(c) for c in set(colours)}
    print(f"peer=any: {counts}; sender {status['sender']}; mpegts {status['mpegts']}")
    assert status["sender"]["foreign_datagrams"] == 0 and not status["sender"]["locked"]
    assert (
        counts.get("blue", 0) + counts.get("mixed", 0) > 0 or status["mpegts"]["lost_packets"] > 0
    )
    assert np.mean([c == "red" for c in colours]) < 1.0 or status["mpegts"]["dropped_frames"] > 0

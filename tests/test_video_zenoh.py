"""BlueOS's camera over Zenoh (``--video zenoh:video/<source>/stream``): ``foxglove.CompressedVideo`` messages in
CDR, as mavlink-camera-manager's Zenoh sink publishes them, read by the live video reader on real Zenoh sessions on
loopback: a router (BlueOS's, which time-stamps what it routes), the camera as its client, the service as a peer.

Checked: the CDR layout against bytes written out by hand from the camera manager's serializer's rules; frames
timed by the messages' own time stamps (a camera clock 1000 s off, frames published in bursts of two); another
peer's video refused and counted, garbage counted, a stream that stops reported and taken again when it returns;
``skyfix run`` fed by ``skyfix replay --video-out zenoh:...`` through a router tracks a generated session as
accurately as over RTP; ``skyfix latency`` measures a Zenoh camera's glass-to-publication latency.
"""

from __future__ import annotations

import json
import socket
import subprocess
import threading
import time
from fractions import Fraction
from pathlib import Path

import av
import numpy as np
import pytest
from live_helpers import (
    MIN_SHARE,
    ROOT,
    free_port,
    replay_shift,
    skyfix,
    start,
    stop,
    truth_errors_m,
    wait_for,
)
from test_live_video_inputs import FPS, SIZE, Receiver, _check_timing

from groundstation.latency.timecode import render_timecode
from groundstation.runtime.zenoh_session import open_session
from groundstation.video.frames import VideoError
from groundstation.video.inputs import parse_video_input
from groundstation.video.zenoh_video import (
    ENCODING,
    BadVideoMessage,
    CompressedVideo,
    camera_access_units,
    camera_encoder,
    encode_compressed_video,
    parse_compressed_video,
    publish_video,
)

KEY = "video/RadCamUDPStream/stream"  # the camera manager's: its stream's name, letters and digits only

# {timestamp {sec 1234, nsec 0x12345678}, frame_id "vehicle", data 00 00 00 01 65, format "h264"}, as Rust's
# cdr::serialize::<_, _, CdrLe>(.., Infinite) writes it: the encapsulation header, then each u32 aligned to 4
# from the body's start; a string's length counts its NUL; a Vec<u8> is a u32 count and the bytes
CAMERA_MANAGER_BYTES = bytes.fromhex(
    "00010000"  # CDR, little endian
    "d2040000"  # sec
    "78563412"  # nsec
    "08000000" + "76656869636c6500"  # "vehicle\0"
    "05000000" + "0000000165" + "000000"  # data (5 bytes), padding to 4
    "05000000" + "6832363400"  # "h264\0"
)


def test_the_camera_managers_cdr_layout():
    msg = parse_compressed_video(CAMERA_MANAGER_BYTES)
    assert msg == CompressedVideo(1234, 0x12345678, "vehicle", b"\x00\x00\x00\x01\x65", "h264")
    assert msg.ticks_90khz == 1234 * 90_000 + 0x12345678 * 90_000 // 10**9
    assert encode_compressed_video(msg) == CAMERA_MANAGER_BYTES
    big_endian = bytes.fromhex("00000000 000004d2 12345678 00000008") + CAMERA_MANAGER_BYTES[16:24]
    big_endian += bytes.fromhex("00000005 0000000165 000000 00000005 6832363400")
    assert parse_compressed_video(big_endian) == msg


@pytest.mark.parametrize(
    "payload, says",
    [
        (b"", "CDR header"),
        (b"\x00\x07\x00\x00" + CAMERA_MANAGER_BYTES[4:], "CDR header 00070000"),
        (CAMERA_MANAGER_BYTES[:30], "data of 5 bytes runs past"),
        (CAMERA_MANAGER_BYTES[:-1], "format of 5 bytes runs past"),
        (CAMERA_MANAGER_BYTES[:8] + b"\xff\xff\xff\xff" + CAMERA_MANAGER_BYTES[12:], "nsec"),
        (CAMERA_MANAGER_BYTES[:-1] + b"x", "format is not a NUL-terminated string"),
        (b'{"t": 1, "data": "AAAB"}', "CDR header"),
    ],
)
def test_garbage_is_named(payload, says):
    with pytest.raises(BadVideoMessage, match=says):
        parse_compressed_video(payload)


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    """4 s of a test pattern at the receiver's size, as a file a camera's frames are taken from."""
    path = tmp_path_factory.mktemp("clip") / "clip.mp4"
    subprocess.run(
        ["ffmpeg", "-v", "error", "-y", "-f", "lavfi"]
        + ["-i", f"testsrc=size={SIZE[0]}x{SIZE[1]}:rate={FPS}", "-t", "4"]
        + ["-c:v", "libx264", "-preset", "ultrafast", "-pix_fmt", "yuv420p", str(path)],
        check=True,
        timeout=60,
    )
    return path


@pytest.fixture
def net():
    """BlueOS's router; the camera manager, its client; the service, a peer of the router that also listens;
    an intruder, a peer connected to the service directly."""
    router_ep = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    service_ep = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    sessions = {"router": open_session(listen=[router_ep], mode="router")}
    try:
        sessions["camera"] = open_session(connect=[router_ep], mode="client")
        sessions["service"] = open_session(connect=[router_ep], listen=[service_ep])
        sessions["intruder"] = open_session(connect=[service_ep])
        yield sessions
    finally:
        for s in reversed(sessions.values()):
            s.close()


def test_frames_are_timed_by_the_cameras_own_clock(net, clip):
    """The camera computer's clock 1000 s ahead, its frames published in bursts of two: the slots follow the
    messages' time stamps (a frame period apart), mapped onto the station clock (offset about −1000 s)."""
    units = [bytes(p) for _, p in camera_access_units(clip)][:90]
    with Receiver(f"zenoh:{KEY}", session=net["service"]) as rx:
        wait_for(lambda: rx.status()["state"] != "starting", 10, "the receiver to start")
        t0 = time.time() + 0.5
        for i, unit in enumerate(units):
            t_cam_ns = round((t0 + 1000.0 + i / FPS) * 1e9)
            if i % 2 == 0:  # the pair's first waits for its slot, the second goes right after it
                time.sleep(max(0.0, t0 + i / FPS - time.time()))
            msg = CompressedVideo(t_cam_ns // 10**9, t_cam_ns % 10**9, "vehicle", unit, "h264")
            net["camera"].put(KEY, encode_compressed_video(msg), encoding=ENCODING)
        wait_for(lambda: len(rx.frames) >= 80, 15, "80 frames over Zenoh")
        status = rx.status()
    print(f"zenoh: {status}")
    _check_timing(rx.frames)  # slots a frame period apart (median), never after arrival
    together = np.diff([f.t_recv for f in rx.frames]) < 0.5 / FPS
    # about half the frames arrived with the one before, yet timed a frame apart
    assert together.mean() > 0.3
    assert status["stream_offset_s"] == pytest.approx(-1000.0, abs=0.5)
    assert status["kind"] == "zenoh" and status["zenoh"]["bad_packets"] == 0
    assert status["sender"]["peer"] == str(net["router"].zid())  # BlueOS's router stamped them


def test_another_peer_garbage_and_a_cut(net, clip):
    """Locked to the router's ID: another peer's video (stamped or not) is refused and counted; garbage from the
    camera counted and logged in one line; the end of the stream reported, then frames again when it returns."""
    router = str(net["router"].zid())
    good = encode_compressed_video(
        CompressedVideo(1, 0, "vehicle", bytes(next(camera_access_units(clip))[1]), "h264")
    )
    with Receiver(f"zenoh:{KEY}?peer={router}", session=net["service"], read_timeout_s=1.0) as rx:
        wait_for(lambda: rx.status()["state"] != "starting", 10, "the receiver to start")
        stop = threading.Event()
        sent = publish_video(clip, KEY, time.time() + 0.3, stop, session=net["camera"])
        intruder = net["intruder"]
        intruder.put(KEY, good, encoding=ENCODING)
        intruder.put(KEY, good, encoding=ENCODING, timestamp=intruder.new_timestamp())
        for _ in range(3):
            net["camera"].put(KEY, b"\x00\x01\x00\x00garbage", encoding=ENCODING)
        wait_for(
            lambda: (
                rx.status()["sender"]["foreign_datagrams"] == 2
                and rx.status()["zenoh"]["bad_packets"] == 3
            ),
            10,
            lambda: (
                f"the intruder's 2 messages refused and 3 garbage payloads counted: {rx.status()}"
            ),
        )
        wait_for(
            lambda: "nothing received for 1 s" in (rx.status()["error"] or ""),
            10,
            "the stop reported",
        )
        n_before, t_back = len(rx.frames), time.time()
        publish_video(clip, KEY, time.time() + 0.3, stop, session=net["camera"])
        wait_for(lambda: rx.count_after(t_back) >= 60, 15, "frames again after the stream returned")
        status = rx.status()
    print(f"zenoh: {sent} sent; {status}")
    assert sent >= 119 and n_before >= 60  # a loaded machine's decoder skips frames while behind
    assert status["connects"] >= 2 and status["sender"]["peer"] == router
    assert status["sender"]["foreign_datagrams"] == 2 and status["zenoh"]["bad_packets"] == 3
    assert status["decode_errors"] == 0
    _check_timing(rx.frames[:n_before])


def test_zenoh_inputs_are_parsed_and_bad_ones_named():
    src = parse_video_input(f"zenoh:{KEY}?peer=ABC123")
    assert (src.kind, src.file, src.peer, src.any_sender, src.live) == (
        "zenoh",
        KEY,
        "abc123",
        False,
        True,
    )
    assert parse_video_input(f"zenoh:{KEY}?peer=any").any_sender
    for url, says in (
        ("zenoh:", "is not one Zenoh key"),
        ("zenoh:video/*/stream", "is not one Zenoh key"),
        ("zenoh:/video/a", "is not one Zenoh key"),
        (f"zenoh:{KEY}?peer=127.0.0.1:7447", "is not a Zenoh ID"),
        (f"zenoh:{KEY}?codec=h264", "unknown option codec"),
    ):
        with pytest.raises(VideoError, match=says):
            parse_video_input(url)


# -- the live service on a generated session: BlueOS's Zenoh video against RTP -----------------------------------

SESSION = ROOT / "sim_fixtures" / "bundled" / "nadir_hover"  # 640x360, 7 s


def _live_fixes(tmp_path: Path, video_out: str, video_in: str) -> tuple[list[dict], dict]:
    """``skyfix replay`` of :data:`SESSION` (its video to ``video_out``) into ``skyfix run --video video_in``, both
    clients of a Zenoh router (BlueOS's); the fixes (on the session's clock) and the last status seen there."""
    router_ep = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    router = open_session(listen=[router_ep], mode="router")
    seen: list[dict] = []
    sub = router.declare_subscriber(
        "skyfix/**",
        lambda s: seen.append({"key": str(s.key_expr), **json.loads(s.payload.to_bytes())}),
    )
    # the camera's side a client of the router, as BlueOS's camera manager is: what it publishes is routed (and
    # time-stamped) by the router, not sent to the service peer to peer
    client = tmp_path / "client.json5"
    client.write_text('{mode: "client", scouting: {multicast: {enabled: false}}}')
    mav = free_port()
    run = start(
        skyfix(
            "run",
            "--calibration",
            str(SESSION / "session.toml"),
            "--mavlink",
            f"udpin:127.0.0.1:{mav}",
            "--video",
            video_in,
            "--video-latency-ms",
            "0",
            "--zenoh-connect",
            router_ep,
            "--zenoh-listen",
            f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}",
            "--gps-input",
            "none",
            "--duration-s",
            "40",
        ),
        tmp_path / "run.log",
    )
    try:
        wait_for(lambda: any(s["key"] == "skyfix/status" for s in seen), 20, "skyfix status")
        replay = start(
            skyfix(
                "replay",
                str(SESSION),
                "--mavlink-out",
                f"udpout:127.0.0.1:{mav}",
                "--video-out",
                video_out,
                "--zenoh-connect",
                router_ep,
                "--zenoh-config",
                str(client),
                "--uuv-listen",
                "",
                "--tail-s",
                "1.0",
            ),
            tmp_path / "replay.log",
        )
        assert replay.wait(40) == 0, (tmp_path / "replay.log").read_text()[-3000:]
    finally:
        stop(run)
        sub.undeclare()
        router.close()
    shift = replay_shift(tmp_path / "replay.log")
    fixes = [{**s, "t": s["t"] - shift} for s in seen if s["key"] == "skyfix/uuv/fix"]
    return fixes, [s for s in seen if s["key"] == "skyfix/status"][-1]


def test_the_live_service_tracks_from_zenoh_as_from_rtp(tmp_path):
    """The same generated session replayed twice, its video once as RTP, once as BlueOS's camera manager
    publishes it: as many frames tracked, and fixes as close to the truth."""
    n_frames = len((SESSION / "video_frames.csv").read_text().splitlines()) - 1
    mae = {}
    for name, video_out, video_in in (
        ("rtp", f"rtp://127.0.0.1:{(port := free_port())}", f"rtp://127.0.0.1:{port}"),
        ("zenoh", f"zenoh:{KEY}", f"zenoh:{KEY}"),
    ):
        (tmp_path / name).mkdir()
        fixes, status = _live_fixes(tmp_path / name, video_out, video_in)
        ok = [f for f in fixes if f["status"] == "ok"]
        err = truth_errors_m(
            SESSION, np.array([f["t"] for f in ok]), [f["lat"] for f in ok], [f["lon"] for f in ok]
        )
        mae[name] = float(err.mean())
        print(
            f"{name}: {len(fixes)} fixes, {len(ok)} ok of {n_frames} frames, MAE {err.mean():.4f} m, "
            f"max {err.max():.4f} m; video {status['video']['kind']}, sender {status['video']['sender']}"
        )
        assert status["video"]["kind"] == name
        assert len(ok) >= MIN_SHARE * n_frames, (name, len(ok), n_frames)
    assert mae["zenoh"] <= 0.1 and mae["zenoh"] <= 1.5 * mae["rtp"] + 0.005, mae


def test_latency_command_measures_a_zenoh_camera(tmp_path):
    """``skyfix latency --video zenoh:...``: a camera filming the time code through a known delay, published as
    the camera manager publishes (through a router): the glass-to-publication latency within one display frame."""
    delay_s, display_hz, seconds = 0.120, 60.0, 20.0
    router_ep = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    http = free_port(socket.SOCK_STREAM)
    log = tmp_path / "latency.log"
    sent, halt = [], threading.Event()

    def camera(session) -> None:
        """Frame i due at t_i shows the code a 60 Hz screen showed at t_i − delay_s; published when encoded."""
        enc = camera_encoder(640, 360, Fraction(1, FPS))
        t0 = time.time() + 0.3
        for i in range(int(seconds * FPS)):
            if halt.wait(max(0.0, t0 + i / FPS - time.time())):
                return
            glass = t0 + i / FPS - delay_s
            shown_ms = int(np.floor(glass * display_hz) / display_hz * 1000.0)
            frame = av.VideoFrame.from_ndarray(render_timecode(shown_ms, 640, 360), format="bgr24")
            frame.pts = i
            for packet in enc.encode(frame.reformat(format="yuv420p")):
                now_ns = time.time_ns()
                msg = CompressedVideo(
                    now_ns // 10**9, now_ns % 10**9, "vehicle", bytes(packet), "h264"
                )
                session.put(KEY, encode_compressed_video(msg), encoding=ENCODING)
                sent.append(now_ns / 1e9 - glass)

    router = open_session(listen=[router_ep], mode="router")
    cam = open_session(connect=[router_ep], mode="client")
    thread = threading.Thread(target=camera, args=(cam,))
    proc = start(
        skyfix("latency", "--video", f"zenoh:{KEY}", "--zenoh-connect", router_ep)
        + ["--port", str(http), "--duration-s", "40", "--samples", "90"]
        + ["--display-hz", str(display_hz)],
        log,
    )
    try:
        wait_for(lambda: "Open http" in log.read_text(), 20, "the command to start")
        thread.start()
        proc.wait(60)
    finally:
        halt.set()
        if thread.is_alive():
            thread.join(10)
        stop(proc)
        cam.close()
        router.close()
    text = log.read_text()
    assert proc.returncode == 0, text[-2000:]
    result = json.loads(text.strip().splitlines()[-1])
    measured_ms, true_ms = result["latency"]["video_latency_ms"], float(np.median(sent)) * 1000.0
    print(f"zenoh latency: measured {measured_ms} ms, true {true_ms:.1f} ms; {result['latency']}")
    assert result["video"]["kind"] == "zenoh" and result["latency"]["n"] >= 60
    assert abs(measured_ms - true_ms) <= 1000.0 / display_hz

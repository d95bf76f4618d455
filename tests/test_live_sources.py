"""Live sources over real loopback links: depth over Zenoh, the UAV's MAVLink over UDP, video over UDP MPEG-TS."""

from __future__ import annotations

import asyncio
import json
import logging
import socket
import subprocess
import time
from pathlib import Path

import pytest
from live_helpers import free_port, until

from groundstation.live.sources.depth_zenoh import DepthZenoh, parse_depth
from groundstation.live.sources.rates import needed_rates
from groundstation.live.sources.uav_mavlink import UavMavlink
from groundstation.mavlink.ids import SKYFIX_SYSID
from groundstation.mavlink.ingest import mavutil
from groundstation.mavlink.transport import ANY_PEER
from groundstation.runtime.logs import Throttle, kind_of
from groundstation.runtime.zenoh_session import open_session
from groundstation.video.live import VideoLive
from localizer.telemetry import Telemetry


async def _run_until(worker, done, what, during=None):
    """Run ``worker`` while ``during()`` (the stimulus) runs and until ``done()`` holds: conditions, not times."""
    task = asyncio.create_task(worker.run())
    try:
        if during is not None:
            await during()
        await until(done, 30.0, what)
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)


def test_depth_over_zenoh_clocks_garbage_and_jumps(caplog):
    """Depth stamped by a UUV clock an hour ahead is aligned by its arrival (and says so); one that agrees
    with the station is taken as stamped; garbage is named in one line; a jump faster than the vehicle can
    dive is refused with the values."""
    ep = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    service = open_session(listen=[ep])
    publisher = open_session(connect=[ep])
    tel_own, tel_sync = Telemetry(), Telemetry()
    own = DepthZenoh(service, "uuv/depth", tel_own)
    synced = DepthZenoh(service, "uuv/depth_synced", tel_sync)
    stamps = []

    to_own = publisher.declare_publisher("uuv/depth")
    to_synced = publisher.declare_publisher("uuv/depth_synced")

    async def publish():
        await until(
            lambda: to_own.matching_status.matching and to_synced.matching_status.matching,
            30.0,
            "the service's depth subscriptions",
        )
        for i in range(3):
            to_own.put(
                json.dumps({"t": time.time() + 3600.0, "depth_m": 1.0 + 0.02 * i, "extra": "x"})
            )
            stamps.append(time.time())
            to_synced.put(json.dumps({"t": stamps[-1], "depth_m": 0.5}))
            await asyncio.sleep(0.05)  # the stimulus: a depth sensor's pace
        to_own.put(b"\xff\x00garbage")
        to_own.put(json.dumps({"t": time.time() + 3600.0, "depth_m": "deep"}))
        # out of range
        to_own.put(json.dumps({"t": time.time() + 3600.0, "depth_m": 99999.0}))
        await asyncio.sleep(0.05)
        # 2.96 m in 0.1 s
        to_own.put(json.dumps({"t": time.time() + 3600.0, "depth_m": 4.0}))
        await asyncio.sleep(0.05)
        to_own.put(json.dumps({"t": time.time() + 3600.0, "depth_m": 1.06}))

    async def both():
        await asyncio.gather(
            _run_until(
                own,
                lambda: len(tel_own.depth) == 4 and own.bad + own.refused == 4,
                lambda: (
                    f"4 depths and 4 refusals, seen {len(tel_own.depth)}, {own.bad}+{own.refused}"
                ),
                publish,
            ),
            _run_until(synced, lambda: len(tel_sync.depth) == 3, "3 synced depths"),
        )

    caplog.set_level(logging.WARNING)
    try:
        asyncio.run(both())
    finally:
        publisher.close()
        service.close()
    assert list(tel_own.depth.values[:, 0]) == [1.0, 1.02, 1.04, 1.06]
    assert own.bad == 2 and own.refused == 2 and own.gate.refused == 1
    assert tel_own.depth_aligned_by == "arrival"
    assert tel_own.uuv_clock_minus_station_s == pytest.approx(3600.0, abs=0.2)
    # on the station clock (its arrival less the configured latency), not an hour ahead
    assert abs(tel_own.depth.times[0] - stamps[0]) < 2.0
    assert any("UUV's clock is +3600" in r.message for r in caplog.records)
    assert tel_sync.depth_aligned_by == "uuv_clock" and list(tel_sync.depth.times) == stamps
    assert any("deep" in r.message for r in caplog.records)
    assert any("garbage" in r.message for r in caplog.records)
    jump = [r.message for r in caplog.records if "faster than the vehicle can dive" in r.message]
    assert len(jump) == 1 and "depth 4.00 m refused: 2.96 m from 1.04 m" in jump[0], jump
    assert own.status(time.time())["source"] == "skyfix"


def test_a_flood_of_one_problem_stays_a_trickle_in_the_log(caplog):
    """Each distinct problem is named; 1000 copies of one give a handful of lines, not 1000."""
    tel = Telemetry()
    depth = DepthZenoh(None, "uuv/depth", tel)
    caplog.set_level(logging.WARNING)
    for _ in range(1000):
        depth._on_payload("uuv/depth", b"garbage", time.time())
    depth._on_payload(
        "uuv/depth", json.dumps({"t": time.time(), "depth_m": "deep"}).encode(), time.time()
    )
    lines = [r.message for r in caplog.records]
    assert depth.bad == 1001
    assert sum("not JSON" in m for m in lines) == 5 + 1000 // 100
    assert any("'deep'" in m or "deep" in m for m in lines)


def test_throttle_is_keyed_by_the_kind_with_bounded_memory():
    """pymavlink's CRC complaints differ in their numbers only: one kind. Endless distinct kinds stay bounded."""
    throttle = Throttle()
    crcs = [
        f"invalid MAVLink CRC in msgID {i % 250} 0x{i:04x} should be 0x{(i * 7) & 0xFFFF:04x}"
        for i in range(1000)
    ]
    logged = [n for text in crcs if (n := throttle(kind_of(text)))]
    assert list(throttle.counts) == ["invalid MAVLink CRC in msgID # # should be #"]
    assert logged == [1, 2, 3, 4, 5, *range(100, 1001, 100)]
    assert kind_of("message type 'GPS_RAW_INT' is not VFR_HUD") == "message type # is not VFR_HUD"
    for i in range(10_000):
        throttle(f"kind {i}")
    assert len(throttle.counts) == throttle.max_kinds + 1  # the last one: "(other)"


def test_parse_depth_rejects_non_numbers():
    with pytest.raises(ValueError, match="depth_m"):
        parse_depth(b'{"t": 1.0, "depth_m": NaN}')
    with pytest.raises(ValueError, match="t missing"):
        parse_depth(b'{"message": {"type": "VFR_HUD", "alt": 1}}')


def test_uav_mavlink_ingests_heartbeats_and_survives_bad_frames():
    port = free_port()
    tel = Telemetry()
    # system 7 shares the UAV's channel (a radio several systems talk on): every sender taken, no lock
    uav = UavMavlink(f"udpin:127.0.0.1:{port}", tel, needed_rates("fixed"), peer=ANY_PEER)
    mav = mavutil()
    sender = mav.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=1, source_component=1)
    other = mav.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=7, source_component=1)

    async def send():
        async def heard():  # its heartbeat until the service has bound its port and taken it
            while uav.uav_sysid is None:
                sender.mav.heartbeat_send(
                    mav.mavlink.MAV_TYPE_QUADROTOR, mav.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 4
                )
                await asyncio.sleep(0.05)

        await asyncio.wait_for(heard(), 30.0)
        t0 = time.time()
        for i in range(10):
            boot_ms = 100_000 + round((time.time() - t0) * 1000)  # an autopilot's clock: real time
            sender.mav.system_time_send(int(time.time() * 1e6), boot_ms)
            sender.mav.attitude_send(boot_ms, 0.01, -0.02, 0.5 + i * 0.01, 0, 0, 0)
            sender.mav.global_position_int_send(
                boot_ms, 634400000, 104000000, 12000, 10000, 0, 0, 0, 0
            )
            other.mav.attitude_send(boot_ms, 1.0, 1.0, 1.0, 0, 0, 0)
            if i == 5:
                # corrupt: bad CRC
                sender.write(b"\xfd\x09\x00\x00\x00\x01\x01\x1e\x00\x00" + b"\x00" * 11)
            await asyncio.sleep(0.02)

    heartbeats = []  # the service's, to its UAV

    def done() -> bool:
        if not heartbeats and (hb := sender.recv_match(type="HEARTBEAT", blocking=False)):
            heartbeats.append(hb)
        return len(tel.attitude) == 10 and uav.health.other_systems == 10 and bool(heartbeats)

    try:
        asyncio.run(
            _run_until(
                uav, done, lambda: f"10 attitudes and a heartbeat: {len(tel.attitude)}", send
            )
        )
        hb = heartbeats[0]
    finally:
        sender.close()
        other.close()
    assert uav.uav_sysid == 1
    assert len(tel.attitude) == 10 and len(tel.position) == 10
    # system 7's attitude was not mixed in
    assert tel.attitude.values[:, 0].max() == pytest.approx(0.01)
    assert uav.health.other_systems == 10 and uav.health.bad_data >= 1
    status = uav.status(time.time())
    assert abs(status["clocks"]["station_minus_gnss_s"]) < 0.1  # SYSTEM_TIME was stamped when sent
    assert set(status["age_s"]) >= {"ATTITUDE", "GLOBAL_POSITION_INT", "SYSTEM_TIME"}
    assert hb.type == mav.mavlink.MAV_TYPE_GCS and hb.get_srcSystem() == SKYFIX_SYSID


def _stream(port: int, seconds: float) -> subprocess.Popen:
    return subprocess.Popen(
        [
            "ffmpeg",
            "-loglevel",
            "error",
            "-re",
            "-f",
            "lavfi",
            "-i",
            "testsrc=size=320x240:rate=30",
            "-t",
            str(seconds),
            "-c:v",
            "libx264",
            "-preset",
            "ultrafast",
            "-tune",
            "zerolatency",
            "-g",
            "15",
            "-f",
            "mpegts",
            f"udp://127.0.0.1:{port}?pkt_size=1316",
        ]
    )


def _udp_bound(port: int) -> bool:
    """Whether a UDP socket of this machine is bound to ``port`` (read from /proc: binding to test would
    take the port from the reader for a moment)."""
    lines = Path("/proc/net/udp").read_text().splitlines()[1:]
    return any(line.split()[1].endswith(f":{port:04X}") for line in lines)


def test_video_reconnects_when_the_stream_resumes():
    port = free_port()
    frames = []
    video = VideoLive(f"udp://127.0.0.1:{port}", 0.1, frames.append, read_timeout_s=1.5)

    started = []

    async def two_streams():
        task = asyncio.create_task(video.run())
        try:
            for _ in range(2):
                # listening: at the start, or again after the last stream's silence timed out
                await until(lambda: _udp_bound(port), 30.0, f"a socket on port {port}")
                started.append(time.time())
                p = _stream(port, 1.5)
                await asyncio.to_thread(p.wait)
                await until(lambda: video.state == "waiting", 30.0, "the silence's timeout")
            await until(lambda: len(frames) == video.frames, 30.0, "the frames handed over")
        finally:
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)

    asyncio.run(two_streams())
    first = [f for f in frames if f.t_recv < started[1]]
    second = [f for f in frames if f.t_recv >= started[1]]
    assert video.connects >= 2
    # 45 frames sent each time; a GOP may be lost at a start
    assert len(first) >= 25 and len(second) >= 25
    assert [f.index for f in frames] == list(range(len(frames)))
    # exposure = stream slot − latency; the slot (PTS on the station clock) is never after the arrival
    assert all(
        abs(f.t_slot - f.t_unix - 0.1) < 1e-6 and f.t_slot <= f.t_recv + 1e-6 for f in frames
    )
    assert frames[0].image.shape == (240, 320, 3)

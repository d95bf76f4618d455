"""GPS_INPUT through BlueOS's ``mavlink/in`` when the Zenoh router goes away and comes back.

A router (a Python Zenoh session in router mode, its own process: the only router on PyPI),
skyfix as a client of it, and a stand-in for BlueOS's mavlink-server (a client subscribed to
``mavlink/in``, publishing the autopilot's HEARTBEAT on ``mavlink/1/1/HEARTBEAT``). Killing the
router must show in the sink's status (link down, no router) and in one warning; GPS_INPUT reaches
mavlink-server again once the router is back.
"""

from __future__ import annotations

import asyncio
import json
import logging
import socket
import subprocess
import time

from live_helpers import free_port

from groundstation.runtime.gps_input import GpsInputSink
from groundstation.runtime.zenoh_mavlink import ZenohMavlinkIn
from groundstation.runtime.zenoh_session import open_session
from groundstation.testing.link_scenarios import start_router


def _router(ep: str) -> subprocess.Popen:
    return start_router(ep)[0]


def test_router_loss_is_named(caplog):
    ep = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    router = _router(ep)
    blueos = open_session(connect=[ep], mode="client")
    skyfix = open_session(connect=[ep], mode="client")
    got: list[tuple[float, dict]] = []
    sub = blueos.declare_subscriber(
        "mavlink/in", lambda s: got.append((time.time(), json.loads(s.payload.to_bytes())))
    )
    beat = blueos.declare_publisher("mavlink/1/1/HEARTBEAT")
    states: dict[str, dict] = {}

    async def scenario():
        nonlocal router
        sink = GpsInputSink(ZenohMavlinkIn(skyfix, "mavlink/in"), hz=10.0, max_age_s=0.5)
        task = asyncio.create_task(sink.run())

        async def until(pred, what, timeout_s=20.0):
            end = time.time() + timeout_s
            while not pred():
                assert time.time() < end, f"timed out waiting for {what}"
                beat.put(b'{"message": {"type": "HEARTBEAT"}}')
                await asyncio.sleep(0.05)

        await until(
            lambda: sink.status(time.time())["link"]["state"] == "up" and len(got) >= 5,
            "the link up",
        )
        await until(
            lambda: sink.status(time.time())["link"]["peer_age_s"] is not None, "a heartbeat"
        )
        states["up"] = sink.status(time.time())["link"]
        router.kill()
        router.wait()
        t_kill = time.time()
        await until(lambda: sink.status(time.time())["link"]["state"] == "down", "the link down")
        states["down"] = {**sink.status(time.time())["link"], "after_s": time.time() - t_kill}
        await asyncio.sleep(0.5)  # GPS_INPUT keeps being produced meanwhile, into the void
        router = _router(ep)
        t_back = time.time()
        await until(lambda: any(t > t_back for t, _ in got), "GPS_INPUT at mavlink-server again")
        states["back"] = {
            **sink.status(time.time())["link"],
            "after_s": min(t for t, _ in got if t > t_back) - t_back,
        }
        await sink.stop()
        await task

    try:
        with caplog.at_level(logging.INFO, logger="skyfix.gps_input"):
            asyncio.run(scenario())
    finally:
        beat.undeclare()
        sub.undeclare()
        skyfix.close()
        blueos.close()
        router.kill()
        router.wait()
    print(
        {
            k: {x: v[x] for x in ("state", "zenoh_routers", "sent_unmatched", "after_s") if x in v}
            for k, v in states.items()
        }
    )
    assert states["up"]["zenoh_routers"] == 1 and states["up"]["error"] is None
    down = states["down"]
    assert down["zenoh_routers"] == 0 and "mavlink/in" in down["error"]
    assert down["after_s"] < 5.0, "a killed router's closed connection is noticed at once"
    assert states["back"]["state"] == "up" and states["back"]["sent_unmatched"] >= 3
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1 and "no subscriber on mavlink/in" in warnings[0], warnings

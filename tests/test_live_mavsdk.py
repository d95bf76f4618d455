"""Both UAV telemetry backends (pymavlink, MAVSDK-Python) yield the same samples from the same MAVLink stream."""

from __future__ import annotations

import asyncio
import time

import numpy as np
import pytest
from live_helpers import free_port, until

from groundstation.live.sources.rates import needed_rates
from groundstation.live.sources.uav_mavlink import UavMavlink
from groundstation.live.sources.uav_mavsdk import UavMavsdk, mavsdk_url
from groundstation.mavlink.ingest import mavutil
from localizer.telemetry import Telemetry

NAMES = ("attitude", "position", "gimbal")


def test_backends_agree_on_one_stream():
    mav = mavutil()
    ports = free_port(), free_port()
    tels = Telemetry(), Telemetry()
    backends = (
        UavMavlink(f"udpin:127.0.0.1:{ports[0]}", tels[0], needed_rates("gimbal_device")),
        UavMavsdk(f"udpin:127.0.0.1:{ports[1]}", tels[1]),
    )
    senders = [
        mav.mavlink_connection(f"udpout:127.0.0.1:{p}", source_system=1, source_component=1)
        for p in ports
    ]
    rng = np.random.default_rng(5)

    def send(msg):  # the very same frame to both backends
        buf = msg.pack(senders[0].mav)
        for s in senders:
            s.write(buf)

    m = senders[0].mav

    async def scenario():
        tasks = [asyncio.create_task(b.run()) for b in backends]

        async def heard():  # MAVSDK needs the autopilot's heartbeat before it passes messages on
            while any(b.uav_sysid is None for b in backends):
                send(m.heartbeat_encode(2, 3, 0, 0, 4))
                await asyncio.sleep(0.25)

        await asyncio.wait_for(heard(), 60.0)
        now = time.time()
        for i in range(25):
            boot, r = 200_000 + 20 * i, rng.uniform(-0.3, 0.3, 3)
            q = [
                float(x)
                for x in np.r_[0.9, rng.uniform(-0.2, 0.2, 3)]
                / np.linalg.norm(np.r_[0.9, 0.2, 0.2, 0.2])
            ]
            send(m.system_time_encode(int((now + i * 0.02) * 1e6), boot))
            send(m.attitude_encode(boot, *r, 0, 0, 0))
            send(
                m.global_position_int_encode(
                    boot, 634400000 + i, 104000000 - i, 12000, 10000, 0, 0, 0, 0
                )
            )
            send(m.gimbal_device_attitude_status_encode(0, 0, boot, 64, q, 0, 0, 0, 0))
            await asyncio.sleep(0.02)
        await until(
            lambda: all(len(getattr(t, n)) == 25 for t in tels for n in NAMES),
            30.0,
            lambda: f"25 samples of each: {[[len(getattr(t, n)) for n in NAMES] for t in tels]}",
        )
        for t in tasks:
            t.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)

    try:
        asyncio.run(scenario())
    finally:
        for s in senders:
            s.close()
    for name in NAMES:
        a, b = getattr(tels[0], name), getattr(tels[1], name)
        assert len(a) == len(b) == 25, name
        # MAVSDK's JSON prints floats
        np.testing.assert_allclose(a.values, b.values, rtol=1e-6, atol=1e-7)
        # each backend aligns by its own receive times (MAVSDK hands messages over later, more so on a
        # loaded machine): the same boot-clock spacing, shifted by the difference of least delays
        np.testing.assert_allclose(np.diff(a.times), np.diff(b.times), atol=0.05)
        assert abs(np.median(a.times - b.times)) < 0.5, name


def test_connection_strings():
    assert mavsdk_url("udpin:0.0.0.0:14550") == "udpin://0.0.0.0:14550"
    assert mavsdk_url("tcp:10.0.0.2:5760") == "tcpout://10.0.0.2:5760"
    assert mavsdk_url("serial:///dev/ttyACM0:115200") == "serial:///dev/ttyACM0:115200"
    with pytest.raises(ValueError, match="bogus"):
        mavsdk_url("bogus")

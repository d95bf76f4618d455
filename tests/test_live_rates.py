"""skyfix as a ground station on the UAV link: rate requests, TIMESYNC, MNT1_TYPE, measured rates.

The autopilot is a pymavlink stand-in speaking the real protocol over UDP on
loopback: it streams ATTITUDE at 4 Hz (a slow radio's default) and answers
MAV_CMD_SET_MESSAGE_INTERVAL with COMMAND_ACK (accepting, or denying so that
skyfix falls back to REQUEST_DATA_STREAM), TIMESYNC requests the way ArduPilot
does (tc1 = its boot clock at receipt, ts1 echoed) and PARAM_REQUEST_READ.
"""

from __future__ import annotations

import asyncio
import threading
import time

import pytest
from live_helpers import free_port

from groundstation.live.sources.rates import needed_rates
from groundstation.live.sources.uav_mavlink import UavMavlink
from groundstation.mavlink.ingest import mavutil
from localizer.telemetry import Telemetry

BOOT0_S = 412.0
LINK_DELAY_S = 0.03  # the stand-in answers TIMESYNC and sends telemetry this late, both ways


class Autopilot:
    """A MAVLink autopilot stand-in (system 1, component 1) in a thread."""

    def __init__(self, port: int, accept: bool, rangefinder_hz: float | None = None):
        self.conn = mavutil().mavlink_connection(
            f"udpout:127.0.0.1:{port}", source_system=1, source_component=1
        )
        self.accept = accept
        self.rate_hz = {
            "ATTITUDE": 4.0,
            "GLOBAL_POSITION_INT": 10.0,
            "SYSTEM_TIME": 1.0,
            "GPS_RAW_INT": 5.0,
        }
        if rangefinder_hz:  # a downward lidar, streamed slowly
            self.rate_hz["DISTANCE_SENSOR"] = rangefinder_hz
        self.commands: list = []
        self.streams: list = []
        self.t0 = time.time()
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def boot_s(self) -> float:
        """Its time since boot, kept on the station's clock: delays are differences of one clock then, and a step or
        slew of the station clock against the monotonic one (a busy VM) is not taken for a link delay."""
        return BOOT0_S + time.time() - self.t0

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.stop.set()
        self.thread.join(2.0)
        self.conn.close()

    def _send(self, kind: str, boot_ms: int) -> None:
        m = self.conn.mav
        if kind == "ATTITUDE":
            m.attitude_send(boot_ms, 0.01, -0.02, 0.5, 0.0, 0.0, 0.0)
        elif kind == "GLOBAL_POSITION_INT":
            m.global_position_int_send(boot_ms, 634400000, 104000000, 12000, 10000, 0, 0, 0, 0)
        elif kind == "SYSTEM_TIME":
            m.system_time_send(int(time.time() * 1e6), boot_ms)
        elif kind == "GPS_RAW_INT":
            m.gps_raw_int_send(
                int(time.time() * 1e6),
                3,
                634400000,
                104000000,
                12000,
                70,
                100,
                0,
                0,
                14,
                alt_ellipsoid=52000,
                h_acc=800,
            )
        elif kind == "DISTANCE_SENSOR":
            m.distance_sensor_send(boot_ms, 20, 4000, 1000, 0, 0, 25, 0)

    def _answer(self, msg) -> None:
        mav = mavutil().mavlink
        kind = msg.get_type()
        if kind == "COMMAND_LONG" and msg.command == mav.MAV_CMD_SET_MESSAGE_INTERVAL:
            self.commands.append((int(msg.param1), msg.param2))
            name = {
                30: "ATTITUDE",
                33: "GLOBAL_POSITION_INT",
                2: "SYSTEM_TIME",
                24: "GPS_RAW_INT",
                132: "DISTANCE_SENSOR",
            }.get(int(msg.param1))
            if self.accept and name:
                self.rate_hz[name] = 1e6 / msg.param2
            result = mav.MAV_RESULT_ACCEPTED if self.accept else mav.MAV_RESULT_DENIED
            self.conn.mav.command_ack_send(msg.command, result)
        elif kind == "REQUEST_DATA_STREAM":
            self.streams.append((msg.req_stream_id, msg.req_message_rate))
            if msg.req_stream_id == mav.MAV_DATA_STREAM_EXTRA1:
                self.rate_hz["ATTITUDE"] = float(msg.req_message_rate)
        elif kind == "TIMESYNC" and msg.tc1 == 0:
            time.sleep(LINK_DELAY_S)  # the request's way up
            received = self.boot_s()  # ArduPilot stamps the request's receipt
            time.sleep(LINK_DELAY_S)  # the reply's way down
            self.conn.mav.timesync_send(round(received * 1e9), msg.ts1)
        elif kind == "PARAM_REQUEST_READ" and msg.param_id == "MNT1_TYPE":
            self.conn.mav.param_value_send(b"MNT1_TYPE", 1.0, mav.MAV_PARAM_TYPE_REAL32, 900, 412)

    def _run(self) -> None:
        mav = mavutil().mavlink
        due = dict.fromkeys(self.rate_hz, 0.0)
        next_hb = 0.0
        while not self.stop.is_set():
            now = time.monotonic()
            if now >= next_hb:
                self.conn.mav.heartbeat_send(
                    mav.MAV_TYPE_QUADROTOR, mav.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 4
                )
                next_hb = now + 1.0
            for kind, hz in self.rate_hz.items():
                if now >= due[kind]:
                    # stamped LINK_DELAY_S before sending: the sample is that old when it arrives
                    self._send(kind, round((self.boot_s() - LINK_DELAY_S) * 1000))
                    due[kind] = now + 1.0 / hz
            msg = self.conn.recv_match(blocking=True, timeout=0.005)
            if msg is not None:
                self._answer(msg)


def _serve_until(uav: UavMavlink, done, timeout_s: float) -> bool:
    """Run the UAV worker until ``done()`` or the timeout; whether ``done()`` became true."""

    async def main():
        task = asyncio.create_task(uav.run())
        end = time.monotonic() + timeout_s
        try:
            while time.monotonic() < end:
                if done():
                    return True
                await asyncio.sleep(0.1)
            return done()
        finally:
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)

    return asyncio.run(main())


def test_asks_for_the_rates_it_needs_and_measures_them():
    port = free_port()
    tel = Telemetry()
    uav = UavMavlink(f"udpin:127.0.0.1:{port}", tel, needed_rates("fixed"))
    with Autopilot(port, accept=True) as ap:
        ok = _serve_until(
            uav,
            lambda: (
                uav.health.meter.rate_hz("ATTITUDE", time.time()) >= 20.0
                and tel.mount_type == 1
                and tel.measured_latency_s is not None
            ),
            timeout_s=20.0,
        )
        status = uav.status(time.time())
    assert ok, status
    assert (30, pytest.approx(40000.0)) in ap.commands  # ATTITUDE at 25 Hz
    # GLOBAL_POSITION_INT already came at 10 Hz
    assert all(msg_id != 33 for msg_id, _ in ap.commands)
    assert "accepted" in status["rate_requests"]["ATTITUDE"]
    # no rangefinder: DISTANCE_SENSOR is not asked for
    assert all(msg_id != 132 for msg_id, _ in ap.commands)
    assert status["rates_hz"]["ATTITUDE"] >= 20.0
    assert status["clocks"]["uav_link_latency_source"] == "timesync"
    assert status["clocks"]["uav_link_latency_ms"] == pytest.approx(LINK_DELAY_S * 1000, abs=15.0)
    assert tel.mount_type == 1  # ArduPilot's servo mount: roll and pitch become body-relative


def test_a_rangefinders_rate_is_asked_for_once_one_comes():
    port = free_port()
    tel = Telemetry()
    uav = UavMavlink(f"udpin:127.0.0.1:{port}", tel, needed_rates("fixed"))
    with Autopilot(port, accept=True, rangefinder_hz=2.0) as ap:
        ok = _serve_until(
            uav,
            lambda: uav.health.meter.rate_hz("DISTANCE_SENSOR", time.time()) >= 8.0,
            timeout_s=25.0,
        )
        status = uav.status(time.time())
    assert ok, status
    assert (132, pytest.approx(100000.0)) in ap.commands  # 10 Hz
    assert "accepted" in status["rate_requests"]["DISTANCE_SENSOR"]


def test_a_denied_request_falls_back_to_request_data_stream():
    port = free_port()
    tel = Telemetry()
    uav = UavMavlink(f"udpin:127.0.0.1:{port}", tel, needed_rates("fixed"))
    with Autopilot(port, accept=False) as ap:
        ok = _serve_until(
            uav, lambda: uav.health.meter.rate_hz("ATTITUDE", time.time()) >= 20.0, timeout_s=20.0
        )
        status = uav.status(time.time())
    assert ok, status
    assert (mavutil().mavlink.MAV_DATA_STREAM_EXTRA1, 25) in ap.streams
    assert "denied" in status["rate_requests"]["ATTITUDE"]
    assert "stream requested" in status["rate_requests"]["ATTITUDE"]


def test_no_request_rates_leaves_the_autopilot_alone():
    port = free_port()
    tel = Telemetry()
    uav = UavMavlink(f"udpin:127.0.0.1:{port}", tel, needed_rates("fixed"), request_rates=False)
    with Autopilot(port, accept=True) as ap:
        # past the settling time at which requests would go out, with every message measured
        _serve_until(uav, lambda: False, timeout_s=5.0)
        status = uav.status(time.time())
    assert ap.commands == [] and ap.streams == []
    assert 2.0 <= status["rates_hz"]["ATTITUDE"] <= 6.0
    assert status["rate_requests"] == {}

"""The GPS_INPUT link as a UUV's autopilot sees it, over real pymavlink endpoints.

- ``skyfix run --gps-input tcp:`` against a pymavlink TCP server (``tcpin:``) that is not there at
  start, comes, goes away for a few seconds (an ArduSub reboot) and comes back: the service keeps
  running, its Zenoh status names the link down with the reason, and GPS_INPUT arrives again within
  1 s of the server listening again.
- HEARTBEAT at 1 Hz from the GPS_INPUT's own system/component, as an onboard controller.
- MAVLink 2 signing: a receiver holding the key takes signed GPS_INPUT, and rejects unsigned ones and
  ones signed with another key.
- ``GpsInputSink.stop()``: the last message is a no-fix, even right after a valid fix.
- The rate holds while the event loop is blocked (the keep-alive is a thread of the sink's own); a failing
  keep-alive restarts and is counted in the status.
"""

from __future__ import annotations

import asyncio
import json
import logging
import os
import socket
import subprocess
import threading
import time

import numpy as np
import pytest
from live_helpers import ROOT, GpsInputEndpoint, free_port, skyfix, start, stop, wait_for

from groundstation.mavlink.ingest import mavutil
from groundstation.mavlink.link import MavlinkLink, read_signing_key
from groundstation.runtime.gps_input import GpsInputSink, mavlink_gps_link
from groundstation.runtime.zenoh_session import open_session
from localizer.calibration import ConfigError
from localizer.fix import Fix

SESSION = ROOT / "sim_fixtures" / "bundled" / "nadir_hover"
RESUME_S = 1.0  # issue 11: GPS_INPUT resumes within 1 s of the autopilot returning
OUTAGE_S = 2.0  # how long the autopilot stays away (an ArduSub reboot takes a few seconds)


class Autopilot:
    """A pymavlink TCP server standing in for ArduSub's serial port: every message it gets, with its arrival."""

    def __init__(self, port: int):
        self.port = port
        self.msgs: list[tuple[float, object]] = []
        self.conn = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def up(self) -> float:
        self.conn = mavutil().mavlink_connection(f"tcpin:127.0.0.1:{self.port}")
        t = time.time()
        self._stop.clear()
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()
        return t

    def _read(self) -> None:
        while not self._stop.is_set():
            m = self.conn.recv_match(blocking=True, timeout=0.1)
            if m is not None and m.get_type() in ("GPS_INPUT", "HEARTBEAT"):
                self.msgs.append((time.time(), m))

    def down(self) -> float:
        self._stop.set()
        self._thread.join(2)
        self.conn.close()
        return time.time()

    def of(self, kind: str, since: float = 0.0) -> list[tuple[float, object]]:
        return [(t, m) for t, m in list(self.msgs) if t >= since and m.get_type() == kind]


def _autopilot_back(ap: Autopilot, service, link_state) -> float:
    """Start the autopilot's server; the seconds until the first GPS_INPUT reached it."""
    t_up = ap.up()
    wait_for(
        lambda: ap.of("GPS_INPUT", t_up) or service.poll() is not None,
        10,
        "GPS_INPUT after (re)start",
    )
    assert service.poll() is None, "the service exited"
    resumed = ap.of("GPS_INPUT", t_up)[0][0] - t_up
    wait_for(
        lambda: len(ap.of("GPS_INPUT", t_up)) >= 10 and ap.of("HEARTBEAT", t_up), 10, "10 GPS_INPUT"
    )
    wait_for(
        lambda: any(x["state"] == "up" for x in link_state(t_up)), 10, "a status naming the link up"
    )
    return resumed


def test_service_survives_the_autopilot_going_away(tmp_path):
    ap = Autopilot(free_port(socket.SOCK_STREAM))
    ep = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    run_log = tmp_path / "run.log"
    statuses: list[dict] = []
    service = start(
        skyfix(
            "run",
            "--calibration",
            str(SESSION / "session.toml"),
            "--mavlink",
            f"udpin:127.0.0.1:{free_port()}",
            "--zenoh-listen",
            ep,
            "--video",
            "none",
            "--gps-input",
            f"tcp:127.0.0.1:{ap.port}",
            "--duration-s",
            "120",
        ),
        run_log,
    )
    watcher = open_session(connect=[ep])
    sub = watcher.declare_subscriber(
        "skyfix/status", lambda s: statuses.append(json.loads(s.payload.to_bytes()))
    )

    def link_state(since: float) -> list[dict]:
        return [s["gps_input"]["link"] for s in list(statuses) if s["t"] >= since]

    try:
        # no autopilot at start: the service runs, and says why nothing is delivered
        wait_for(
            lambda: any(x["state"] == "down" for x in link_state(0)) or service.poll() is not None,
            30,
            "a status naming the GPS_INPUT link down",
        )
        assert service.poll() is None, run_log.read_text()[-3000:]
        assert "ConnectionRefusedError" in link_state(0)[-1]["error"]
        resumes = []
        for cycle in range(2):
            resumes.append(_autopilot_back(ap, service, link_state))
            t_down = ap.down()
            wait_for(
                lambda t=t_down: any(x["state"] == "down" for x in link_state(t)),
                10,
                "a status naming it down",
            )
            down = next(x for x in link_state(t_down) if x["state"] == "down")
            assert down["error"] and down["disconnects"] >= cycle + 1, (
                down
            )  # the server closes client, then listener
            with pytest.raises(subprocess.TimeoutExpired):
                # the autopilot stays away; the service must not exit meanwhile
                service.wait(OUTAGE_S)
        resumes.append(_autopilot_back(ap, service, link_state))
        assert service.poll() is None, run_log.read_text()[-3000:]
        stop(service)
        ap.down()
    finally:
        stop(service)
        sub.undeclare()
        watcher.close()
    log = run_log.read_text()
    print(
        f"GPS_INPUT resumed {[round(r, 3) for r in resumes]} s after the autopilot's TCP server listened"
    )
    assert service.returncode == 0, log[-3000:]
    assert "Traceback" not in log and "NoneType" not in log, log[-3000:]
    assert max(resumes) <= RESUME_S, (
        f"GPS_INPUT resumed {max(resumes):.3f} s after the autopilot came back"
    )
    transitions = log.count("GPS_INPUT link tcp:")
    assert 6 <= transitions <= 8, f"{transitions} log lines: each transition once, retries not"


def _receiver(port: int, key: bytes | None):
    rx = mavutil().mavlink_connection(f"udpin:127.0.0.1:{port}")
    if key is not None:
        rx.setup_signing(key, sign_outgoing=False)
    return rx


def _collect(rx, seconds: float) -> list:
    out, end = [], time.time() + seconds
    while time.time() < end:
        m = rx.recv_match(blocking=True, timeout=0.1)
        if m is not None:
            out.append(m)
    return out


def _fix(t: float) -> Fix:
    return Fix(
        t_unix=t,
        status="ok",
        u=10.0,
        v=10.0,
        lat=63.44,
        lon=10.4,
        alt_amsl_m=-1.0,
        depth_m=1.0,
        h_acc_m=0.3,
        v_acc_m=0.5,
    )


async def _run_sink(link: MavlinkLink, seconds: float, fixes: bool = False) -> GpsInputSink:
    sink = GpsInputSink(link, hz=10.0, max_age_s=0.5)
    task = asyncio.create_task(sink.run())
    end = time.time() + seconds
    while time.time() < end:
        if fixes:
            t = time.time()
            sink.on_fix(_fix(t), type("I", (), {"t_recv": t})())
        await asyncio.sleep(1 / 30)
    await sink.stop()
    await task
    return sink


def test_heartbeat_and_last_no_fix():
    port = free_port()
    rx = _receiver(port, None)
    try:
        sink = asyncio.run(_run_sink(mavlink_gps_link(f"udpout:127.0.0.1:{port}"), 2.5, fixes=True))
        got = _collect(rx, 0.5)
    finally:
        rx.close()
    beats = [m for m in got if m.get_type() == "HEARTBEAT"]
    gps = [m for m in got if m.get_type() == "GPS_INPUT"]
    assert 2 <= len(beats) <= 4, f"{len(beats)} heartbeats in 2.5 s"
    assert {(m.get_srcSystem(), m.get_srcComponent(), m.type, m.autopilot) for m in beats} == {
        (245, 220, 18, 8)
    }
    assert sum(m.fix_type == 3 for m in gps) >= 30
    assert gps[-1].fix_type == 1 and gps[-1].lat == 0, "stopping must end with a no-fix GPS_INPUT"
    assert sink.status(time.time())["link"]["state"] == "closed"


@pytest.mark.parametrize("sender_key", ["same", None, "other"])
def test_signing(tmp_path, sender_key):
    key = os.urandom(32)
    key_file = tmp_path / "gps_input.key"
    key_file.write_bytes(key.hex().encode() + b"\n")  # 64 hex digits
    assert read_signing_key(str(key_file)) == key
    sender = {"same": read_signing_key(str(key_file)), None: None, "other": os.urandom(32)}[
        sender_key
    ]
    port = free_port()
    rx = _receiver(port, key)
    try:
        asyncio.run(
            _run_sink(mavlink_gps_link(f"udpout:127.0.0.1:{port}", signing_key=sender), 1.0)
        )
        got = _collect(rx, 0.3)
    finally:
        rx.close()
    taken = [m for m in got if m.get_type() in ("GPS_INPUT", "HEARTBEAT")]
    bad = [m for m in got if m.get_type() == "BAD_DATA"]
    if sender_key == "same":
        assert len(taken) >= 9 and not bad
        assert all(m.get_signed() for m in taken) and rx.mav.signing.goodsig_count >= len(taken)
    else:
        assert taken == [], f"{len(taken)} messages accepted without the right signature"
        assert len(bad) >= 9 and all("signature" in str(m.reason).lower() for m in bad)


def test_a_signed_link_writes_its_timestamps_in_order():
    """Two threads hand a signed link messages as fast as they can — one replacing its newest GPS_INPUT, one queueing
    STATUSTEXTs — while the link heartbeats: a receiver that checks signatures, and refuses a timestamp not after the
    last (MAVLink's replay protection, as ArduPilot's), takes every one. Packed when handed over, a message could
    be written after a later-signed one (the heartbeat, the other thread's) and be refused."""
    key = os.urandom(32)
    port = free_port()
    rx = _receiver(port, key)
    link = mavlink_gps_link(f"udpout:127.0.0.1:{port}", signing_key=key)
    m = mavutil().mavlink
    stop_at = time.time() + 2.5

    def gps():
        while time.time() < stop_at:
            link.send(
                "GPS_INPUT",
                {
                    "time_usec": 0,
                    "gps_id": 0,
                    "ignore_flags": 0,
                    "time_week_ms": 0,
                    "time_week": 0,
                    "fix_type": 1,
                    "lat": 0,
                    "lon": 0,
                    "alt": 0.0,
                    "hdop": 99.0,
                    "vdop": 99.0,
                    "vn": 0.0,
                    "ve": 0.0,
                    "vd": 0.0,
                    "speed_accuracy": 0.0,
                    "horiz_accuracy": 0.0,
                    "vert_accuracy": 0.0,
                    "satellites_visible": 0,
                },
            )
            time.sleep(0.001)

    def text():
        while time.time() < stop_at:
            link.queue("STATUSTEXT", {"severity": m.MAV_SEVERITY_INFO, "text": b"skyfix"})
            time.sleep(0.002)

    got = []
    try:
        link.open()
        threads = [threading.Thread(target=gps), threading.Thread(target=text)]
        for th in threads:
            th.start()
        got = _collect(rx, 3.0)
        for th in threads:
            th.join()
    finally:
        link.close()
        rx.close()
    kinds = [msg.get_type() for msg in got]
    assert kinds.count("BAD_DATA") == 0, f"{kinds.count('BAD_DATA')} refused of {len(kinds)}"
    assert (
        kinds.count("GPS_INPUT") > 100
        and kinds.count("STATUSTEXT") > 100
        and kinds.count("HEARTBEAT") >= 2
    )


@pytest.mark.parametrize("content", [b"short", b"x" * 33, b"zz" * 32])
def test_signing_key_file_must_hold_32_bytes(tmp_path, content):
    path = tmp_path / "k"
    path.write_bytes(content)
    with pytest.raises(ConfigError, match="32 raw bytes or 64 hex digits"):
        read_signing_key(str(path))


def test_the_rate_holds_while_the_event_loop_is_blocked():
    """The event loop blocked for 1.5 s (a long step on a loaded machine): GPS_INPUT still arrives at its rate
    (no gap over ArduPilot's 245 ms), and the last fix, once older than max_age_s, goes out as no fix."""
    port = free_port()
    rx = GpsInputEndpoint(port)

    async def blocked() -> tuple[float, float]:
        sink = GpsInputSink(mavlink_gps_link(f"udpout:127.0.0.1:{port}"), hz=10.0, max_age_s=0.5)
        task = asyncio.create_task(sink.run())
        t_give_up = time.time() + 10.0
        while (
            sink.gate.status(time.time())["accepted"] < 5 and time.time() < t_give_up
        ):  # confirmed over a second
            t = time.time()
            sink.on_fix(_fix(t), type("I", (), {"t_recv": t})())
            await asyncio.sleep(1 / 30)  # fixes at a camera's 30 fps
        t_block = time.time()
        time.sleep(1.5)  # noqa: ASYNC251 - the stimulus: nothing else runs on the loop meanwhile
        t_unblock = time.time()
        await sink.stop()
        await task
        return t_block, t_unblock

    try:
        t_block, t_unblock = asyncio.run(blocked())
        wait_for(lambda: rx.received and rx.received[-1][1]["fix_type"] == 1, 5, "the last no-fix")
    finally:
        rx.close()
    during = [(t, g["fix_type"]) for t, g in rx.received if t_block <= t <= t_unblock]
    t_all = [t for t, _ in rx.received if t_block - 0.2 <= t <= t_unblock]
    # up to the end of the block: silence at its end is a gap too
    gaps_ms = np.diff([*t_all, t_unblock]) * 1000
    print(
        f"{len(during)} GPS_INPUT while the loop was blocked for {t_unblock - t_block:.2f} s; max gap "
        f"{gaps_ms.max():.0f} ms; fix_types {[ft for _, ft in during]}"
    )
    assert len(during) >= 12 and gaps_ms.max() <= 245
    valid_until = max(t for t, ft in during if ft == 3)
    assert {ft for t, ft in during if t > t_block + 0.5 + 0.15} == {1}, (
        "a fix older than max_age_s sent as valid"
    )
    assert valid_until >= t_block + 0.2, "valid fixes should have been repeated until they aged out"


def test_a_failing_keep_alive_restarts_and_says_so(caplog):
    """The keep-alive thread failing (a bug: here its first two sends) is one log line, restarts with back-off and
    keeps sending; the sink's status counts the restarts and names the failure."""
    port = free_port()
    rx = GpsInputEndpoint(port)
    link = mavlink_gps_link(f"udpout:127.0.0.1:{port}")
    real_send, failures = link.send, [2]

    def send(kind: str, fields: dict) -> bool:
        if threading.current_thread().name == "GPS_INPUT keep-alive" and failures[0]:
            failures[0] -= 1
            raise KeyError("a bug in the keep-alive")
        return real_send(kind, fields)

    link.send = send

    async def run() -> dict:
        sink = GpsInputSink(link, hz=10.0, max_age_s=0.5)
        # no fixes: every GPS_INPUT before the stop is the keep-alive's
        task = asyncio.create_task(sink.run())
        await asyncio.to_thread(
            wait_for, lambda: len(rx.received) >= 5, 20, "GPS_INPUT after the restarts"
        )
        status = sink.status(time.time())
        await sink.stop()
        await task
        return status

    try:
        with caplog.at_level(logging.INFO, logger="skyfix"):
            status = asyncio.run(run())
    finally:
        rx.close()
    failed = [r.getMessage() for r in caplog.records if "thread failed" in r.getMessage()]
    print(
        f"status: {status['keep_alive_restarts']} restarts, {status['keep_alive_failure']}; log: {failed}"
    )
    assert status["keep_alive_restarts"] == 2 and "KeyError" in status["keep_alive_failure"]
    assert "a bug in the keep-alive" in status["keep_alive_failure"]
    assert len(failed) == 1 and "GPS_INPUT keep-alive" in failed[0]
    assert status["sent"] >= 5 and {g["fix_type"] for _, g in rx.received} == {1}

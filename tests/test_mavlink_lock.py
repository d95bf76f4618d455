"""A ``udpin:`` MAVLink link takes its autopilot's datagrams only: it locks to the first sender whose datagram holds
the vehicle's messages (or to ``--mavlink-peer``) and counts the rest unread; with a signing key it takes only
messages signed with it. Real sockets on loopback, real pymavlink frames."""

from __future__ import annotations

import select
import socket
import threading

from live_helpers import free_port, wait_for
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from groundstation.mavlink.link import MavlinkLink
from groundstation.mavlink.transport import open_transport


def heartbeat(system: int, key: bytes | None = None, timestamp: int = 1) -> bytes:
    """An ArduSub autopilot's HEARTBEAT from ``system`` (signed with ``key`` when given, at ``timestamp``)."""
    mav = mavlink2.MAVLink(None, srcSystem=system, srcComponent=1)
    if key is not None:
        s = mav.signing
        s.secret_key, s.sign_outgoing, s.link_id, s.timestamp = key, True, 1, timestamp
    msg = mav.heartbeat_encode(
        mavlink2.MAV_TYPE_SUBMARINE, mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 4
    )
    return msg.pack(mav)


def sender() -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    return s


def read_one(t) -> bytes:
    assert select.select(t.filenos(), [], [], 10.0)[0], "no datagram within 10 s"
    return t.read()


def test_udpin_locks_to_the_sender_it_answers_and_drops_the_rest():
    port = free_port()
    autopilot, forger = sender(), sender()
    t = open_transport(f"udpin:127.0.0.1:{port}")
    try:
        autopilot.sendto(b"first", ("127.0.0.1", port))
        assert read_one(t) == b"first"
        t.answer_last_sender()
        forger.sendto(b"forged", ("127.0.0.1", port))
        assert read_one(t) == b"" and t.foreign == 1
        autopilot.sendto(b"again", ("127.0.0.1", port))
        assert read_one(t) == b"again" and t.dest == autopilot.getsockname()
    finally:
        t.close()


def test_a_given_peer_is_the_only_sender_from_the_start():
    port = free_port()
    autopilot, forger = sender(), sender()
    host, aport = autopilot.getsockname()
    t = open_transport(f"udpin:127.0.0.1:{port}", peer=f"{host}:{aport}")
    try:
        forger.sendto(b"forged", ("127.0.0.1", port))
        assert read_one(t) == b"" and t.foreign == 1
        autopilot.sendto(b"mine", ("127.0.0.1", port))
        assert read_one(t) == b"mine"
        t.answer_last_sender()  # never another: a given peer is not replaced
        forger.sendto(b"forged", ("127.0.0.1", port))
        assert read_one(t) == b"" and t.foreign == 2 and t.dest == (host, aport)
    finally:
        t.close()


def _link(port: int, **kw) -> tuple[MavlinkLink, list]:
    got: list = []
    lock = threading.Lock()

    def on_message(msg, t):
        with lock:
            got.append((msg.get_type(), msg.get_srcSystem(), getattr(msg, "reason", "")))

    link = MavlinkLink(
        f"udpin:127.0.0.1:{port}",
        245,
        190,
        name="test link",
        on_message=on_message,
        is_peer=lambda m: m.get_type() == "HEARTBEAT" and m.get_srcSystem() == 1,
        **kw,
    )
    link.open()
    return link, got


def test_a_forged_autopilot_on_another_address_is_not_heard():
    port = free_port()
    autopilot, forger = sender(), sender()
    link, got = _link(port)
    try:
        autopilot.sendto(heartbeat(1), ("127.0.0.1", port))
        wait_for(lambda: link.status(0)["peer"] is not None, 10, "the lock")
        for _ in range(3):
            forger.sendto(heartbeat(1), ("127.0.0.1", port))
        wait_for(
            lambda: link.status(0)["foreign_datagrams"] == 3,
            10,
            lambda: f"3 foreign datagrams: {link.status(0)}",
        )
        autopilot.sendto(heartbeat(1), ("127.0.0.1", port))
        wait_for(lambda: len(got) == 2, 10, lambda: f"the autopilot's second heartbeat: {got}")
        status = link.status(0)
    finally:
        link.close()
    assert (
        status["peer"] == "{}:{}".format(*autopilot.getsockname())
        and status["foreign_datagrams"] == 3
    ), status
    assert got == [("HEARTBEAT", 1, "")] * 2


def test_a_link_that_requires_signing_takes_only_signed_messages():
    key = bytes(range(32))
    port = free_port()
    autopilot = sender()
    link, got = _link(port, signing_key=key, require_signed=True)
    try:
        autopilot.sendto(heartbeat(1), ("127.0.0.1", port))
        autopilot.sendto(heartbeat(1, bytes(32)), ("127.0.0.1", port))  # another key
        # (pymavlink took the forged one's time)
        autopilot.sendto(heartbeat(1, key, 2), ("127.0.0.1", port))
        wait_for(lambda: len(got) == 3, 10, lambda: f"3 messages: {got}")
        status = link.status(0)
    finally:
        link.close()
    assert [g[0] for g in got] == ["BAD_DATA", "BAD_DATA", "HEARTBEAT"], got
    assert status["signed"] and status["peer"] == "{}:{}".format(*autopilot.getsockname())

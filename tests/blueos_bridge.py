"""A stand-in for BlueOS's mavlink-server between an autopilot's MAVLink (a TCP port of ArduSub SITL) and Zenoh.

As mavlink-server does (bluerobotics/mavlink-server, ``src/lib/drivers/zenoh/json.rs``): every message the
autopilot sends is put as JSON on ``mavlink/{system}/{component}/{MESSAGE}`` (encoding ``application/json``)
in rust-mavlink's serde shape — ``{"header": {"system_id", "component_id", "sequence"}, "message": {"type":
NAME, field: value, ...}}``, enums as ``{"type": "ENUM_ENTRY"}``, bitmasks as ``{"bits": N}``, char arrays as
strings, HEARTBEAT's ``type`` field named ``mavtype`` — and every JSON message put on ``mavlink/in`` is
packed with its header's system and component and written to the autopilot. (The per-field keys
``.../{MESSAGE}/{field}`` and ``mavlink/out`` are left out: skyfix does not read them.)

Run as a script: ``python blueos_bridge.py tcp:127.0.0.1:PORT ZENOH_ENDPOINT``; it connects to the Zenoh
endpoint (a skyfix listening on it) and to the autopilot, retrying both, until SIGINT/SIGTERM.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import sys
import threading

os.environ.setdefault("MAVLINK20", "1")

import zenoh
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

RENAMED = {"type": "mavtype"}  # rust-mavlink's names for fields that are Rust keywords


def to_json(msg) -> dict:
    """One pymavlink message as mavlink-server's JSON object (header and message)."""
    enums, displays = msg.fieldenums_by_name, msg.fielddisplays_by_name
    fields = {"type": msg.get_type()}
    for name in msg.get_fieldnames():
        value = getattr(msg, name)
        if isinstance(value, bytes):
            value = value.decode(errors="replace")
        if displays.get(name) == "bitmask":
            value = {"bits": value}
        elif name in enums and isinstance(value, int):
            entry = mavlink2.enums.get(enums[name], {}).get(value)
            value = {"type": entry.name if entry is not None else str(value)}
        fields[RENAMED.get(name, name)] = value
    header = {
        "system_id": msg.get_srcSystem(),
        "component_id": msg.get_srcComponent(),
        "sequence": msg.get_seq(),
    }
    return {"header": header, "message": fields}


def from_json(obj: dict):
    """A mavlink-server JSON message (as skyfix puts on ``mavlink/in``) as ``(pymavlink message, sys, comp)``."""
    header, fields = obj["header"], dict(obj["message"])
    kind = fields.pop("type")
    cls = getattr(mavlink2, f"MAVLink_{kind.lower()}_message")
    renamed = {v: k for k, v in RENAMED.items()}
    args = {}
    for name, value in fields.items():
        name = renamed.get(name, name)
        if isinstance(value, dict) and "bits" in value:
            value = value["bits"]
        elif isinstance(value, dict) and "type" in value:
            value = getattr(mavlink2, value["type"])
        elif isinstance(value, str):
            value = value.encode()
        args[name] = value
    return cls(**args), header["system_id"], header["component_id"]


def main(url: str, endpoint: str) -> None:
    host, port = url.removeprefix("tcp:").rsplit(":", 1)
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    session = zenoh.open(conf)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    lock = threading.Lock()
    conn: dict = {"sock": None}
    packers: dict[tuple[int, int], mavlink2.MAVLink] = {}
    counts = {"to_zenoh": 0, "to_autopilot": 0, "bad_in": 0}

    def on_in(sample) -> None:  # Zenoh's thread: decode and write (a short TCP send on loopback)
        try:
            msg, sysid, compid = from_json(json.loads(sample.payload.to_bytes()))
        except (ValueError, KeyError, TypeError, AttributeError) as e:
            counts["bad_in"] += 1
            print(f"bridge: mavlink/in: not a message: {e!r}", flush=True)
            return
        with lock:
            packer = packers.setdefault(
                (sysid, compid), mavlink2.MAVLink(None, srcSystem=sysid, srcComponent=compid)
            )
            if conn["sock"] is not None:
                try:
                    conn["sock"].sendall(msg.pack(packer))
                    counts["to_autopilot"] += 1
                except OSError:
                    pass

    sub = session.declare_subscriber("mavlink/in", on_in)
    parser = mavlink2.MAVLink(None)
    parser.robust_parsing = True
    try:
        while not stop.is_set():
            try:
                sock = socket.create_connection((host, int(port)), timeout=2.0)
            except OSError:
                stop.wait(0.2)
                continue
            sock.settimeout(0.5)
            with lock:
                conn["sock"] = sock
            print(f"bridge: connected to {url}", flush=True)
            while not stop.is_set():
                try:
                    data = sock.recv(65536)
                except TimeoutError:
                    continue
                except OSError:
                    break
                if not data:
                    break
                for msg in parser.parse_buffer(data) or ():
                    if msg.get_type() == "BAD_DATA":
                        continue
                    obj = to_json(msg)
                    key = f"mavlink/{msg.get_srcSystem()}/{msg.get_srcComponent()}/{msg.get_type()}"
                    session.put(key, json.dumps(obj), encoding=zenoh.Encoding.APPLICATION_JSON)
                    counts["to_zenoh"] += 1
            with lock:
                conn["sock"] = None
            sock.close()
    finally:
        print(f"bridge: stopped {json.dumps(counts)}", flush=True)
        sub.undeclare()
        session.close()


if __name__ == "__main__":
    main(*sys.argv[1:3])

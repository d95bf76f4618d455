"""``uav.tlog``: the UAV's MAVLink as recorded, each frame with its record time (pymavlink's tlog format).

Read once here for everything that reads a session: the session reader, the replay, the benches; its
record written by :func:`tlog_record` for everything that writes one: the live recorder, ``skyfix sim``
and ``skyfix import``.
"""

from __future__ import annotations

import struct
from pathlib import Path

from groundstation.mavlink.ingest import mavutil
from groundstation.session import SessionError


def read_tlog(path: Path, warnings: list[str] | None = None) -> list[tuple[float, object]]:
    """``(record time UNIX s, message)`` of every decodable frame, in file order (ArduPilot's dialect).

    Undecodable frames are skipped, counted in one line appended to ``warnings``; a missing file is a
    :class:`SessionError`, one without a decodable frame an empty list (the caller says what it lacks).
    """
    if not path.is_file():
        raise SessionError(f"{path}: missing (the UAV's telemetry is required)")
    conn = mavutil().mavlink_connection(str(path), dialect="ardupilotmega", robust_parsing=True)
    out, bad = [], 0
    try:
        while True:
            try:
                m = conn.recv_msg()
            except Exception:  # noqa: BLE001 - pymavlink raises assorted errors on corrupt records
                bad += 1
                continue
            if m is None:
                break
            if m.get_type() == "BAD_DATA":
                bad += 1
                continue
            out.append((m._timestamp, m))
    finally:
        conn.close()
    if bad and warnings is not None:
        warnings.append(f"{path}: {bad} undecodable MAVLink frames skipped")
    return out


def tlog_record(t_unix_us: int, frame: bytes) -> bytes:
    """One record: the record time (UNIX µs, a big-endian uint64) and one MAVLink frame."""
    return struct.pack(">Q", t_unix_us) + frame

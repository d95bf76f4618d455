"""Replay's re-timing of MAVLink: SYSTEM_TIME shifted with the record times, everything else byte for byte."""

from __future__ import annotations

from groundstation.mavlink_io import mavutil
from groundstation.replay import frame_bytes


def _decode(buf: bytes):
    mav = mavutil().mavlink.MAVLink(None)
    msgs = mav.parse_buffer(buf)
    assert len(msgs) == 1
    return msgs[0]


def test_system_time_is_shifted_and_others_are_untouched():
    mav = mavutil().mavlink.MAVLink(None, srcSystem=3, srcComponent=1)
    mav.seq = 41
    st = _decode(mav.system_time_encode(1_763_800_000_250_000, 412_000).pack(mav))
    att_buf = mav.attitude_encode(412_000, 0.1, 0.2, 0.3, 0, 0, 0).pack(mav)
    att = _decode(att_buf)

    out = _decode(frame_bytes(st, 1000.5))
    assert out.time_unix_usec == 1_763_800_000_250_000 + 1_000_500_000
    assert out.time_boot_ms == 412_000
    assert (out.get_srcSystem(), out.get_srcComponent(), out.get_seq()) == (3, 1, 41)
    assert frame_bytes(att, 1000.5) == att_buf
    assert _decode(frame_bytes(_decode(mav.system_time_encode(0, 5).pack(mav)), 10.0)).time_unix_usec == 0

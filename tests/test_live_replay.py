"""Replay's re-timing of MAVLink: the UNIX times in it (SYSTEM_TIME, GPS_RAW_INT, TIMESYNC replies' ts1) shifted
with the record times, boot times and everything else byte for byte."""

from __future__ import annotations

from groundstation.mavlink.ingest import mavutil
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


def test_timesync_replies_and_gps_time_are_shifted_but_requests_and_boot_times_are_not():
    mav = mavutil().mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    reply = _decode(mav.timesync_encode(412_045_000_000, 1_763_800_000_123_456_789).pack(mav))
    out = _decode(frame_bytes(reply, 1000.5))
    assert out.ts1 == 1_763_800_000_123_456_789 + 1_000_500_000_000 and out.tc1 == 412_045_000_000
    request = mav.timesync_encode(0, 412_000_000_000).pack(mav)  # the autopilot's own request: its clock
    assert frame_bytes(_decode(request), 1000.5) == request
    gps = _decode(mav.gps_raw_int_encode(1_763_800_000_250_000, 3, 1, 2, 3, 70, 100, 0, 0, 14).pack(mav))
    assert _decode(frame_bytes(gps, 2.0)).time_usec == 1_763_800_002_250_000
    boot_stamped = mav.gps_raw_int_encode(412_000_000, 3, 1, 2, 3, 70, 100, 0, 0, 14).pack(mav)  # ArduPilot's
    assert frame_bytes(_decode(boot_stamped), 2.0) == boot_stamped

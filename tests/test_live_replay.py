"""Replay's re-timing of MAVLink: the UNIX times in it (SYSTEM_TIME, GPS_RAW_INT, TIMESYNC replies' ts1) shifted
with the record times, boot times and everything else byte for byte. Its UUV endpoint's log: each GPS_INPUT stamped
with its arrival, however late the replay reads it."""

from __future__ import annotations

import signal
import time

from live_helpers import ROOT, free_port, read_jsonl, skyfix, start, stop, wait_for

from groundstation.mavlink.ingest import mavutil
from groundstation.session.replay import frame_bytes


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
    assert (
        _decode(frame_bytes(_decode(mav.system_time_encode(0, 5).pack(mav)), 10.0)).time_unix_usec
        == 0
    )


def test_timesync_replies_and_gps_time_are_shifted_but_requests_and_boot_times_are_not():
    mav = mavutil().mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    reply = _decode(mav.timesync_encode(412_045_000_000, 1_763_800_000_123_456_789).pack(mav))
    out = _decode(frame_bytes(reply, 1000.5))
    assert out.ts1 == 1_763_800_000_123_456_789 + 1_000_500_000_000 and out.tc1 == 412_045_000_000
    # the autopilot's own request: its clock
    request = mav.timesync_encode(0, 412_000_000_000).pack(mav)
    assert frame_bytes(_decode(request), 1000.5) == request
    gps = _decode(
        mav.gps_raw_int_encode(1_763_800_000_250_000, 3, 1, 2, 3, 70, 100, 0, 0, 14).pack(mav)
    )
    assert _decode(frame_bytes(gps, 2.0)).time_usec == 1_763_800_002_250_000
    # ArduPilot's
    boot_stamped = mav.gps_raw_int_encode(412_000_000, 3, 1, 2, 3, 70, 100, 0, 0, 14).pack(mav)
    assert frame_bytes(_decode(boot_stamped), 2.0) == boot_stamped


def test_the_uuv_log_stamps_a_gps_input_with_its_arrival_while_the_replay_is_held(tmp_path):
    """The replay's UUV endpoint (``--uuv-listen udpin:``) held — the process stopped (SIGSTOP), a loaded machine's
    reader at its worst — while a GPS_INPUT arrives: ``--uuv-log`` stamps it with the time the kernel received it,
    not with when the replay read it."""
    port = free_port()
    log = tmp_path / "uuv.jsonl"
    replay = start(
        skyfix(
            "replay",
            str(ROOT / "sim_fixtures" / "bundled" / "nadir_hover"),
            "--no-video",
            "--mavlink-out",
            f"udpout:127.0.0.1:{free_port()}",
            "--uuv-listen",
            f"udpin:127.0.0.1:{port}",
            "--uuv-log",
            str(log),
            "--lead-s",
            "0.2",
            "--duration-s",
            "60",
        ),
        tmp_path / "replay.log",
    )
    sender = mavutil().mavlink_connection(
        f"udpout:127.0.0.1:{port}", source_system=245, source_component=220
    )

    def gps_input(week_ms: int) -> None:
        sender.mav.gps_input_send(
            0, 0, 0, week_ms, 2300, 1, 0, 0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 0, 0
        )

    def logged(week_ms: int) -> list[dict]:
        return [
            r
            for r in read_jsonl(log)
            if r.get("event") == "gps_input" and r["time_week_ms"] == week_ms
        ]

    try:
        # the socket is bound
        wait_for(lambda: gps_input(1) or logged(1), 30, "the replay listening")
        replay.send_signal(signal.SIGSTOP)
        t_before = time.time()
        gps_input(2)  # on loopback the datagram is in the replay's socket queue when sendto returns
        t_after = time.time()
        replay.send_signal(signal.SIGCONT)
        wait_for(lambda: logged(2), 30, "the GPS_INPUT sent while the replay was stopped")
    finally:
        replay.send_signal(signal.SIGCONT)
        stop(replay)
        sender.close()
    t_recv = logged(2)[0]["t_recv"]
    print(
        f"logged t_recv {(t_recv - t_before) * 1e3:+.3f} ms after the send began ({(t_after - t_before) * 1e3:.3f} ms "
        "to send)"
    )
    assert t_before - 1e-6 <= t_recv <= t_after + 1e-6, "t_recv is not the datagram's arrival"

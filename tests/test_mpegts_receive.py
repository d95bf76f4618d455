"""skyfix's own MPEG-TS depacketizer against real MPEG-TS from FFmpeg's muxer (PyAV, sent to a loopback socket in
1316-byte datagrams, each frame flushed as a camera sends it): every access unit decodes to exactly the frame FFmpeg
decodes from the file; every frame is handed over by its own last datagram — the keyframes above 64 KiB too, whose
PES cannot state its length (FFmpeg's demuxer holds those until the next frame starts) — with the muxer stating
the lengths it can, and with none stated (FFmpeg's default); a lost datagram loses its frame and the frames up to
the next keyframe, never a damaged picture; garbage is counted and ignored."""

from __future__ import annotations

import random
import subprocess

import av
import numpy as np
import pytest
from datagram_capture import mux_to_datagrams

from groundstation.video.mpegts import TS_BYTES, TsDepacketizer

FRAMES, GOP = 45, 15
# the muxer's PES lengths: stated where they fit 16 bits (as skyfix replay sends), or never (FFmpeg's default)
VARIANTS = {"lengths": {"omit_video_pes_length": "0"}, "no-lengths": {"omit_video_pes_length": "1"}}


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    """A 1280x720 H.264 clip whose keyframes are above 64 KiB (a fine quantiser on a busy test pattern)."""
    path = tmp_path_factory.mktemp("ts") / "clip.ts"
    subprocess.run(
        [
            "ffmpeg",
            "-v",
            "error",
            "-y",
            "-f",
            "lavfi",
            "-i",
            "testsrc2=size=1280x720:rate=30",
            "-t",
            str(FRAMES / 30),
            "-c:v",
            "libx264",
            "-tune",
            "zerolatency",
            "-preset",
            "ultrafast",
            "-qp",
            "12",
            "-g",
            str(GOP),
            "-pix_fmt",
            "yuv420p",
            "-f",
            "mpegts",
            str(path),
        ],
        check=True,
        timeout=120,
    )
    return path


@pytest.fixture(scope="module", params=list(VARIANTS))
def stream(request, clip):
    """(variant, the datagrams FFmpeg's MPEG-TS muxer sends, the index after each frame's last datagram, each
    frame's size)."""
    datagrams, ends, sizes = mux_to_datagrams(
        clip, "udp", "mpegts", {**VARIANTS[request.param], "flush_packets": "1"}, "?pkt_size=1316"
    )
    return request.param, datagrams, ends, sizes


def _reference(clip) -> dict[int, np.ndarray]:
    with av.open(str(clip)) as c:
        return {f.pts: f.to_ndarray(format="gray") for f in c.decode(c.streams.video[0])}


def _decode(units) -> list[tuple[int, np.ndarray]]:
    ctx = av.CodecContext.create("h264", "r")
    out = []
    for u in units:
        packet = av.Packet(u.data)
        packet.pts = u.timestamp
        out += [(f.pts, f.to_ndarray(format="gray")) for f in ctx.decode(packet)]
    return out


def _push(datagrams, keep=lambda i: True) -> tuple[TsDepacketizer, list, list[int]]:
    """The depacketizer after all datagrams, its units, and the index of the datagram that completed each."""
    d, units, at = TsDepacketizer(), [], []
    for i, g in enumerate(datagrams):
        if keep(i):
            got = d.push(g)
            units += got
            at += [i] * len(got)
    return d, units, at


def test_every_frame_decodes_to_the_files_and_comes_with_its_own_last_datagram(stream, clip):
    variant, datagrams, ends, sizes = stream
    assert max(sizes) > 65535  # keyframes whose PES cannot state its length
    d, units, at = _push(datagrams)
    assert d.codec == "h264" and len(units) == FRAMES
    assert d.lost_packets == d.dropped_units == d.bad_packets == 0
    assert [u.keyframe for u in units] == [i % GOP == 0 for i in range(FRAMES)]
    # frame k is complete by its own last datagram, never waiting for frame k+1's first
    assert [a < end for a, end in zip(at, ends, strict=True)] == [True] * FRAMES, (
        variant,
        at,
        ends,
    )
    reference = _reference(clip)
    decoded = _decode(units)
    assert [p for p, _ in decoded] == sorted(reference)  # the PTS as the file's
    for pts, image in decoded:
        assert np.array_equal(image, reference[pts])


def test_a_lost_datagram_loses_frames_up_to_the_next_keyframe_never_a_damaged_one(stream, clip):
    _, datagrams, ends, _ = stream
    lost = ends[19] + 1  # the second datagram of frame 20 (not a keyframe; 15 and 30 are)
    d, units, _ = _push(datagrams, keep=lambda i: i != lost)
    _, whole, _ = _push(datagrams)
    pts = [u.timestamp for u in whole]
    assert [pts.index(u.timestamp) for u in units] == list(range(20)) + list(range(30, FRAMES))
    assert d.lost_packets == (len(datagrams[lost]) // TS_BYTES) and d.dropped_units == 10
    reference = _reference(clip)
    for p, image in _decode(units):
        assert np.array_equal(image, reference[p])


def test_garbage_is_counted_and_the_stream_read_through_it(stream):
    _, datagrams, _, _ = stream
    rng = random.Random(7)
    d, units = TsDepacketizer(), []
    for g in datagrams:
        junk = rng.randbytes(rng.randint(1, 400))
        assert d.push(junk if len(junk) % TS_BYTES else junk + b"x") == []
        units += d.push(g)
    assert d.bad_packets == len(datagrams) and len(units) == FRAMES


def test_a_program_without_h264_or_h265_is_named(tmp_path):
    clip = tmp_path / "mpeg2.ts"
    subprocess.run(
        [
            "ffmpeg",
            "-v",
            "error",
            "-y",
            "-f",
            "lavfi",
            "-i",
            "testsrc=size=160x120:rate=10",
            "-t",
            "1",
            "-c:v",
            "mpeg2video",
            "-f",
            "mpegts",
            str(clip),
        ],
        check=True,
        timeout=60,
    )
    d = TsDepacketizer()
    data = clip.read_bytes()
    for i in range(0, len(data), 7 * TS_BYTES):
        d.push(data[i : i + 7 * TS_BYTES])
    assert d.codec is None and d.unreadable is not None and "0x02" in d.unreadable


def test_the_33_bit_pts_is_unwrapped():
    d = TsDepacketizer()
    assert [d._unwrap(p) for p in ((1 << 33) - 3000, 0, 3000)] == [
        (1 << 33) - 3000,
        1 << 33,
        (1 << 33) + 3000,
    ]

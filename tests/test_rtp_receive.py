"""skyfix's own RTP depacketizer against real RTP from FFmpeg's muxer (PyAV, sent to a loopback socket):
every access unit decodes to exactly the frame FFmpeg decodes from the file; the packet kinds a camera
sends all occur (single NAL units, aggregation, fragments); a lost packet loses its frame and the
frames up to the next keyframe, never a damaged picture; garbage and other payload types are counted
and ignored."""

from __future__ import annotations

import random
import subprocess

import av
import numpy as np
import pytest
from datagram_capture import mux_to_datagrams

from groundstation.video.rtp import Depacketizer

ENCODERS = {
    "h264": ["libx264", "-tune", "zerolatency", "-x264-params", "slices=4"],
    "h265": ["libx265", "-x265-params", "bframes=0:log-level=error"],
}
# FFmpeg's RTP muxer aggregates what fits a datagram; in packetization mode 0 it sends each NAL unit
# alone (as GStreamer's payloader does with small slices), so the slices are kept under a datagram
VARIANTS = {
    "h264": ("h264", {}),
    "h264-single-nal": ("h264", {"rtpflags": "h264_mode0"}),
    "h265": ("h265", {}),
}


@pytest.fixture(scope="module", params=list(VARIANTS))
def stream(request, tmp_path_factory):
    """(codec, clip path, the RTP datagrams FFmpeg's muxer makes of it, in order)."""
    codec, options = VARIANTS[request.param]
    encoder = ENCODERS[codec]
    if options:
        encoder = ["libx264", "-tune", "zerolatency", "-x264-params", "slice-max-size=1000"]
    clip = tmp_path_factory.mktemp("rtp") / f"{request.param}.ts"
    subprocess.run(
        [
            "ffmpeg",
            "-v",
            "error",
            "-y",
            "-f",
            "lavfi",
            "-i",
            "testsrc=size=320x240:rate=30",
            "-t",
            "2",
            "-c:v",
            *encoder,
            "-preset",
            "ultrafast",
            "-g",
            "15",
            "-pix_fmt",
            "yuv420p",
            "-f",
            "mpegts",
            str(clip),
        ],
        check=True,
        timeout=120,
    )
    datagrams, _, _ = mux_to_datagrams(clip, "rtp", "rtp", options)
    return codec, clip, request.param, datagrams


def _reference(clip) -> dict[int, np.ndarray]:
    with av.open(str(clip)) as c:
        s = c.streams.video[0]
        return {round(f.time * 90000): f.to_ndarray(format="gray") for f in c.decode(s)}


def _decode(codec: str, units) -> list[tuple[int, np.ndarray]]:
    ctx = av.CodecContext.create("hevc" if codec == "h265" else "h264", "r")
    out = []
    for u in units:
        packet = av.Packet(u.data)
        packet.pts = u.timestamp
        for f in ctx.decode(packet):
            out.append((f.pts, f.to_ndarray(format="gray")))
    return out


def _units(codec: str, datagrams, keep=lambda i: True):
    d = Depacketizer(codec)
    units = [u for i, g in enumerate(datagrams) if keep(i) for u in d.push(g)]
    return d, units


def _kinds(codec: str, datagrams) -> set[str]:
    """The payload structures among the datagrams, read from their NAL headers here."""
    names = (
        {24: "aggregation", 28: "fragment"}
        if codec == "h264"
        else {48: "aggregation", 49: "fragment"}
    )
    kinds = set()
    for g in datagrams:
        header = g[12]
        t = header & 0x1F if codec == "h264" else (header >> 1) & 0x3F
        kinds.add(names.get(t, "single"))
    return kinds


def test_every_access_unit_decodes_to_the_files_frame(stream):
    codec, clip, variant, datagrams = stream
    assert _kinds(codec, datagrams) == (
        {"single"} if variant == "h264-single-nal" else {"aggregation", "fragment"}
    )
    d, units = _units(codec, datagrams)
    reference = _reference(clip)
    decoded = _decode(codec, units)
    assert (
        len(units) == len(reference) == 60
        and d.lost_packets == d.dropped_units == d.bad_packets == 0
    )
    first = units[0].timestamp
    ref_first = min(reference)
    assert [u.keyframe for u in units] == [i % 15 == 0 for i in range(60)]
    for pts, image in decoded:
        assert np.array_equal(image, reference[pts - first + ref_first])


def test_a_lost_packet_loses_frames_up_to_the_next_keyframe_never_a_damaged_one(stream):
    codec, clip, _, datagrams = stream
    _, whole = _units(codec, datagrams)
    # a datagram of the 20th frame (not a keyframe; 15 and 30 are) left out
    first = whole[0].timestamp
    ts = [int.from_bytes(g[4:8], "big") for g in datagrams]
    lost = ts.index(first + 20 * 3000 & 0xFFFFFFFF)
    d, units = _units(codec, datagrams, keep=lambda i: i != lost)
    frames = [(u.timestamp - first) // 3000 for u in units]
    assert frames == list(range(20)) + list(range(30, 60))
    partly_in = ts.count(ts[lost]) > 1  # frame 20 itself is a unit dropped when some of it came
    assert d.lost_packets == 1 and d.dropped_units == 9 + partly_in
    reference = _reference(clip)
    ref_first = min(reference)
    for pts, image in _decode(codec, units):
        assert np.array_equal(image, reference[pts - first + ref_first])


def test_garbage_and_other_payload_types_are_ignored(stream):
    codec, _, _, datagrams = stream
    rng = random.Random(5)
    other_pt = bytearray(datagrams[3])
    other_pt[1] = (other_pt[1] & 0x80) | 97
    noise = [bytes(other_pt)] + [rng.randbytes(rng.randint(0, 40)) for _ in range(199)]
    d = Depacketizer(codec)
    units = []
    for g in datagrams:
        for junk in noise[: rng.randint(0, 4)]:
            assert d.push(junk) == []
        noise = noise[4:] + noise[:4]
        units += d.push(g)
    # random bytes that look like RTP of this stream are rare
    assert d.bad_packets >= len(datagrams)
    assert len(units) == 60 and d.lost_packets == 0

"""Sending a video file live, as a camera would: each frame leaves when its time comes.

:func:`send_video` streams a file's video over UDP (MPEG-TS, or RTP with
``rtp://``) in-process with PyAV. A frame's *slot* is ``t0_unix`` plus its
presentation time after the first frame's; its packets leave at that slot, in
decoding order, never before the packet before them (a B-frame's reference goes
first and the B-frame right after it, as an encoder sends them). So the stream's
glass-to-first-packet latency is zero: ``--video-latency-ms 0`` is the truth for
a replay on one machine. H.264, HEVC and MPEG-2 are sent as they are (each PES
with its length, so a receiver hands a frame over as soon as it is in); other
codecs are re-encoded to H.264 (zero latency).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path

import av
import av.bitstream

COPY_CODECS = ("h264", "hevc", "mpeg2video")
# each PES with its length, and every frame's packets sent at once (not its tail held until the next frame's)
MPEGTS_OPTIONS = {"omit_video_pes_length": "0", "flush_packets": "1"}


def wait_until(t_unix: float, stop: threading.Event) -> bool:
    """Wait for a UNIX time; False if stopped first."""
    delay = t_unix - time.time()
    return not stop.wait(delay) if delay > 0 else not stop.is_set()


def _open_output(url: str):
    if url.startswith("rtp://"):
        return av.open(url, "w", format="rtp", options={"flush_packets": "1"})
    sep = "&" if "?" in url else "?"
    return av.open(f"{url}{sep}pkt_size=1316", "w", format="mpegts", options=MPEGTS_OPTIONS)


def _annexb_filter(stream, ost, out):
    """For RTP, H.264/H.265 from an MP4 (parameter sets only in the header) put in the stream before each
    keyframe, as cameras send them: a receiver without them in its session description (QGroundControl's
    convention, skyfix's own) cannot decode otherwise. None where nothing is to be done."""
    name = stream.codec_context.name
    extradata = stream.codec_context.extradata or b""
    if (
        out.format.name != "rtp"
        or name not in ("h264", "hevc")
        or not extradata.startswith(b"\x01")
    ):
        return None
    return av.bitstream.BitStreamFilterContext(f"{name}_mp4toannexb", stream, ost)


def _packets(container, stream, out):
    """``(pts seconds, packet for out)`` in decoding order: copied, or re-encoded to H.264."""
    tb = float(stream.time_base)
    if stream.codec_context.name in COPY_CODECS:
        ost = out.add_stream_from_template(stream)
        annexb = _annexb_filter(stream, ost, out)
        for packet in container.demux(stream):
            if packet.dts is None or packet.pts is None:
                continue
            for p in [packet] if annexb is None else annexb.filter(packet):
                p.stream = ost
                yield p.pts * tb, p
        return
    ost = out.add_stream("libx264", options={"preset": "ultrafast", "tune": "zerolatency"})
    ost.width, ost.height, ost.pix_fmt = (
        stream.codec_context.width,
        stream.codec_context.height,
        "yuv420p",
    )
    ost.codec_context.time_base = stream.time_base
    pts_s = 0.0
    for frame in container.decode(stream):
        if frame.pts is None:
            continue
        frame.pict_type = av.video.frame.PictureType.NONE
        pts_s = frame.pts * tb
        for packet in ost.encode(frame):
            yield pts_s, packet
    for packet in ost.encode(None):
        yield pts_s, packet


def send_video(
    path: Path,
    url: str,
    t0_unix: float,
    stop: threading.Event,
    skip: Callable[[float, bool], bool] | None = None,
) -> int:
    """Stream ``path`` to ``url`` so that its first frame leaves at ``t0_unix``; the number of packets sent.

    ``skip(t_s, keyframe)`` (seconds after the first frame, whether the packet starts a keyframe), when given,
    says which packets are left out (a cut link).
    """
    sent = 0
    with av.open(str(path)) as container, _open_output(url) as out:
        stream = container.streams.video[0]
        pts0 = None
        for pts_s, packet in _packets(container, stream, out):
            pts0 = pts_s if pts0 is None else pts0
            if not wait_until(t0_unix + pts_s - pts0, stop):
                break
            if skip is not None and skip(pts_s - pts0, packet.is_keyframe):
                continue
            out.mux(packet)
            sent += 1
    return sent

"""What ``--video`` names, as FFmpeg (PyAV) opens it: input, format, per-stream options.

| ``--video`` | kind | opened as |
|---|---|---|
| ``udp://HOST:PORT[?peer=…]`` | udp | MPEG-TS over UDP (a multicast group joined), depacketized by skyfix (:mod:`.mpegts`), decoded by FFmpeg |
| ``rtp://HOST:PORT?codec=h264\\|h265[&pt=96][&peer=…]`` | rtp | RTP without a session description (QGroundControl/BlueOS send H.264 RTP to 5600), depacketized by skyfix (:mod:`.rtp`), decoded by FFmpeg |
| ``zenoh:video/<source>/stream[?peer=ZID\\|any]`` | zenoh | BlueOS's camera manager's ``foxglove.CompressedVideo`` messages on the service's Zenoh session (:mod:`.zenoh_video`), decoded by FFmpeg |
| ``FILE.sdp`` | sdp | the RTP stream the file describes, live |
| ``rtsp://…[?transport=tcp\\|udp]`` | rtsp | RTSP, over TCP or UDP (default: FFmpeg tries UDP first) |
| ``/dev/videoN``, ``v4l2:N`` ``[?video_size=WxH&framerate=F&input_format=mjpeg]`` | v4l2 | a V4L2 camera |
| other ``scheme://`` | url | whatever FFmpeg opens, live |
| a path | file | a file, read once |

``udp://`` and ``rtp://`` take one sender (:mod:`groundstation.runtime.sender_lock`): the first whose datagram is
the stream's, or ``peer=HOST:PORT`` (the camera's source address), or every sender with ``peer=any``;
the others' datagrams are counted (the status's ``sender``), never read.

Every live kind is opened for low delay: the smallest probe (its packets are
kept, not dropped), no RTP reordering wait. A malformed
value is a :class:`~groundstation.video.file.VideoError` naming it.
"""

from __future__ import annotations

import errno
import ipaddress
import re
import socket
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import parse_qsl, urlencode, urlsplit, urlunsplit

from groundstation.runtime.sender_lock import ANY_PEER, parse_peer
from groundstation.video.frames import VideoError

# No "fflags nobuffer": it throws away the packets read while probing, and with them the
# keyframe a camera may not repeat for seconds; probing reads little with these limits.
# Format and protocol options only (the decoder's low delay is set on it): they go to
# av.open as container_options, since PyAV 16's per-stream options array overflows
# (segfault) when a stream appears while probing, as an MPEG-TS stream joined late does.
LOW_DELAY = {"probesize": "32", "analyzeduration": "0"}
RTP_OPTIONS = {"protocol_whitelist": "file,udp,rtp", "max_delay": "0", "reorder_queue_size": "0"}
RTP_CODECS = ("h264", "h265", "hevc")
V4L2_KEYS = ("video_size", "framerate", "input_format", "pixel_format", "standard")


@dataclass(frozen=True)
class VideoInput:
    """An input ready for ``av.open(file, format=format, container_options=options)``."""

    url: str  # as given
    kind: str  # udp, rtp, zenoh, sdp, rtsp, v4l2, url, file
    file: str
    format: str | None = None
    options: dict[str, str] = field(default_factory=dict)
    port: int | None = None  # the local UDP port it binds (udp, rtp), for "in use" messages
    # rtp: h264 or h265 (read by skyfix itself, :mod:`.rtp`; ``file`` the address)
    codec: str | None = None
    payload_type: int | None = None  # rtp
    # udp, rtp: the only sender taken (peer=HOST:PORT); zenoh: the Zenoh ID (hex) that time-stamps its messages
    peer: tuple[str, int] | str | None = None
    any_sender: bool = False  # udp, rtp, zenoh: peer=any, every sender taken

    @property
    def live(self) -> bool:
        return self.kind != "file"

    def port_in_use(self) -> bool:
        """Whether another program holds the UDP port this input listens on (RTCP's next port too, for RTP).

        Checked before FFmpeg binds: its failed bind is reported as another error.
        """
        ports = (
            ()
            if self.port is None
            else (self.port, self.port + 1)
            if self.kind == "sdp"
            else (self.port,)
        )
        for port in ports:
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
                try:
                    s.bind(("0.0.0.0", port))
                except OSError as e:
                    if e.errno == errno.EADDRINUSE:
                        return True
        return False


def _port(url: str, parts) -> int:
    try:
        port = parts.port
    except ValueError:
        port = None
    if port is None:
        raise VideoError(f"{url}: no port (expected {parts.scheme}://HOST:PORT)")
    return port


def _sender(url: str, query: dict[str, str]) -> dict:
    """The ``peer=`` option's fields of a :class:`VideoInput` (popped from ``query``)."""
    text = query.pop("peer", None)
    if text is None:
        return {}
    if text == ANY_PEER:
        return {"any_sender": True}
    try:
        return {"peer": parse_peer(text, "peer")}
    except ValueError as e:
        raise VideoError(f"{url}: {e}") from None


def _udp(url: str, parts, query: dict[str, str]) -> VideoInput:
    sender = _sender(url, query)
    if query:
        raise VideoError(
            f"{url}: unknown option {next(iter(query))} (udp:// takes peer only: skyfix reads the port itself)"
        )
    return VideoInput(
        url, "udp", parts.hostname or "0.0.0.0", None, {}, _port(url, parts), **sender
    )


def _rtp(url: str, parts, query: dict[str, str]) -> VideoInput:
    port = _port(url, parts)
    codec = query.pop("codec", "h264").lower()
    if codec not in RTP_CODECS:
        raise VideoError(f"{url}: codec={codec} is not one of {', '.join(RTP_CODECS)}")
    pt_text = query.pop("pt", "96")
    if not pt_text.isdigit() or not 96 <= int(pt_text) <= 127:
        raise VideoError(f"{url}: pt={pt_text} is not a dynamic RTP payload type (96 … 127)")
    sender = _sender(url, query)
    if query:
        raise VideoError(f"{url}: unknown option {next(iter(query))} (known: codec, pt, peer)")
    host = parts.hostname or "0.0.0.0"
    try:
        multicast = ipaddress.ip_address(host).is_multicast
    except ValueError:  # a host name: the address it is bound by
        multicast = False
    if multicast:
        raise VideoError(
            f"{url}: a multicast group: describe the stream in an .sdp file (FFmpeg joins the group)"
        )
    return VideoInput(
        url,
        "rtp",
        host,
        None,
        {},
        port,
        "h265" if codec == "hevc" else codec,
        int(pt_text),
        **sender,
    )


def _sdp_port(path: Path) -> int | None:
    match = re.search(r"^m=video (\d+)", path.read_text(errors="replace"), re.MULTILINE)
    return int(match.group(1)) if match else None


def _v4l2(url: str, device: str, query: dict[str, str]) -> VideoInput:
    unknown = [k for k in query if k not in V4L2_KEYS]
    if unknown:
        raise VideoError(f"{url}: unknown option {unknown[0]} (known: {', '.join(V4L2_KEYS)})")
    if "video_size" in query and not re.fullmatch(r"\d+x\d+", query["video_size"]):
        raise VideoError(f"{url}: video_size={query['video_size']} is not WIDTHxHEIGHT")
    if device.isdigit():
        device = f"/dev/video{device}"
    return VideoInput(url, "v4l2", device, "v4l2", {**LOW_DELAY, **query})


def _zenoh(url: str, key: str, query: dict[str, str]) -> VideoInput:
    """``zenoh:KEY[?peer=ZID|any]``: ``peer`` the Zenoh ID (hex) that time-stamps the camera's messages."""
    if not key or any(c in key for c in "*$#") or "//" in key or key.strip("/") != key:
        raise VideoError(
            f"{url}: {key!r} is not one Zenoh key (expected e.g. zenoh:video/<source>/stream)"
        )
    peer = query.pop("peer", None)
    if query:
        raise VideoError(f"{url}: unknown option {next(iter(query))} (zenoh: takes peer only)")
    if peer is not None and peer != ANY_PEER and not re.fullmatch(r"[0-9a-fA-F]{1,32}", peer):
        raise VideoError(f"{url}: peer={peer} is not a Zenoh ID (hex) or {ANY_PEER}")
    return VideoInput(
        url,
        "zenoh",
        key,
        peer=None if peer in (None, ANY_PEER) else peer.lower(),
        any_sender=peer == ANY_PEER,
    )


def parse_video_input(url: str) -> VideoInput:
    """The :class:`VideoInput` for a ``--video`` value (see the module doc)."""
    url = str(url)
    base, _, query_text = url.partition("?")
    query = dict(parse_qsl(query_text, keep_blank_values=True))
    if url.startswith("v4l2:"):
        return _v4l2(url, base.removeprefix("v4l2:"), query)
    if url.startswith("zenoh:"):
        return _zenoh(url, base.removeprefix("zenoh:"), query)
    if base.startswith("/dev/video"):
        return _v4l2(url, base, query)
    if "://" not in url:
        path = Path(url)
        if path.suffix.lower() == ".sdp":
            if not path.is_file():
                raise VideoError(f"{url}: missing")
            return VideoInput(url, "sdp", url, "sdp", {**LOW_DELAY, **RTP_OPTIONS}, _sdp_port(path))
        return VideoInput(url, "file", url)
    parts = urlsplit(url)
    scheme = parts.scheme.lower()
    if scheme == "udp":
        return _udp(url, parts, query)
    if scheme == "rtp":
        return _rtp(url, parts, query)
    if scheme in ("rtsp", "rtsps"):
        transport = query.pop("transport", None)
        options = dict(LOW_DELAY)
        if transport is not None:
            if transport not in ("tcp", "udp"):
                raise VideoError(f"{url}: transport={transport} is not tcp or udp")
            options["rtsp_transport"] = transport
        if transport != "tcp":
            options.update(max_delay="0", reorder_queue_size="0")
        file = urlunsplit(parts._replace(query=urlencode(query)))
        return VideoInput(url, "rtsp", file, "rtsp", options)
    return VideoInput(url, "url", url, None, dict(LOW_DELAY))

"""A UDP port whose video skyfix depacketizes itself, shaped as the PyAV container the live reader uses.

``udp://`` (MPEG-TS, :mod:`.mpegts`) and ``rtp://`` (:mod:`.rtp`) are read here so that a frame is
handed over as soon as its last packet is in (FFmpeg's demuxers wait for the next frame's start in
both cases, see those modules). :class:`DatagramInput` binds the port (joining a multicast group
when the address is one), feeds each datagram to its depacketizer, and :meth:`~DatagramInput.demux`
yields one ``av.Packet`` per whole access unit (``pts`` in 1/90 000 s); the decoder is FFmpeg's.
The codec is the depacketizer's: given for RTP, read from the PMT for MPEG-TS — the open waits
for it as FFmpeg's open waits for its probe, and raises ``TimeoutError`` after ``open_timeout_s``
(:class:`~groundstation.video.frames.VideoError` for a program without H.264/H.265 video).
Each datagram is read only when the input's :class:`~groundstation.runtime.sender_lock.SenderLock` admits its
sender; the lock is taken by the first sender whose datagram the depacketizer reads as the stream's (one
that adds to ``bad_packets`` does not lock), and is the caller's, kept across reconnections: a second
sender neither splices its packets into the stream nor takes the port over while the camera sends (a
camera silent for the read timeout has stopped: the next sender of the stream is taken, a relock).
"""

from __future__ import annotations

import ipaddress
import socket
import time
from collections import deque
from collections.abc import Iterator
from fractions import Fraction

import av

from groundstation.runtime.sender_lock import SenderLock
from groundstation.video.frames import VideoError
from groundstation.video.rtp import VIDEO_HZ, AccessUnit

DATAGRAM_BYTES = 65_536
SOCKET_BUFFER_BYTES = 4 << 20  # a 1080p keyframe comes as a burst of some 150 datagrams


class DecoderStream:
    """What :func:`packet_of` and the decoder loop need of a container's stream, for access units that come
    without one (RTP over UDP, BlueOS's Zenoh video): a decoder context of the codec, time in 1/90 000 s."""

    def __init__(self, codec: str):
        self.codec_context = av.CodecContext.create("hevc" if codec == "h265" else codec, "r")
        self.time_base = Fraction(1, VIDEO_HZ)


class DecoderStreams:
    """A stand-in for a container's ``streams``: its one video stream."""

    def __init__(self, stream: DecoderStream):
        self.video = [stream]


def packet_of(unit: AccessUnit, stream) -> av.Packet:
    """An access unit as the packet the decoder takes (``pts`` in the stream's 1/90 000 s)."""
    packet = av.Packet(unit.data)
    packet.pts = packet.dts = unit.timestamp
    packet.time_base = stream.time_base
    packet.is_keyframe = unit.keyframe
    return packet


def _bind(host: str, port: int) -> socket.socket:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, SOCKET_BUFFER_BYTES)
        try:
            multicast = ipaddress.ip_address(host).is_multicast
        except ValueError:  # a host name: the address it is bound by
            multicast = False
        if multicast:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            sock.bind(("", port))
            sock.setsockopt(
                socket.IPPROTO_IP,
                socket.IP_ADD_MEMBERSHIP,
                socket.inet_aton(host) + socket.inet_aton("0.0.0.0"),
            )
        else:
            sock.bind((host, port))
    except OSError:
        sock.close()
        raise
    return sock


class DatagramInput:
    """``host``:``port`` read through ``depacketizer`` (an :class:`~.rtp.Depacketizer` or
    :class:`~.mpegts.TsDepacketizer`: ``push(datagram)`` → access units, ``codec``, ``unreadable``), from the
    senders ``lock`` admits; see the module doc.
    :meth:`demux` raises ``TimeoutError`` when nothing came for ``read_timeout_s``."""

    def __init__(
        self,
        host: str,
        port: int,
        depacketizer,
        open_timeout_s: float,
        read_timeout_s: float,
        lock: SenderLock | None = None,
    ):
        self.depacketizer = depacketizer
        self.read_timeout_s = read_timeout_s
        self.lock = SenderLock() if lock is None else lock
        self._sock = _bind(host, port)
        self._units: deque = deque()
        try:
            deadline = time.monotonic() + open_timeout_s
            while depacketizer.codec is None:
                try:
                    self._receive(deadline)
                except TimeoutError:
                    raise TimeoutError(
                        f"no video stream described within {open_timeout_s:g} s"
                    ) from None
                if depacketizer.unreadable:
                    raise VideoError(depacketizer.unreadable)
        except BaseException:
            self._sock.close()
            raise
        self.streams = DecoderStreams(DecoderStream(depacketizer.codec))

    def demux(self, stream) -> Iterator[av.Packet]:
        while True:
            while self._units:
                yield packet_of(self._units.popleft(), stream)
            try:
                self._receive(time.monotonic() + self.read_timeout_s)
            except TimeoutError:
                raise TimeoutError(f"nothing received for {self.read_timeout_s:g} s") from None

    def _receive(self, deadline: float) -> None:
        """Read datagrams until one from an admitted sender (``TimeoutError`` when none came by ``deadline``,
        monotonic s); its access units. A datagram the depacketizer takes as the stream's locks its sender."""
        while True:
            self._sock.settimeout(max(0.001, deadline - time.monotonic()))
            datagram, addr = self._sock.recvfrom(DATAGRAM_BYTES)
            if self.lock.admits(addr):
                break
            if time.monotonic() > deadline:
                raise TimeoutError
        bad = self.depacketizer.bad_packets
        self._units.extend(self.depacketizer.push(datagram))
        if self.depacketizer.bad_packets == bad:
            self.lock.lock(addr)

    def close(self) -> None:
        self._sock.close()

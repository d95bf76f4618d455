"""H.264/H.265 over RTP (RFC 6184, RFC 7798), received by skyfix itself: a frame ends at its marker bit.

FFmpeg's RTP depacketizer ignores the marker bit that ends an access unit; its parser
then hands each frame over only when the next one starts, a frame interval (33 ms at
30 fps) later. For ``rtp://HOST:PORT?codec=h264|h265`` inputs (the QGroundControl/BlueOS
convention) skyfix reads the datagrams itself:

- :class:`Depacketizer`: RTP datagrams in, whole access units out (Annex B byte stream,
  the RTP timestamp unwrapped, whether it starts a keyframe) as soon as the packet with
  the marker bit is in. Single NAL units, aggregation (STAP-A, AP) and fragmentation
  (FU-A, FU) packets. A lost packet (a gap in the sequence numbers) loses its access
  unit and everything up to the next keyframe: frames decoded from a damaged picture
  would be tracked where the picture is wrong. Read from a UDP port by
  :class:`~groundstation.video.udp.DatagramInput`.

The stream's parameter sets must come in the stream (cameras repeat them before each
keyframe; there is no session description to carry them), as with FFmpeg's reading.
"""

from __future__ import annotations

from dataclasses import dataclass

START_CODE = b"\x00\x00\x00\x01"
VIDEO_HZ = 90_000  # the clock of RTP timestamps and MPEG-TS PTS of H.264/H.265 video


@dataclass
class AccessUnit:
    """One frame's NAL units as an Annex B byte stream; ``timestamp`` the RTP timestamp or MPEG-TS PTS, unwrapped
    (1/90 000 s; None: a PES without a PTS)."""

    data: bytes
    timestamp: int | None
    keyframe: bool


def nal_type(codec: str, header: int) -> int:
    """The NAL unit type in its header's first byte."""
    return header & 0x1F if codec == "h264" else (header >> 1) & 0x3F


def is_keyframe_nal(codec: str, kind: int) -> bool:
    """An IDR picture or a parameter set (H.264 5, 7, 8); an IRAP picture or a parameter set (H.265 16–23, 32–34)."""
    return kind in (5, 7, 8) if codec == "h264" else 16 <= kind <= 23 or 32 <= kind <= 34


class Depacketizer:
    """Access units from the RTP datagrams of one H.264 (``codec="h264"``) or H.265 (``"h265"``) stream."""

    def __init__(self, codec: str, payload_type: int = 96):
        if codec not in ("h264", "h265"):
            raise ValueError(f"RTP codec {codec!r}: h264 or h265")
        self.codec = codec
        # never set: the codec is given (MPEG-TS's comes from its PMT)
        self.unreadable: str | None = None
        self.payload_type = payload_type
        self.lost_packets = 0  # sequence numbers never seen
        # access units not handed over: damaged, or depending on one that was
        self.dropped_units = 0
        self.bad_packets = 0  # datagrams that are not RTP of this stream's shape
        self._seq: int | None = None
        self._ts: int | None = None  # the current access unit's RTP timestamp, unwrapped
        self._wraps = 0
        self._last_raw_ts: int | None = None
        self._nals: list[bytes] = []
        self._fragment: bytearray | None = None
        self._damaged = False
        self._need_keyframe = False
        self._keyframe = False

    def push(self, datagram: bytes) -> list[AccessUnit]:
        """Take one datagram; the access unit it completes (none or one), if it has the marker bit and the unit is
        whole."""
        unit = self._push(datagram)
        return [] if unit is None else [unit]

    def _push(self, datagram: bytes) -> AccessUnit | None:
        if len(datagram) < 12 or datagram[0] >> 6 != 2 or datagram[1] & 0x7F != self.payload_type:
            self.bad_packets += 1
            return None
        csrc, extension, padding = datagram[0] & 0x0F, datagram[0] & 0x10, datagram[0] & 0x20
        marker = bool(datagram[1] & 0x80)
        seq = int.from_bytes(datagram[2:4], "big")
        raw_ts = int.from_bytes(datagram[4:8], "big")
        start = 12 + 4 * csrc
        if extension:
            if len(datagram) < start + 4:
                self.bad_packets += 1
                return None
            start += 4 + 4 * int.from_bytes(datagram[start + 2 : start + 4], "big")
        end = len(datagram) - (datagram[-1] if padding else 0)
        if end <= start:
            self.bad_packets += 1
            return None
        lost = 0 if self._seq is None else (seq - self._seq - 1) & 0xFFFF
        self._seq = seq
        ts = self._unwrap(raw_ts)
        if (
            ts != self._ts
        ):  # a new access unit (if the previous one is unfinished, its marker bit was lost)
            self._drop_unit()
            self._ts = ts
        if lost:  # whatever they held (this unit's start, or whole units), the pictures after depend on it
            self.lost_packets += lost
            self._damaged = self._need_keyframe = True
        self._payload(datagram[start:end])
        return self._finish() if marker else None

    def _unwrap(self, raw_ts: int) -> int:
        if (
            self._last_raw_ts is not None
            and raw_ts < self._last_raw_ts
            and self._last_raw_ts - raw_ts > 1 << 31
        ):
            self._wraps += 1
        self._last_raw_ts = raw_ts
        return raw_ts + (self._wraps << 32)

    def _payload(self, payload: bytes) -> None:
        h264 = self.codec == "h264"
        kind = nal_type(self.codec, payload[0])
        if (h264 and 1 <= kind <= 23) or (not h264 and kind < 48):  # a single NAL unit
            self._add_nal(payload)
        elif (h264 and kind == 24) or (
            not h264 and kind == 48
        ):  # aggregation: 16-bit size, NAL, ...
            i = 1 if h264 else 2
            while i + 2 <= len(payload):
                size = int.from_bytes(payload[i : i + 2], "big")
                if size == 0 or i + 2 + size > len(payload):
                    self._damaged = True
                    return
                self._add_nal(payload[i + 2 : i + 2 + size])
                i += 2 + size
        elif (h264 and kind == 28) or (not h264 and kind == 49):  # a fragment of one NAL unit
            self._fragment_part(payload)
        else:  # STAP-B, MTAP, FU-B, PACI: not sent by cameras in non-interleaved mode
            self._damaged = True

    def _fragment_part(self, payload: bytes) -> None:
        header_len = 2 if self.codec == "h264" else 3
        if len(payload) <= header_len:
            self._damaged = True
            return
        fu = payload[header_len - 1]
        first, last = bool(fu & 0x80), bool(fu & 0x40)
        if self.codec == "h264":
            nal_header = bytes([(payload[0] & 0xE0) | (fu & 0x1F)])
        else:
            nal_header = bytes([(payload[0] & 0x81) | ((fu & 0x3F) << 1), payload[1]])
        if first:
            if self._fragment is not None:
                self._damaged = True
            self._fragment = bytearray(nal_header)
        elif self._fragment is None:  # its start was lost
            self._damaged = True
            return
        self._fragment += payload[header_len:]
        if last:
            self._add_nal(bytes(self._fragment))
            self._fragment = None

    def _add_nal(self, nal: bytes) -> None:
        if nal:
            self._keyframe |= is_keyframe_nal(self.codec, nal_type(self.codec, nal[0]))
            self._nals.append(nal)

    def _finish(self) -> AccessUnit | None:
        whole = bool(self._nals) and not self._damaged and self._fragment is None
        usable = whole and (self._keyframe or not self._need_keyframe)
        unit = (
            AccessUnit(b"".join(START_CODE + n for n in self._nals), self._ts, self._keyframe)
            if usable
            else None
        )
        self.dropped_units += not usable
        self._need_keyframe = not usable and (self._need_keyframe or not whole)
        self._reset()
        return unit

    def _drop_unit(self) -> None:
        if self._nals or self._fragment is not None:
            self.dropped_units += 1
            self._need_keyframe = True
        self._reset()

    def _reset(self) -> None:
        self._nals, self._fragment, self._damaged, self._keyframe = [], None, False, False
        self._ts = None

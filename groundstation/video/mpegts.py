"""H.264/H.265 in MPEG-TS over UDP (ISO/IEC 13818-1), received by skyfix itself: a frame ends at its PES's last packet.

FFmpeg's MPEG-TS demuxer hands a PES (a frame) over once its declared length is in. A video
PES of more than 64 KiB — a keyframe at 720p and above — cannot declare its length (the field
is 16 bits: its ``PES_packet_length`` is 0), and FFmpeg hands it over only when the next PES
starts, a frame interval later (measured with ``bench/live_latency.py``: keyframes the tail
of stream slot → GPS_INPUT, p50 55–80 ms while the other frames' p99 was 28–37 ms at 720p30).
A muxer starts every PES in a TS packet of its own, so it pads the last packet of a PES with
adaptation-field stuffing (FFmpeg, GStreamer's ``mpegtsmux`` and cameras' hardware muxers do);
skyfix ends a PES

- of declared length when that length is in;
- of no declared length at the first TS packet of its stream that carries stuffing (an
  adaptation field longer than its PCR, splice, private-data and extension fields take; a
  packet whose payload is short only by a PCR is not an end); a PES whose last packet happened
  to be exactly full ends when the next starts, as with FFmpeg.

:class:`TsDepacketizer`: datagrams (whole 188-byte TS packets) in, access units out (the PES's
elementary stream, its PTS unwrapped past 33 bits in 1/90 000 s, whether it starts a keyframe).
The video stream is the first H.264 (stream type 0x1B) or H.265 (0x24) stream of the first
program in the PAT's PMT. A continuity-counter gap on it (a lost datagram) or a packet with
the transport-error bit loses its PES and everything up to the next keyframe, as over RTP
(:mod:`.rtp`): frames decoded from a damaged picture would be tracked where the picture is
wrong. Read by :class:`~groundstation.video.udp.DatagramInput`.
"""

from __future__ import annotations

from groundstation.video.rtp import AccessUnit, is_keyframe_nal, nal_type

TS_BYTES = 188
SYNC = 0x47
PAT_PID = 0x0000
NULL_PID = 0x1FFF
STREAM_TYPES = {0x1B: "h264", 0x24: "h265"}  # ISO/IEC 13818-1 table 2-34
PTS_WRAP = 1 << 33


def _adaptation_used(af: bytes) -> int:
    """The bytes an adaptation field's (``af``: after its length byte) flags and fields take; the rest is stuffing."""
    if not af:
        return 0
    flags, used = af[0], 1
    used += 6 if flags & 0x10 else 0  # PCR
    used += 6 if flags & 0x08 else 0  # OPCR
    used += 1 if flags & 0x04 else 0  # splice countdown
    if flags & 0x02 and used < len(af):  # transport private data
        used += 1 + af[used]
    if flags & 0x01 and used < len(af):  # adaptation field extension
        used += 1 + af[used]
    return used


def _section(payload: bytes) -> bytes | None:
    """A PSI section's bytes (a PAT or PMT starting in this packet: its pointer field skipped), or None."""
    if not payload:
        return None
    start = 1 + payload[0]
    section = payload[start:]
    if len(section) < 3:
        return None
    length = ((section[1] & 0x0F) << 8) | section[2]
    return section[: 3 + length] if len(section) >= 3 + length else None


def _pts(header: bytes) -> int | None:
    """The PTS of a PES header (the bytes from its start code), or None."""
    if len(header) < 14 or not header[7] & 0x80:
        return None
    p = header[9:14]
    return ((p[0] >> 1) & 0x07) << 30 | p[1] << 22 | (p[2] >> 1) << 15 | p[3] << 7 | p[4] >> 1


class TsDepacketizer:
    """Access units from the MPEG-TS datagrams of one program's H.264 or H.265 video (see the module doc)."""

    def __init__(self):
        self.codec: str | None = None  # h264 or h265, once the PMT has said
        # why the program's video cannot be read (a PMT without H.264/H.265)
        self.unreadable: str | None = None
        self.lost_packets = 0  # TS packets missing (continuity-counter gaps) or marked in error
        # access units not handed over: damaged, or depending on one that was
        self.dropped_units = 0
        self.bad_packets = 0  # datagrams or packets that are not MPEG-TS
        self._pmt_pid: int | None = None
        self._video_pid: int | None = None
        self._cc: int | None = None
        self._pes: bytearray | None = None  # the PES being received, from its start code
        # its declared length (bytes after the length field), 0: none
        self._length: int | None = None
        self._damaged = False
        self._need_keyframe = False
        self._wraps = 0
        self._last_pts: int | None = None

    def push(self, datagram: bytes) -> list[AccessUnit]:
        """Take one datagram; the access units it completes."""
        if not datagram or len(datagram) % TS_BYTES:
            self.bad_packets += 1
            return []
        out: list[AccessUnit] = []
        for i in range(0, len(datagram), TS_BYTES):
            self._packet(datagram[i : i + TS_BYTES], out)
        return out

    def _packet(self, pkt: bytes, out: list[AccessUnit]) -> None:
        if pkt[0] != SYNC:
            self.bad_packets += 1
            return
        pid = ((pkt[1] & 0x1F) << 8) | pkt[2]
        start, error = bool(pkt[1] & 0x40), bool(pkt[1] & 0x80)
        control, cc = (pkt[3] >> 4) & 0x03, pkt[3] & 0x0F
        payload_at, stuffed = 4, False
        if control & 0x02:
            af_len = pkt[4]
            stuffed = af_len == 0 or af_len > _adaptation_used(pkt[5 : 5 + af_len])
            payload_at = 5 + af_len
        payload = pkt[payload_at:] if control & 0x01 and payload_at < TS_BYTES else b""
        if pid == PAT_PID and start:
            self._read_pat(payload)
        elif pid == self._pmt_pid and start:
            self._read_pmt(payload)
        elif pid == self._video_pid and pid != NULL_PID:
            if control & 0x01 and self._continuity(cc) == "duplicate":
                return  # sent twice on purpose: already taken
            if error:
                self.lost_packets += 1
                self._lost()
            self._video(payload, start, error, stuffed, out)

    def _continuity(self, cc: int) -> str:
        """The continuity counter of a packet with a payload: ``next``, ``duplicate``, or ``gap`` (packets lost)."""
        last, self._cc = self._cc, cc
        if last is None or cc == (last + 1) & 0x0F:
            return "next"
        if cc == last:
            return "duplicate"
        self.lost_packets += (cc - last - 1) & 0x0F
        self._lost()
        return "gap"

    def _lost(self) -> None:
        """Packets were lost: the PES being received is damaged; between PES, whole frames may be gone."""
        if self._pes is not None:
            self._damaged = True
        else:
            self._need_keyframe = True

    def _read_pat(self, payload: bytes) -> None:
        section = _section(payload)
        if section is None or section[0] != 0x00:
            return
        for j in range(8, len(section) - 4, 4):  # program loop, before the CRC
            program, pid = (
                (section[j] << 8) | section[j + 1],
                ((section[j + 2] & 0x1F) << 8) | section[j + 3],
            )
            if program != 0:  # 0 names the network information table
                self._pmt_pid = pid
                return

    def _read_pmt(self, payload: bytes) -> None:
        section = _section(payload)
        if section is None or section[0] != 0x02 or self._video_pid is not None:
            return
        j = 12 + (((section[10] & 0x0F) << 8) | section[11])  # after the program info descriptors
        kinds = []
        while j + 5 <= len(section) - 4:
            kind, pid = section[j], ((section[j + 1] & 0x1F) << 8) | section[j + 2]
            if kind in STREAM_TYPES:
                self._video_pid, self.codec = pid, STREAM_TYPES[kind]
                return
            kinds.append(f"0x{kind:02X}")
            j += 5 + (((section[j + 3] & 0x0F) << 8) | section[j + 4])
        self.unreadable = (
            f"its program holds stream types {', '.join(kinds) or 'none'}: skyfix reads H.264 (0x1B) "
            "and H.265 (0x24) video"
        )

    def _video(
        self, payload: bytes, start: bool, error: bool, stuffed: bool, out: list[AccessUnit]
    ) -> None:
        if start:
            if (
                self._pes is not None
            ):  # the one before had no declared length and no stuffing at its end
                self._finish(out)
            if len(payload) < 9 or payload[:3] != b"\x00\x00\x01":
                self.dropped_units += 1
                self._need_keyframe = True
                return
            self._pes, self._length, self._damaged = (
                bytearray(payload),
                (payload[4] << 8) | payload[5],
                error,
            )
        elif self._pes is None:
            return  # joined mid-PES, or after a damaged start
        else:
            self._pes += payload
        if (len(self._pes) >= 6 + self._length) if self._length else stuffed:
            self._finish(out)

    def _finish(self, out: list[AccessUnit]) -> None:
        pes, self._pes = self._pes, None
        header_end = 9 + pes[8]
        pts = _pts(bytes(pes[:header_end]))
        data = bytes(pes[header_end : 6 + self._length] if self._length else pes[header_end:])
        keyframe = self._keyframe(data)
        usable = not self._damaged and bool(data) and (keyframe or not self._need_keyframe)
        self.dropped_units += not usable
        self._need_keyframe = not usable
        self._damaged = False
        if usable:
            out.append(AccessUnit(data, self._unwrap(pts) if pts is not None else None, keyframe))

    def _keyframe(self, data: bytes) -> bool:
        """Whether the access unit holds a keyframe's NAL unit or a parameter set (looked for up to its first slice)."""
        at = data.find(b"\x00\x00\x01")
        while 0 <= at < len(data) - 3:
            kind = nal_type(self.codec, data[at + 3])
            if is_keyframe_nal(self.codec, kind):
                return True
            if 1 <= kind <= 5 if self.codec == "h264" else kind <= 31:
                return False  # a slice of a picture that is not a keyframe
            at = data.find(b"\x00\x00\x01", at + 3)
        return False

    def _unwrap(self, pts: int) -> int:
        if self._last_pts is not None and pts < self._last_pts - PTS_WRAP // 2:
            self._wraps += 1
        self._last_pts = pts
        return pts + self._wraps * PTS_WRAP

"""A clip's video muxed by FFmpeg (PyAV) to a loopback UDP socket, and the datagrams it sent, caught as they come:
what skyfix's own depacketizers (RTP, MPEG-TS) are tested on."""

from __future__ import annotations

import socket

import av


def mux_to_datagrams(
    clip, scheme: str, fmt: str, options: dict, query: str = ""
) -> tuple[list[bytes], list[int], list[int]]:
    """The datagrams FFmpeg's ``fmt`` muxer sends of ``clip``'s video to ``scheme://127.0.0.1:PORT{query}``, the
    number of datagrams sent after each frame, and each frame's size (bytes)."""
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
    rx.bind(("127.0.0.1", 0))
    rx.setblocking(False)
    datagrams, ends, sizes = [], [], []
    with (
        av.open(str(clip)) as src,
        av.open(
            f"{scheme}://127.0.0.1:{rx.getsockname()[1]}{query}", "w", format=fmt, options=options
        ) as out,
    ):
        ost = out.add_stream_from_template(src.streams.video[0])
        for packet in src.demux(video=0):
            if not packet.size:
                continue
            sizes.append(packet.size)
            packet.stream = ost
            out.mux(packet)
            while True:  # as they come, so that the socket's buffer never overflows
                try:
                    datagrams.append(rx.recv(65536))
                except BlockingIOError:
                    break
            ends.append(len(datagrams))
    rx.close()
    return datagrams, ends, sizes

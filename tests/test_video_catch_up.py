"""A live decoder far behind its stream skips to the newest keyframe waiting (groundstation.video.live.catch_up):
the packets before it are dropped unread, the keyframe and what follows it kept in order, the stream's end kept."""

import queue
import threading
from collections import deque
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from groundstation.video.live import _END, PACKET_BACKLOG, VideoLive, catch_up


@dataclass
class Packet:
    name: str
    is_keyframe: bool


def queued(names: str) -> queue.Queue:
    """A packet queue as the demuxer fills it: ``K`` a keyframe, ``p`` another frame, ``E`` the stream's end;
    each packet's t_recv is its position."""
    q = queue.Queue()
    for i, c in enumerate(names):
        q.put(_END if c == "E" else (Packet(f"{c}{i}", c == "K"), float(i)))
    return q


def names(waiting: deque) -> list[str]:
    return [item[0].name if isinstance(item, tuple) else "E" for item in waiting]


def test_packets_before_the_newest_keyframe_are_dropped():
    waiting = deque()
    assert catch_up(queued("KppKppKpE"), waiting) == (6, 5.0)
    assert names(waiting) == ["K6", "p7", "E"]


def test_without_a_later_keyframe_nothing_is_dropped_and_order_is_kept():
    q = queued("pppp")
    waiting = deque([(Packet("K0x", True), -1.0)])
    assert catch_up(q, waiting) == (0, None)
    assert names(waiting) == ["K0x", "p0", "p1", "p2", "p3"] and q.empty()


def test_at_most_the_backlog_is_taken_from_the_queue():
    q = queued("p" * (PACKET_BACKLOG + 5) + "K")
    waiting = deque()
    assert catch_up(q, waiting) == (0, None)  # the keyframe is still queued
    assert len(waiting) == PACKET_BACKLOG and q.qsize() == 6


@dataclass
class Decoded:
    pts: int
    format = SimpleNamespace(name="bgr24")  # not yuv420p: handed over in BGR alone

    def to_ndarray(self, format: str):
        return np.zeros((4, 6, 3), np.uint8)


class OneFramePerPacket:
    def decode(self, packet):
        return [Decoded(packet.pts)]


def test_the_first_frame_is_handed_over_however_far_behind():
    """The run's first frame is the one ``[tracker] init_bbox`` belongs to: a decoder behind from the start (six
    packets and the stream's end waiting: a busy laptop) hands it over, then skips while more than BEHIND_PACKETS
    wait. Handing over a later frame first put the box where the UUV had been (a live run under load tracked 25 px
    off it: 0.24 m in every fix)."""
    video = VideoLive("udp://127.0.0.1:5600", 0.0, lambda frame: None)
    handed = []
    video.handoff = SimpleNamespace(put=handed.append)
    q = queue.Queue()
    for pts in range(6):
        q.put((SimpleNamespace(pts=pts * 3000, is_keyframe=pts == 0), 100.0 + pts / 30))
    q.put(_END)
    video._decode(OneFramePerPacket(), 1 / 90000, q, threading.Event(), False)
    assert [round((f.t_slot - 100.0) * 30) for f in handed] == [0, 4, 5]
    assert [f.index for f in handed] == [0, 1, 2] and video.skipped_behind == 3

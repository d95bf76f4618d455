"""A live decoder far behind its stream skips to the newest keyframe waiting (groundstation.video.live.catch_up):
the packets before it are dropped unread, the keyframe and what follows it kept in order, the stream's end kept."""

import queue
from collections import deque
from dataclasses import dataclass

from groundstation.video.live import _END, PACKET_BACKLOG, catch_up


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

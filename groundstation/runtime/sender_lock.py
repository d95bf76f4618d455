"""One listening UDP port, one sender: the lock a ``udpin:`` MAVLink link and a ``udp://`` / ``rtp://`` video input
keep on whoever may feed them.

A port bound beyond loopback takes datagrams from anyone on the network; a second sender's datagrams
would be read as the autopilot's messages or spliced into the camera's stream. :class:`SenderLock`
takes the first sender its owner names with :meth:`~SenderLock.lock` (the first whose datagram held the
peer's messages, or the stream's packets), or the ``peer`` address it was given (``--mavlink-peer``, a
video URL's ``peer=``): datagrams from any other address are refused and counted (``foreign``). Without a
given peer the lock moves to a new sender only once the peer has been silent for ``relock_s`` (:data:`RELOCK_S`
for MAVLink; a video input's read timeout, after which it takes the stream as stopped: a forwarder or camera
restarted on a new source port), counted in ``relocks``. ``locked=False``
(:data:`ANY_PEER`) takes every sender: a channel several systems share.
"""

from __future__ import annotations

import socket
import time

#: The peer value that takes every sender (no lock)
ANY_PEER = "any"
#: A lock's peer silent this long (s) may be replaced by another sender the owner accepts
RELOCK_S = 5.0


def parse_peer(text: str, what: str) -> tuple[str, int]:
    """``HOST:PORT`` as an ``(IPv4 address, port)`` pair; :class:`ValueError` naming ``what`` and the value."""
    host, colon, port = text.rpartition(":")
    if not (host and colon and port.isdigit() and 0 < int(port) < 65536):
        raise ValueError(f"{what}={text} is not HOST:PORT (or {ANY_PEER})")
    try:
        return socket.gethostbyname(host), int(port)
    except OSError as e:
        raise ValueError(f"{what}={text}: {e.strerror or e}") from None


class SenderLock:
    """Which sender's datagrams a listening port takes (see the module doc). ``peer`` the address locked to (None:
    none yet); ``fixed`` when it was given."""

    def __init__(
        self, peer: tuple[str, int] | None = None, locked: bool = True, relock_s: float = RELOCK_S
    ):
        self.peer = peer
        self.relock_s = relock_s
        self.locked = locked
        self.fixed = locked and peer is not None
        self.foreign = self.relocks = 0
        self._heard = time.monotonic()

    def admits(self, addr: tuple[str, int]) -> bool:
        """Whether a datagram from ``addr`` may be read; a refused one is counted in ``foreign``."""
        if not self.locked or self.peer is None:
            return True
        if addr == self.peer:
            self._heard = time.monotonic()
            return True
        if self.fixed or time.monotonic() - self._heard < self.relock_s:
            self.foreign += 1
            return False
        return True  # the peer has been silent: a candidate, locked to once its owner says so

    def lock(self, addr: tuple[str, int]) -> None:
        """Take ``addr`` as the peer (its datagram held what the owner expects); a given peer never moves."""
        if self.fixed or addr == self.peer:
            return
        self.relocks += self.locked and self.peer is not None
        self.peer, self._heard = addr, time.monotonic()

    def status(self) -> dict:
        peer = self.peer  # an address, or a Zenoh ID (groundstation.video.zenoh_video)
        return {
            "peer": peer if peer is None or isinstance(peer, str) else f"{peer[0]}:{peer[1]}",
            "locked": self.locked,
            "foreign_datagrams": self.foreign,
            "relocks": self.relocks,
        }

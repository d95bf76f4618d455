"""Byte transports for a MAVLink link skyfix owns: every failure an :class:`OSError`, no hidden retries.

pymavlink's connections reconnect (and sleep) inside reads and writes, from whichever
thread calls them, swallow write errors and print to stdout. A link whose failures
must be seen and survived — GPS_INPUT to the UUV's autopilot — uses these instead and
pymavlink's ``MAVLink`` object only for framing, parsing and signing. The connection
strings are pymavlink's:

- ``tcp:HOST:PORT`` connect to a TCP server (ArduSub SITL's serial ports, a BlueOS "TCP Server" endpoint);
- ``tcpin:HOST:PORT`` listen, one client at a time (a newer one replaces the older);
- ``udpout:HOST:PORT`` send to HOST:PORT, read replies on the same socket;
- ``udpin:HOST:PORT`` (or ``udp:``) listen, locked to its peer: the sender the caller names with
  :meth:`Udp.answer_last_sender` (the autopilot's first message), or the ``peer`` address given to
  :func:`open_transport` (``--mavlink-peer``); datagrams from any other address are dropped unread and counted
  (``foreign``); ``peer`` :data:`ANY_PEER` turns the lock off (every sender taken: a radio channel or a router
  several systems share; writes still go to the last sender named). Without a given peer the lock moves to a new sender only once the peer has been silent for
  :data:`RELOCK_S` (an autopilot's forwarder restarted on a new port), counted in ``relocks``;
- ``DEVICE`` or ``DEVICE,BAUD`` a serial port (default 115200 baud).

:func:`open_transport` opens one (or raises :class:`OSError`, ``EINVAL`` for a malformed string); a
transport's ``read()`` returns what is there (``b""``: nothing yet; one datagram at a time where
``datagrams`` is true, so that a frame is never taken to continue in the next), ``write(buf)``
sends all of it or raises (a write that cannot finish in :data:`WRITE_TIMEOUT_S` is a
failure: a serial port or TCP peer that stopped reading), ``close()`` may be called twice.
``t_received`` is when the last read's bytes came (UNIX s): a UDP datagram's time as the kernel received it
(Linux's ``SO_TIMESTAMPNS``: a reader a loaded machine holds back for hundreds of ms still stamps each message
with its arrival; ``kernel_times`` says whether the socket gives them), the read's own time otherwise.
The end of a TCP connection is :class:`ConnectionResetError`. None of them retries:
the caller decides when to open again.
"""

from __future__ import annotations

import errno
import select
import socket
import struct
import sys
import time

# ANY_PEER (``--mavlink-peer any``) and RELOCK_S are the lock's, named here for the link's users
from groundstation.runtime.sender_lock import ANY_PEER, RELOCK_S, SenderLock  # noqa: F401

WRITE_TIMEOUT_S = 1.0
# a burst of datagrams (or a busy moment of the reader) is absorbed, not dropped
UDP_RCVBUF = 4 << 20
CONNECT_TIMEOUT_S = 1.0
DEFAULT_BAUD = 115200
_READ_MAX = 65536
#: Linux's SO_TIMESTAMPNS (asm-generic: x86-64, arm64), which Python's socket module does not name: each datagram
#: comes with the time the kernel received it, a struct timespec (two 64-bit integers).
SO_TIMESTAMPNS = 35
_TIMESPEC = struct.Struct("qq")


def _send_all(sock: socket.socket, buf: bytes) -> None:
    """All of ``buf`` on a non-blocking stream socket within :data:`WRITE_TIMEOUT_S`, else TimeoutError."""
    view, deadline = memoryview(buf), time.monotonic() + WRITE_TIMEOUT_S
    while view:
        try:
            view = view[sock.send(view) :]
        except BlockingIOError:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([], [sock], [], left)[1]:
                raise TimeoutError(
                    errno.ETIMEDOUT, f"the peer took no data for {WRITE_TIMEOUT_S:g} s"
                ) from None


def _recv(sock: socket.socket, what: str) -> bytes:
    try:
        data = sock.recv(_READ_MAX)
    except BlockingIOError:
        return b""
    if not data:
        raise ConnectionResetError(errno.ECONNRESET, what)
    return data


def _host_port(url: str, rest: str) -> tuple[str, int]:
    host, sep, port = rest.rpartition(":")
    if not sep or not port.isdigit() or not 0 <= int(port) < 65536:
        raise OSError(errno.EINVAL, f"expected HOST:PORT, got {rest!r}")
    return host or "0.0.0.0", int(port)


class _Transport:
    datagrams = False  # a read is one datagram: a frame never continues in the next
    kernel_times = False  # t_received is the kernel's receive time
    t_received = 0.0


class TcpClient(_Transport):
    """``tcp:HOST:PORT``."""

    def __init__(self, url: str, addr: tuple[str, int]):
        self.url = url
        self.sock = socket.create_connection(addr, timeout=CONNECT_TIMEOUT_S)
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.sock.setblocking(False)
        self.peer_known = True

    def filenos(self) -> list[int]:
        return [self.sock.fileno()]

    def read(self) -> bytes:
        self.t_received = time.time()
        return _recv(self.sock, "connection closed by the autopilot's end")

    def write(self, buf: bytes) -> None:
        _send_all(self.sock, buf)

    def close(self) -> None:
        self.sock.close()


class TcpServer(_Transport):
    """``tcpin:HOST:PORT``: the newest client is the peer; its end returns the transport to listening."""

    def __init__(self, url: str, addr: tuple[str, int]):
        self.url = url
        self.listener = socket.create_server(addr, reuse_port=False)
        self.listener.setblocking(False)
        self.client: socket.socket | None = None

    @property
    def peer_known(self) -> bool:
        return self.client is not None

    def filenos(self) -> list[int]:
        return [self.listener.fileno()] + ([self.client.fileno()] if self.client else [])

    def read(self) -> bytes:
        try:
            conn, _ = self.listener.accept()
        except BlockingIOError:
            pass
        else:
            self._drop_client()
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            conn.setblocking(False)
            self.client = conn
        if self.client is None:
            return b""
        self.t_received = time.time()
        try:
            return _recv(self.client, "the autopilot's client disconnected")
        except OSError:
            self._drop_client()
            raise

    def write(self, buf: bytes) -> None:
        if self.client is not None:
            try:
                _send_all(self.client, buf)
            except OSError:
                self._drop_client()
                raise

    def _drop_client(self) -> None:
        if self.client is not None:
            self.client.close()
            self.client = None

    def close(self) -> None:
        self._drop_client()
        self.listener.close()


class Udp(_Transport):
    """``udpout:`` (a fixed destination) or ``udpin:``/``udp:`` (bound; locked to the sender the caller names with
    :meth:`answer_last_sender`, or to ``peer``: see the module doc)."""

    datagrams = True

    def __init__(
        self,
        url: str,
        addr: tuple[str, int],
        listen: bool,
        peer: tuple[str, int] | None = None,
        locked: bool = True,
    ):
        self.url = url
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setblocking(False)
        # the kernel caps it (rmem_max)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, UDP_RCVBUF)
        self.listen = listen
        # listening: the sender lock (groundstation.runtime.sender_lock; locked False: every sender read, ANY_PEER)
        self.lock: SenderLock | None = None
        self._dest: tuple[str, int] | None = None
        if listen:
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self.sock.bind(addr)
            given = None if peer is None else (socket.gethostbyname(peer[0]), peer[1])
            self.lock = SenderLock(given, locked)
        else:
            self._dest = (socket.gethostbyname(addr[0]), addr[1])
        self.last_from: tuple[str, int] | None = None
        # elsewhere the option's number means something else
        self.kernel_times = sys.platform == "linux"
        if self.kernel_times:
            self.sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)

    @property
    def dest(self) -> tuple[str, int] | None:
        """Where writes go: the fixed destination, or the lock's peer."""
        return self._dest if self.lock is None else self.lock.peer

    @property
    def foreign(self) -> int:
        return 0 if self.lock is None else self.lock.foreign

    @property
    def relocks(self) -> int:
        return 0 if self.lock is None else self.lock.relocks

    @property
    def peer_known(self) -> bool:
        return self.dest is not None

    def filenos(self) -> list[int]:
        return [self.sock.fileno()]

    def read(self) -> bytes:
        try:
            data, ancillary, _, addr = self.sock.recvmsg(
                _READ_MAX, socket.CMSG_SPACE(_TIMESPEC.size)
            )
        except (
            BlockingIOError,
            ConnectionRefusedError,
        ):  # ICMP port unreachable of an earlier datagram
            return b""
        if self.lock is not None and not self.lock.admits(addr):
            return b""
        stamps = [
            _TIMESPEC.unpack(d[: _TIMESPEC.size])
            for level, kind, d in ancillary
            if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS
        ]
        self.t_received = stamps[0][0] + stamps[0][1] * 1e-9 if stamps else time.time()
        self.last_from = addr
        return data

    def answer_last_sender(self) -> None:
        """Lock to the sender of the last datagram read (the caller found its peer's messages in it)."""
        if self.lock is not None and self.last_from is not None:
            self.lock.lock(self.last_from)

    def write(self, buf: bytes) -> None:
        if self.dest is not None:
            # unconnected: no ICMP errors, but a missing route raises
            self.sock.sendto(buf, self.dest)

    def close(self) -> None:
        self.sock.close()


class Serial(_Transport):
    """``DEVICE[,BAUD]`` through pyserial."""

    peer_known = True

    def __init__(self, url: str, device: str, baud: int):
        import serial

        self.url = url
        try:
            self.port = serial.Serial(device, baud, timeout=0, write_timeout=WRITE_TIMEOUT_S)
        except (serial.SerialException, ValueError) as e:
            raise OSError(errno.ENODEV, str(e)) from None

    def filenos(self) -> list[int]:
        return [self.port.fileno()]

    def read(self) -> bytes:
        self.t_received = time.time()
        return self.port.read(max(1, self.port.in_waiting))

    def write(self, buf: bytes) -> None:
        self.port.write(buf)  # SerialTimeoutException and SerialException are OSErrors

    def close(self) -> None:
        self.port.close()


def open_transport(url: str, peer: str | None = None):
    """An open transport for a pymavlink-style connection string; :class:`OSError` when it cannot be opened.
    ``peer`` (``HOST:PORT``, ``udpin:`` only) is the only sender it takes; :data:`ANY_PEER`: every sender."""
    kind, _, rest = url.partition(":")
    if peer is not None and kind not in ("udpin", "udp"):
        raise OSError(errno.EINVAL, f"a peer address ({peer}) is for udpin: links only")
    if kind == "tcp":
        return TcpClient(url, _host_port(url, rest))
    if kind == "tcpin":
        return TcpServer(url, _host_port(url, rest))
    if kind == "udpout":
        return Udp(url, _host_port(url, rest), listen=False)
    if kind in ("udpin", "udp"):
        if peer == ANY_PEER:
            return Udp(url, _host_port(url, rest), listen=True, locked=False)
        return Udp(
            url,
            _host_port(url, rest),
            listen=True,
            peer=None if peer is None else _host_port(url, peer),
        )
    device, _, baud = url.partition(",")
    if not device.startswith("/") and not device.upper().startswith("COM"):
        raise OSError(errno.EINVAL, "expected tcp:, tcpin:, udpout:, udpin: or a serial device")
    if baud and not baud.isdigit():
        raise OSError(errno.EINVAL, f"baud rate {baud!r} is not a number")
    return Serial(url, device, int(baud) if baud else DEFAULT_BAUD)

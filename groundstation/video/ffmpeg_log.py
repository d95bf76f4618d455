"""FFmpeg's own log lines (through PyAV) in skyfix's log, thinned out by :class:`~groundstation.runtime.logs.Throttle`.

FFmpeg says why a stream fails ("bind failed: Address already in use", "non-existing
PPS 0 referenced") in its log, not in the error code. :func:`route_ffmpeg_log`
sends its warnings and errors to the ``skyfix.ffmpeg`` logger, each distinct
message a few times and then every 100th, and keeps the latest error so a
source can quote it (:func:`last_ffmpeg_error`).
"""

from __future__ import annotations

import logging
import threading
import time

import av.logging

from groundstation.runtime.logs import Throttle, kind_of

log = logging.getLogger("skyfix.ffmpeg")

_lock = threading.Lock()
_routed = False
_latest: tuple[float, str] | None = None  # (time.time(), "component: message") of the latest error


class _Handler(logging.Handler):
    def __init__(self):
        super().__init__(logging.WARNING)
        self.throttle = Throttle(first=3, every=100)

    def emit(self, record: logging.LogRecord) -> None:
        global _latest
        component = record.name.removeprefix("libav.")
        text = f"{component}: {record.getMessage()}"
        with _lock:
            if record.levelno >= logging.ERROR:
                _latest = (time.time(), text)
            n = self.throttle(kind_of(text))
        if n is not None:
            log.log(record.levelno, "ffmpeg %s%s", text, f" (seen {n} times)" if n > 1 else "")


def route_ffmpeg_log() -> None:
    """Send FFmpeg's warnings and errors to the ``skyfix.ffmpeg`` logger (once per process)."""
    global _routed
    with _lock:
        if _routed:
            return
        _routed = True
    libav = logging.getLogger("libav")
    libav.propagate = False
    libav.addHandler(_Handler())
    av.logging.set_level(av.logging.WARNING)


def last_ffmpeg_error(since_unix: float) -> str | None:
    """FFmpeg's latest error logged at or after ``since_unix``, or None."""
    with _lock:
        latest = _latest
    return latest[1] if latest is not None and latest[0] >= since_unix else None

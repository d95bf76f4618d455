"""Other clocks mapped onto the station's clock (the ground station's ``time.time()``).

skyfix has one time base: the station clock. Frames are stamped with it, and
every other source is mapped onto it by what arrives when:

- :class:`ClockMap` follows a source clock (an autopilot's ``time_boot_ms``, a
  UUV's own UNIX clock) by the least ``arrival − source time`` over a sliding
  window: the source clock's offset plus the link's smallest delay. The window
  follows drift; a source time going backwards starts a new segment (a reboot).
- :class:`RoundTrip` measures a link's one-way delay from MAVLink TIMESYNC
  exchanges (ours out, stamped by the autopilot on receipt, back) together with
  the :class:`ClockMap` of the autopilot's own messages.
- :class:`Median` keeps the median of recent values (GNSS time offsets from
  SYSTEM_TIME), so one bad pair cannot move it.

All times in seconds; ``arrival_s`` is station time.
"""

from __future__ import annotations

from collections import deque

import numpy as np


class _WindowMin:
    """Minimum of values added over the last ``window_s`` of arrival time (monotonic deque)."""

    def __init__(self, window_s: float):
        self.window_s = window_s
        # (arrival, value, payload), values increasing
        self._q: deque[tuple[float, float, object]] = deque()

    def clear(self) -> None:
        self._q.clear()

    def add(self, arrival_s: float, value: float, payload=None) -> None:
        q = self._q
        while q and q[-1][1] >= value:
            q.pop()
        q.append((arrival_s, value, payload))
        while q[0][0] < arrival_s - self.window_s:
            q.popleft()

    @property
    def best(self) -> tuple[float, float, object] | None:
        """``(arrival, value, payload)`` of the minimum, or None when empty."""
        return self._q[0] if self._q else None


OK, RESTART, STEP, OUTLIER = "ok", "restart", "step", "outlier"


class ClockMap:
    """A source clock on the station clock: ``station ≈ source + offset_s − latency``.

    ``offset_s`` is the least ``arrival − source`` over the last ``window_s`` seconds
    of arrivals, so it includes the link's smallest delay (subtract it where it is
    known: :class:`RoundTrip`, or a configured latency).

    A sample that does not fit the clock so far — its source time more than
    ``reboot_s`` before the latest, or arriving more than ``early_s`` sooner than the
    fastest delivery yet (its source time jumped ahead) — is an *outlier* and is not
    used: one garbage or spoofed frame must not move the clock. It becomes the clock
    only when at least ``confirm`` consecutive outliers, spread over ``confirm_s`` or more
    of arrival time, agree with each other (source times not decreasing, ``arrival −
    source`` within ``early_s``) and no fitting sample came in between (the old clock
    fell silent, as it does when its source reboots): a reboot (the source time went back; a new segment: the window restarts
    from them, samples already mapped keep their station times) or a clock that stepped
    ahead or a link that got faster (the window restarts from them, no new segment).
    A station clock that stepped back (our own clock: trusted) starts a new segment at once.
    """

    def __init__(
        self,
        window_s: float = 30.0,
        reboot_s: float = 1.0,
        early_s: float = 0.25,
        confirm: int = 3,
        confirm_s: float = 0.3,
    ):
        self.reboot_s = reboot_s
        self.early_s = early_s
        self.confirm = confirm
        self.confirm_s = confirm_s
        self._min = _WindowMin(window_s)
        self._last_source: float | None = None
        self._last_arrival: float | None = None
        self._candidates: list[
            tuple[float, float]
        ] = []  # outliers that may be a new clock: (source, arrival)
        self.segments = 0  # restarts seen (reboots of the source, steps of the station clock)
        self.reboots = 0  # those of them where the source's time went back (the source rebooted)
        self.outliers = 0  # samples not used
        # (source time before, source time after)
        self.last_restart: tuple[float, float] | None = None

    def _fits(self, source_s: float, arrival_s: float) -> bool:
        off = self.offset_s
        return (
            source_s >= self._last_source - self.reboot_s
            and arrival_s - source_s >= off - self.early_s
        )

    def add(self, source_s: float, arrival_s: float) -> str:
        """One sample's source and arrival times: :data:`OK`, :data:`OUTLIER` (not used), or, when it
        confirms the outliers before it, :data:`RESTART` (a new segment begins with them) or :data:`STEP`."""
        if self._last_source is None:
            self._take(source_s, arrival_s)
            return OK
        if arrival_s < self._last_arrival - self.reboot_s:  # the station clock stepped back
            self._restart(self._last_source, [(source_s, arrival_s)])
            return RESTART
        if self._fits(source_s, arrival_s):
            self._candidates.clear()
            self._take(source_s, arrival_s)
            return OK
        c = self._candidates
        if c and not (
            source_s >= c[-1][0]
            and abs((arrival_s - source_s) - (c[-1][1] - c[-1][0])) <= self.early_s
        ):
            c.clear()
        c.append((source_s, arrival_s))
        if len(c) < self.confirm or c[-1][1] - c[0][1] < self.confirm_s:
            self.outliers += 1
            return OUTLIER
        went_back = c[0][0] < self._last_source - self.reboot_s
        confirmed, self._candidates = list(c), []
        if went_back:
            self._restart(self._last_source, confirmed)
            return RESTART
        self._min.clear()
        for src, arr in confirmed:
            self._take(src, arr)
        return STEP

    @property
    def candidates(self) -> int:
        """Outliers so far that agree with each other (a new clock once there are enough)."""
        return len(self._candidates)

    @property
    def last_source_s(self) -> float | None:
        return self._last_source

    def _restart(self, before: float, samples: list[tuple[float, float]]) -> None:
        self._min.clear()
        self.segments += 1
        self.reboots += samples[0][0] < before - self.reboot_s
        self.last_restart = (before, samples[0][0])
        self._last_source = self._last_arrival = None
        for src, arr in samples:
            self._take(src, arr)

    def _take(self, source_s: float, arrival_s: float) -> None:
        last, last_arrival = self._last_source, self._last_arrival
        self._last_source = source_s if last is None else max(source_s, last)
        self._last_arrival = arrival_s if last_arrival is None else max(arrival_s, last_arrival)
        self._min.add(arrival_s, arrival_s - source_s)

    @property
    def offset_s(self) -> float | None:
        """Least ``arrival − source`` in the window (seconds), or None before any sample."""
        best = self._min.best
        return None if best is None else best[1]

    def to_arrival(self, source_s):
        """Source time(s) on the station clock as the fastest delivery would see them (offset added)."""
        off = self.offset_s
        if off is None:
            raise LookupError("no sample from this source yet")
        return np.asarray(source_s, dtype=float) + off


class RoundTrip:
    """MAVLink TIMESYNC exchanges with a remote clock: what the link's delay is, one way.

    ``add(remote_s, sent_s, arrival_s)``: our request left at ``sent_s`` (station),
    the remote stamped its receipt ``remote_s`` (its own clock) and the reply arrived
    at ``arrival_s``. Each direction's least delay is measured on its own:
    ``least_up_s`` = min(remote − sent) is the uplink's least delay minus the remote
    clock's offset; a :class:`ClockMap` of the remote's messages holds the
    downlink's least delay plus that offset. Their mean is the one-way delay,
    provided the least delays are the same both ways (:func:`one_way_delay_s`) —
    a weaker assumption than splitting each round trip evenly, and one that
    converges with every exchange instead of waiting for one with no queueing
    either way.
    """

    MAX_ROUND_TRIP_S = 2.0

    def __init__(self, window_s: float = 30.0):
        self._up = _WindowMin(window_s)
        self._rtt = _WindowMin(window_s)
        self.exchanges = 0

    def clear(self) -> None:
        self._up.clear()
        self._rtt.clear()

    def add(self, remote_s: float, sent_s: float, arrival_s: float) -> bool:
        """One exchange; False (ignored) when its round trip is negative or implausibly long."""
        rtt = arrival_s - sent_s
        if not 0.0 <= rtt <= self.MAX_ROUND_TRIP_S:
            return False
        self._up.add(arrival_s, remote_s - sent_s)
        self._rtt.add(arrival_s, rtt)
        self.exchanges += 1
        return True

    @property
    def least_up_s(self) -> float | None:
        best = self._up.best
        return None if best is None else best[1]

    @property
    def round_trip_s(self) -> float | None:
        best = self._rtt.best
        return None if best is None else best[1]

    def one_way_delay_s(self, downlink: ClockMap) -> float | None:
        """The link's one-way delay (s) from these exchanges and the remote's ``downlink`` map; None without both."""
        up, down = self.least_up_s, downlink.offset_s
        return None if up is None or down is None else (up + down) / 2.0


class Median:
    """Median of the last ``n`` values added."""

    def __init__(self, n: int = 31):
        self._v: deque[float] = deque(maxlen=n)

    def add(self, value: float) -> None:
        self._v.append(value)

    def clear(self) -> None:
        self._v.clear()

    def __len__(self) -> int:
        return len(self._v)

    @property
    def value(self) -> float | None:
        return float(np.median(self._v)) if self._v else None

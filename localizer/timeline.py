"""Telemetry buffers sampled at a frame's time, and the vehicle clock mapped to UNIX time.

A :class:`Series` holds samples in increasing time and interpolates them with a
rule per column: ``l`` linear, ``a`` an angle in radians (interpolated along the
short way, so yaw crosses ±180° correctly), ``q`` four consecutive columns of a
quaternion (w, x, y, z; spherical linear interpolation), ``s`` a step (the
earlier sample's value, for flags). Staleness is explicit: a time further than
``max_gap_s`` from both neighbours' gap, or more than ``max_hold_s`` after the
last sample, or before the first, gets a status instead of a value.
"""

from __future__ import annotations

from collections import deque

import numpy as np

OK = 0
BEFORE_FIRST = 1  # no sample yet at that time
GAP = 2  # the bracketing samples are too far apart
STALE = 3  # the newest sample is too old


class Series:
    """Append-only time series with interpolation; times in seconds of any one clock.

    ``keep_s`` bounds memory for live use: samples older than ``keep_s`` before the
    newest are dropped as the buffer grows. ``None`` keeps everything (offline).
    """

    def __init__(self, kinds: str, max_gap_s: float, max_hold_s: float, keep_s: float | None = None):
        if "q" in kinds and kinds.count("q") != 4:
            raise ValueError("a quaternion takes exactly four 'q' columns")
        self.kinds = kinds
        self.max_gap_s = max_gap_s
        self.max_hold_s = max_hold_s
        self.keep_s = keep_s
        self._t = np.empty(64)
        self._v = np.empty((64, len(kinds)))
        self._n = 0
        self.rejected = 0  # samples refused: out of order, non-finite or out of range
        self._angle = np.array([k == "a" for k in kinds])
        self._step = np.array([k == "s" for k in kinds])
        self._quat = np.array([k == "q" for k in kinds])

    def __len__(self) -> int:
        return self._n

    @property
    def times(self) -> np.ndarray:
        return self._t[: self._n]

    @property
    def values(self) -> np.ndarray:
        return self._v[: self._n]

    def append(self, t: float, values) -> bool:
        """Add one sample; returns False (and counts it) if it is out of order or not finite."""
        values = np.asarray(values, dtype=float)
        if not np.isfinite(t) or values.shape != (len(self.kinds),) or not np.all(np.isfinite(values)):
            self.rejected += 1
            return False
        if self._n and t <= self._t[self._n - 1]:
            self.rejected += 1
            return False
        if self._n == len(self._t):
            self._make_room(t)
        self._t[self._n] = t
        self._v[self._n] = values
        self._n += 1
        return True

    def clear(self) -> None:
        self._n = 0

    def _make_room(self, t_new: float) -> None:
        if self.keep_s is not None:
            keep_from = np.searchsorted(self._t[: self._n], t_new - self.keep_s)
            if keep_from > self._n // 4:
                n = self._n - keep_from
                self._t[:n] = self._t[keep_from : self._n]
                self._v[:n] = self._v[keep_from : self._n]
                self._n = n
                return
        self._t = np.concatenate([self._t, np.empty(len(self._t))])
        self._v = np.concatenate([self._v, np.empty_like(self._v)])

    def sample(self, t):
        """Values at time(s) ``t``: ``(values (..., ncols), status (...))``; statuses above.

        Rows whose status is not OK hold NaN.
        """
        t = np.asarray(t, dtype=float)
        out = np.full(t.shape + (len(self.kinds),), np.nan)
        status = np.full(t.shape, BEFORE_FIRST, dtype=np.int8)
        n = self._n
        if n == 0:
            return out, status
        ts, vs = self._t[:n], self._v[:n]
        i = np.searchsorted(ts, t, side="right")  # ts[i-1] <= t < ts[i]
        after_last = i >= n
        hold_ok = after_last & (t - ts[-1] <= self.max_hold_s)
        status = np.where(i == 0, BEFORE_FIRST, np.where(after_last, np.where(hold_ok, OK, STALE), OK))
        inner = (i > 0) & ~after_last
        i0 = np.clip(i - 1, 0, n - 1)
        i1 = np.clip(i, 0, n - 1)
        gap = ts[i1] - ts[i0]
        status = np.where(inner & (gap > self.max_gap_s), GAP, status).astype(np.int8)
        ok = status == OK
        if not np.any(ok):
            return out, status
        t0, t1 = ts[i0][ok], ts[i1][ok]
        v0, v1 = vs[i0][ok], vs[i1][ok]
        with np.errstate(invalid="ignore", divide="ignore"):
            w = np.where(t1 > t0, (t[ok] - t0) / (t1 - t0), 0.0)
        w = np.clip(w, 0.0, 1.0)[:, None]
        diff = v1 - v0
        diff[:, self._angle] = (diff[:, self._angle] + np.pi) % (2 * np.pi) - np.pi
        res = v0 + w * diff
        res[:, self._angle] = (res[:, self._angle] + np.pi) % (2 * np.pi) - np.pi
        res[:, self._step] = v0[:, self._step]
        if self._quat.any():
            res[:, self._quat] = slerp(v0[:, self._quat], v1[:, self._quat], w[:, 0])
        out[ok] = res
        return out, status


def slerp(q0, q1, w):
    """Spherical linear interpolation of quaternions (..., 4) by weight w in [0, 1]."""
    q0 = q0 / np.linalg.norm(q0, axis=-1, keepdims=True)
    q1 = q1 / np.linalg.norm(q1, axis=-1, keepdims=True)
    dot = np.sum(q0 * q1, axis=-1)
    q1 = np.where(dot[..., None] < 0, -q1, q1)  # the short way round
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin_t = np.sin(theta)
    small = sin_t < 1e-9
    with np.errstate(invalid="ignore", divide="ignore"):
        a = np.where(small, 1.0 - w, np.sin((1.0 - w) * theta) / sin_t)
        b = np.where(small, w, np.sin(w * theta) / sin_t)
    q = a[..., None] * q0 + b[..., None] * q1
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


class VehicleClock:
    """Maps the autopilot's ``time_boot_ms`` to UNIX time.

    Preferred: SYSTEM_TIME pairs (``time_unix_usec`` from the autopilot's GNSS);
    the offset is the median of the last ``window`` pairs, so one bad pair cannot
    move it. Fallback when no SYSTEM_TIME carries a UNIX time: the smallest
    ``receive time − boot time`` seen, i.e. the offset plus the link's least
    delay. A reboot (boot time going back by more than ``reboot_s``) resets it and
    calls ``on_reboot()``, so samples stamped with the old boot clock can be dropped.
    """

    def __init__(self, window: int = 31, reboot_s: float = 5.0, on_reboot=None):
        self._system = deque(maxlen=window)
        self._recv_min: float | None = None
        self._last_boot_s: float | None = None
        self._reboot_s = reboot_s
        self.reboots = 0
        self._on_reboot = on_reboot

    def _check_reboot(self, boot_s: float) -> None:
        last = self._last_boot_s
        if last is not None and boot_s < last - self._reboot_s:
            self._system.clear()
            self._recv_min = None
            self.reboots += 1
            if self._on_reboot is not None:
                self._on_reboot()
            last = None
        self._last_boot_s = boot_s if last is None else max(boot_s, last)

    def add_system_time(self, time_boot_ms: int, time_unix_usec: int) -> None:
        """A SYSTEM_TIME message; ``time_unix_usec == 0`` (autopilot without UNIX time) is ignored."""
        boot_s = time_boot_ms / 1000.0
        self._check_reboot(boot_s)
        if time_unix_usec > 0:
            self._system.append(time_unix_usec / 1e6 - boot_s)

    def add_receive(self, time_boot_ms: int, receive_unix_s: float) -> None:
        """Any timestamped message with the ground station's receive time (UNIX seconds)."""
        boot_s = time_boot_ms / 1000.0
        self._check_reboot(boot_s)
        off = receive_unix_s - boot_s
        if self._recv_min is None or off < self._recv_min:
            self._recv_min = off

    @property
    def source(self) -> str | None:
        """``"system_time"``, ``"receive"``, or None before any usable message."""
        if self._system:
            return "system_time"
        if self._recv_min is not None:
            return "receive"
        return None

    @property
    def receive_offset_s(self) -> float | None:
        """The smallest ``receive time − boot time`` seen (seconds), whatever SYSTEM_TIME says."""
        return self._recv_min

    @property
    def offset_s(self) -> float | None:
        """UNIX time minus boot time (seconds), or None if unknown."""
        if self._system:
            return float(np.median(self._system))
        return self._recv_min

    def to_boot_s(self, t_unix):
        """Boot-clock seconds of UNIX time(s); raises LookupError when no offset is known."""
        off = self.offset_s
        if off is None:
            raise LookupError("no clock reference yet (no SYSTEM_TIME or timestamped message)")
        return np.asarray(t_unix, dtype=float) - off

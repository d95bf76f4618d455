"""Telemetry buffers sampled at a frame's time: interpolation rules, extrapolation, staleness.

A :class:`Series` holds samples in increasing time and interpolates them with a
rule per column:

- ``l`` linear; ``a`` an angle in radians (interpolated along the short way, so
  yaw crosses ±180° correctly); ``s`` a step (the earlier sample's value, for flags);
- ``q`` four consecutive columns of a quaternion (w, x, y, z; spherical linear
  interpolation);
- ``h`` (a value) and ``H`` (an angle) with their rates of change in ``d`` columns
  (the i-th ``d`` is the rate of the i-th ``h``/``H``, per second): cubic Hermite
  interpolation, exact for motions that are cubic between samples, so a slow
  telemetry radio (ATTITUDE at 4 Hz) still gives the attitude between samples. A
  sample whose rate is NaN is interpolated linearly. Step columns may hold NaN
  (a value the source does not report).

Staleness is explicit: a time between two samples further apart than
``max_gap_s``, more than ``max_hold_s`` after the newest sample, or before the
first, gets a status instead of a value. Within ``max_hold_s`` after the newest
sample, ``h``/``H`` columns are extrapolated with their rate and other columns
are held; :meth:`Series.sample` also returns each column's estimated error of that
extrapolation or hold (half the last change of rate times the time squared, or the
last rate of change times the time), so the fix's accuracy can grow with it.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

OK = 0
BEFORE_FIRST = 1  # no sample yet at that time
GAP = 2  # the bracketing samples are too far apart
STALE = 3  # the newest sample is too old


class Sampled(NamedTuple):
    values: np.ndarray  # (..., ncols); NaN where status is not OK
    status: np.ndarray  # (...) int8
    # (..., ncols) 1-sigma estimate of the extrapolation/hold error; 0 when interpolated
    error: np.ndarray


def _wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


class Series:
    """Append-only time series with interpolation; times in seconds of one clock.

    ``keep_s`` bounds memory for live use: samples older than ``keep_s`` before the
    newest are dropped as the buffer grows. ``None`` keeps everything (offline).
    """

    def __init__(
        self, kinds: str, max_gap_s: float, max_hold_s: float, keep_s: float | None = None
    ):
        if "q" in kinds and kinds.count("q") != 4:
            raise ValueError("a quaternion takes exactly four 'q' columns")
        k = np.array(list(kinds))
        self._herm = np.flatnonzero((k == "h") | (k == "H"))
        self._rate = np.flatnonzero(k == "d")
        if len(self._herm) != len(self._rate):
            raise ValueError("every 'h'/'H' column needs one 'd' rate column")
        self.kinds = kinds
        self.max_gap_s = max_gap_s
        self.max_hold_s = max_hold_s
        self.keep_s = keep_s
        self._t = np.empty(64)
        self._v = np.empty((64, len(kinds)))
        self._n = 0
        self.rejected = 0  # samples refused: out of order, non-finite or out of range
        self._angle = (k == "a") | (k == "H")
        self._linear = (k == "l") | (k == "h") | (k == "d")
        self._quat = k == "q"
        self._may_be_nan = (k == "d") | (k == "s")  # unknown rates; steps that are not reported
        self._exact = (k == "d") | (k == "s")  # no error estimate: rates themselves, flags

    def __len__(self) -> int:
        return self._n

    @property
    def times(self) -> np.ndarray:
        return self._t[: self._n]

    @property
    def values(self) -> np.ndarray:
        return self._v[: self._n]

    @property
    def last_t(self) -> float | None:
        return float(self._t[self._n - 1]) if self._n else None

    def append(self, t: float, values) -> bool:
        """Add one sample; returns False (and counts it) if it is out of order or not finite.

        Rate (``d``) columns may be NaN: that sample is then interpolated linearly.
        """
        values = np.asarray(values, dtype=float)
        if (
            not np.isfinite(t)
            or values.shape != (len(self.kinds),)
            or not np.all(np.isfinite(values) | self._may_be_nan)
        ):
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

    def sample(self, t) -> Sampled:
        """Values at time(s) ``t`` with their statuses (above) and extrapolation errors."""
        t = np.asarray(t, dtype=float)
        ncol = len(self.kinds)
        out = np.full(t.shape + (ncol,), np.nan)
        err = np.zeros(t.shape + (ncol,))
        status = np.full(t.shape, BEFORE_FIRST, dtype=np.int8)
        n = self._n
        if n == 0:
            return Sampled(out, status, err)
        ts, vs = self._t[:n], self._v[:n]
        i = np.searchsorted(ts, t, side="right")  # ts[i-1] <= t < ts[i]
        after_last = i >= n
        hold_ok = after_last & (t - ts[-1] <= self.max_hold_s)
        status = np.where(
            i == 0, BEFORE_FIRST, np.where(after_last, np.where(hold_ok, OK, STALE), OK)
        )
        inner = (i > 0) & ~after_last
        i0 = np.clip(i - 1, 0, n - 1)
        i1 = np.clip(i, 0, n - 1)
        status = np.where(inner & (ts[i1] - ts[i0] > self.max_gap_s), GAP, status).astype(np.int8)
        ok = status == OK
        if np.any(ok & inner):
            sel = ok & inner
            out[sel] = self._interpolate(t[sel], ts[i0][sel], ts[i1][sel], vs[i0][sel], vs[i1][sel])
        if np.any(ok & after_last):
            sel = ok & after_last
            out[sel], err[sel] = self._extrapolate(t[sel] - ts[-1])
        return Sampled(out, status, err)

    def _interpolate(self, t, t0, t1, v0, v1):
        h = t1 - t0
        with np.errstate(invalid="ignore", divide="ignore"):
            w = np.clip(np.where(h > 0, (t - t0) / h, 0.0), 0.0, 1.0)
        diff = v1 - v0
        diff[:, self._angle] = _wrap(diff[:, self._angle])
        res = v0.copy()
        res[:, self._linear | self._angle] += w[:, None] * diff[:, self._linear | self._angle]
        if self._quat.any():
            res[:, self._quat] = slerp(v0[:, self._quat], v1[:, self._quat], w)
        if len(self._herm):
            d0, d1 = v0[:, self._rate], v1[:, self._rate]
            w2 = w[:, None]
            hh = h[:, None]
            h10 = w2 * (1 - w2) ** 2  # Hermite basis in the form v0 + w·Δ + corrections
            h11 = w2 * w2 * (w2 - 1)
            # cubic Hermite = linear interpolation + the rates' departure from the chord
            herm = h10 * (hh * d0 - diff[:, self._herm]) + h11 * (hh * d1 - diff[:, self._herm])
            herm = np.where(np.isfinite(herm), herm, 0.0)  # a NaN rate: linear
            res[:, self._herm] += herm
        res[:, self._angle] = _wrap(res[:, self._angle])
        return res

    def _extrapolate(self, dt):
        """Values ``dt`` seconds after the newest sample and the error estimates (see the module doc)."""
        n = self._n
        last = self._v[n - 1]
        res = np.tile(last, (len(dt), 1))
        err = np.zeros_like(res)
        if n >= 2:
            prev, span = self._v[n - 2], self._t[n - 1] - self._t[n - 2]
            change = last - prev
            change[self._angle] = _wrap(change[self._angle])
            err[:] = np.abs(change) / span * dt[:, None]  # held: drifts at the last rate of change
            if self._quat.any():
                dot = abs(float(np.dot(last[self._quat], prev[self._quat])))
                turn = 2.0 * np.arccos(
                    min(
                        1.0,
                        dot / (np.linalg.norm(last[self._quat]) * np.linalg.norm(prev[self._quat])),
                    )
                )
                err[:, self._quat] = turn / span * dt[:, None]
        if len(self._herm):
            rate = last[self._rate]
            has_rate = np.isfinite(rate)
            res[:, self._herm] += np.where(has_rate, rate * dt[:, None], 0.0)
            if n >= 2:
                accel = np.abs(last[self._rate] - self._v[n - 2][self._rate]) / (
                    self._t[n - 1] - self._t[n - 2]
                )
                extra = 0.5 * accel * dt[:, None] ** 2
                err[:, self._herm] = np.where(
                    has_rate & np.isfinite(extra), extra, err[:, self._herm]
                )
        err = np.where(np.isfinite(err), err, 0.0)
        err[:, self._exact] = 0.0
        res[:, self._angle] = _wrap(res[:, self._angle])
        return res, err


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

"""The EKF height's white noise, taken out: the barometer carries the short term, its noise does not.

GLOBAL_POSITION_INT's height (:func:`localizer.height.ekf_height_m`) can carry white noise from one message to the
next (a barometer's, centimetres) that the slow error ``b`` of :mod:`localizer.height` does not see: a frame's height
``h_ekf − b`` would pass it through. Its vertical velocity (``vz``, the EKF's, from the accelerometers) says how the
height moves between two messages, so the height is followed by a local-level Kalman filter over the messages
``k``: the smooth height ``X`` moves by the velocity's trapezoid ``u_k`` plus a random walk of variance ``q`` per
message, and each message's height is ``X`` plus white noise of variance ``R``. Without a velocity (NaN) ``u_k`` is
0 and the random walk takes the motion (``q`` grows: nothing is smoothed away that the data do not show as noise).

``R`` and ``q`` are measured from the data, not configured: the differences ``r_k = h_k − h_{k−1} − u_k`` are white
noise's differences plus the walk's steps, and their sums over :data:`LAG_N` messages the difference of two white
noises plus :data:`LAG_N` steps: the mean square of ``r_k`` is ``2R + q``, of the sums ``2R + LAG_N·q`` (over about
the last :data:`MOMENTS_N` messages; ``q`` at least :data:`WALK_FLOOR` of ``R``, so that a velocity that disagrees
with the heights is followed within about a second). A motion smoother than a walk shows a larger ``q`` over
:data:`LAG_N` messages than over one: less is smoothed, nothing lags. An EKF whose height has no white noise (under :data:`NOISE_FLOOR_M`) shows
none and is left as it is.

The filter starts again at an arming (ArduPilot sets home: ``relative_alt`` steps), a gap in the messages longer than
the position's ``max_gap_s``, and a height more than :data:`JUMP_SIGMAS` sigmas from the prediction (an EKF reset):
a step is passed through at once, not smoothed over seconds. Live, it is causal (each message's estimate uses the
messages up to it); offline (two-sided) a Rauch-Tung-Striebel pass over the same filter, with ``R`` and ``q``
measured over the whole recording, uses the messages after it too. The height at a frame between two messages is
the EKF's (cubic Hermite with the velocities) minus the noise estimated at the two messages, interpolated the same
way (with zero rates); its 1-sigma (the filter's, about the smooth height) joins the height's.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from .surface import height_above_surface_m

if TYPE_CHECKING:
    from .calibration import Water
    from .telemetry import Telemetry

MOMENTS_N = 100  # messages over which R and q are measured (10 s at 10 Hz) ...
LAG_N = (
    10  # ... from the differences between successive messages and between messages this many apart
)
WALK_FLOOR = 0.01  # q is at least this share of R per message
JUMP_SIGMAS = 5.0  # a height this far from the prediction starts the filter again
NOISE_FLOOR_M = 0.002  # white noise below this (the messages' millimetres) is left as it is


class HeightNoise:
    """The filter of the module doc over a :class:`~localizer.telemetry.Telemetry`'s GLOBAL_POSITION_INT heights."""

    def __init__(self, water: Water):
        self.water = water
        self._rate_col = (
            6 if water.surface_amsl_m is not None else 7
        )  # the height's rate in the position series
        self._clear()

    def _clear(self) -> None:
        # per message: time, height, rate, increment u from the previous, whether it starts the filter, the filtered
        # level and its variance, the predicted ones, R and q in force
        self._rows: list[tuple] = []
        # (differences counted, mean r², sums counted, mean square of the sums of LAG_N r)
        self._moments = (0, 0.0, 0, 0.0)
        self._sums: tuple = ()  # the running sums of r since the filter started, the last LAG_N + 1
        self._arms = 0
        self._columns: tuple | None = (
            None  # the rows' times, heights, rates, levels and variances as arrays
        )
        self._two_sided: tuple | None = None

    def __deepcopy__(self, memo) -> HeightNoise:
        """A copy for another thread (see :meth:`localizer.height.HeightEstimator.__deepcopy__`): the rows are
        tuples, the smoothed arrays never written in place."""
        new = object.__new__(HeightNoise)
        new.__dict__ = {k: list(v) if isinstance(v, list) else v for k, v in self.__dict__.items()}
        return new

    def update(self, tel: Telemetry) -> None:
        """Filter the GLOBAL_POSITION_INT messages that arrived since the last call."""
        times, values = tel.position.times, tel.position.values
        last = self._rows[-1][0] if self._rows else -math.inf
        if len(times) and times[-1] < last:  # the series started again (a reboot)
            self._clear()
            last = -math.inf
        sel = times > last
        if not sel.any():
            return
        h = height_above_surface_m(
            values[sel, 2],
            values[sel, 3],
            self.water.takeoff_height_above_surface_m,
            self.water.surface_amsl_m,
        )
        arms = tel.arm_times
        for t, hk, vk in zip(times[sel], h, values[sel, self._rate_col]):
            armed = self._arms < len(arms) and arms[self._arms] <= t
            while self._arms < len(arms) and arms[self._arms] <= t:
                self._arms += 1
            self._step(float(t), float(hk), float(vk), tel.position.max_gap_s, armed)
        self._trim(tel.keep_s)
        self._columns = self._two_sided = None

    def _step(self, t, h, v, max_gap_s, armed) -> None:
        n1, m1, nL, mL = self._moments
        R, q = _noise(*self._moments[1:])
        if self._rows:
            t0, h0, v0, *_, x0, P0, _, _, _, _ = self._rows[-1]
            dt = t - t0
            u = 0.5 * (v0 + v) * dt if math.isfinite(v0) and math.isfinite(v) else 0.0
            restart = armed or dt > max_gap_s
        else:
            u, restart = 0.0, True
        if not restart:
            x_pre, P_pre = x0 + u, P0 + q
            s = P_pre + R
            restart = s > 0.0 and abs(h - x_pre) > JUMP_SIGMAS * math.sqrt(s)
        if restart:  # the filter starts from this message
            x_pre, P_pre, x, P = h, math.inf, h, R
            self._sums = (0.0,)
        else:
            r = h - h0 - u
            n1 += 1
            m1 += (r * r - m1) / min(n1, MOMENTS_N)
            self._sums = (self._sums + (self._sums[-1] + r,))[-(LAG_N + 1) :]
            if len(self._sums) > LAG_N:
                nL += 1
                mL += ((self._sums[-1] - self._sums[0]) ** 2 - mL) / min(nL, MOMENTS_N)
            x, P = _update(x_pre, P_pre, h, R)
        self._moments = (n1, m1, nL, mL)
        self._rows.append((t, h, v, u, restart, x, P, x_pre, P_pre, R, q))

    def _trim(self, keep_s: float | None) -> None:
        if (
            keep_s is not None
            and self._rows
            and self._rows[0][0] < self._rows[-1][0] - 2.0 * keep_s
        ):
            cut = self._rows[-1][0] - keep_s
            self._rows = [r for r in self._rows if r[0] >= cut]

    def _smoothed(self) -> tuple:
        """Offline: per message the level and its variance given every message (``R``, ``q`` over the whole)."""
        if self._two_sided is None:
            rows = self._rows
            R, q = _noise(*self._moments[1:])
            n = len(rows)
            xf, Pf, xp, Pp = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
            for k, (_, h, _, u, restart, *_) in enumerate(rows):
                if restart:
                    xp[k], Pp[k], xf[k], Pf[k] = h, math.inf, h, R
                    continue
                xp[k], Pp[k] = xf[k - 1] + u, Pf[k - 1] + q
                xf[k], Pf[k] = _update(xp[k], Pp[k], h, R)
            xs, Ps = xf.copy(), Pf.copy()
            for k in range(n - 2, -1, -1):
                if (
                    rows[k + 1][4] or not Pp[k + 1] > 0.0
                ):  # the next one started again: nothing reaches back
                    continue
                C = Pf[k] / Pp[k + 1]
                xs[k] = xf[k] + C * (xs[k + 1] - xp[k + 1])
                Ps[k] = Pf[k] + C * C * (Ps[k + 1] - Pp[k + 1])
            self._two_sided = (xs, Ps)
        return self._two_sided

    def at(self, t_uav, two_sided: bool) -> tuple[np.ndarray, np.ndarray]:
        """The EKF height's white noise (m, the height − the smooth level) at UAV-scale times and the level's
        1-sigma (m); 0 and 0 where no message is filtered around the time."""
        tq = np.atleast_1d(np.asarray(t_uav, dtype=float))
        if not self._rows:
            return np.zeros(len(tq)), np.zeros(len(tq))
        if self._columns is None:
            cols = list(zip(*self._rows))
            self._columns = tuple(np.array(cols[k], dtype=float) for k in (0, 1, 2, 5, 6))
        t, h, v, x, P = self._columns
        x, P = self._smoothed() if two_sided else (x, P)
        noise, sd = h - x, np.sqrt(np.maximum(P, 0.0))
        i = np.clip(np.searchsorted(t, tq, side="right") - 1, 0, len(t) - 1)
        j = np.minimum(i + 1, len(t) - 1)
        with np.errstate(invalid="ignore", divide="ignore"):
            w = np.clip(np.where(t[j] > t[i], (tq - t[i]) / (t[j] - t[i]), 0.0), 0.0, 1.0)
        # the Hermite weight of zero rates where the heights are interpolated with their rates, else linear
        w = np.where(np.isfinite(v[i]) & np.isfinite(v[j]), w * w * (3.0 - 2.0 * w), w)
        out = (1.0 - w) * noise[i] + w * noise[j]
        sigma = (1.0 - w) * sd[i] + w * sd[j]
        known = np.isfinite(tq) & (tq >= t[0])
        return np.where(known, out, 0.0), np.where(known, sigma, 0.0)


def _noise(m1: float, nL: int, mL: float) -> tuple[float, float]:
    """``R`` and ``q`` (m², see the module doc) from the mean squares of ``r`` and (``nL`` counted) of its sums over
    :data:`LAG_N`; before a sum is counted, all of ``r`` is taken as the walk (nothing is smoothed)."""
    walk = max(mL - m1, 0.0) / (LAG_N - 1) if nL else m1
    R = max(m1 - walk, 0.0) / 2.0
    R = R if R >= NOISE_FLOOR_M**2 else 0.0
    return R, max(walk, WALK_FLOOR * R)


def _update(x_pre: float, P_pre: float, h: float, R: float) -> tuple[float, float]:
    """The level and its variance after the height ``h`` of noise variance ``R`` (0: the height itself, exactly)."""
    if R == 0.0:
        return h, 0.0
    K = P_pre / (P_pre + R)
    return x_pre + K * (h - x_pre), (1.0 - K) * P_pre

"""The UUV's track: a constant-velocity Kalman filter over its fixes, in metres north and east of a reference.

What a fix is made of, as the track sees it::

    fix = UUV + common(t) + white

- ``white``: what changes from one frame to the next — the tracker's pixel jitter, the
  gimbal's shake, the frame time's jitter against the telemetry. Its covariance is taken
  as a share ``s²`` of the fix's own covariance ``C`` (``sigma_n_m``, ``sigma_e_m``,
  ``cov_ne_m2``), plus :data:`WHITE_FLOOR_M` (a tracker's sub-pixel limit); the share is
  measured on the fixes themselves by :class:`Scatter` (see there). Before enough fixes
  were seen it is 1: the whole claim.
- ``common``: the rest of ``C`` — the camera's attitude bias, the height's, the depth's,
  the UAV's GNSS error — the same in consecutive frames. No averaging removes it, and a
  frame-to-frame comparison must not be made against it: two fixes 2·h_acc apart are not
  "within their accuracy" of each other when they share one bias. On the generated
  sessions ``C`` claims 0.1–0.4 m (1-sigma per axis) while consecutive fixes differ by
  3–7 mm, or 4–7 cm with ``field_like``'s noisy telemetry. The common error changes
  smoothly, over seconds (:func:`common_change_share`): little from one frame to the next,
  much across a long loss.

The state is the position and velocity of the fixes (the UUV plus its slowly changing
common error). It moves with constant velocity between fixes; for the filter's gain the
UUV's acceleration enters as the process noise of a piecewise-constant white acceleration
of 1-sigma :data:`PROCESS_ACCEL_SHARE` times the bound ``max_accel_mps2`` over each
prediction step (Bar-Shalom's DWPA model: ``Q = σ² G Gᵀ``, ``G = (Δ²/2, Δ)`` per axis),
and the velocity is held within the top speed ``max_speed_mps``. The velocity starts unknown (1-sigma the
top speed). Each fix updates it with the white part of its covariance only
(:meth:`UuvTrack.white_m2`). Whether a new fix can be the UUV (:meth:`UuvTrack.distance`)
takes the bounds as bounds, not as a Gaussian: the offset the UUV's speed and
acceleration allow is free, only what lies beyond it is measured against the noise.

The track's absolute uncertainty is its own (how well it knows where the fixes are) plus
the common error, which it cannot know: :meth:`UuvTrack.absolute_m2`.
Pure computation: times are station-clock UNIX seconds, positions metres (north, east).
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from .uncertainty import isotropic_sigma_m

#: Time scale (s) over which the fixes' common error changes: the attitude, height and GNSS errors of a
#: hovering UAV drift over tens of seconds; its turning rotates an attitude bias's footprint within seconds.
TAU_COMMON_S = 5.0
#: The white part of a fix's error is never taken below this (m, 1-sigma per axis): half a pixel to a pixel of
#: a tracker's jitter at the usual image scales (1–2 cm per pixel from 9–10 m).
WHITE_FLOOR_M = 0.01
#: The filter's process noise: a white acceleration of this share of the bound, 1-sigma (see the module doc).
#: Manoeuvres at the bounds (stopping from top speed, accelerating from rest, ±a every 0.3 s, turning at top speed)
#: stay within 3.4 sigma at 10–60 fps with this; at 0.2 they reach 11 at 30 fps (refused), at 1.0 an abrupt start at top
#: speed is no longer refused.
PROCESS_ACCEL_SHARE = 0.4
#: :class:`Scatter` keeps this many second differences (3 s at 30 fps) ...
SCATTER_KEEP = 90
#: ... and measures nothing from fewer than this many.
SCATTER_MIN = 8
#: :class:`Scatter` compares the middle of this many consecutive fixes with a line through the others ...
SCATTER_FIXES = 7
#: ... when they span at most this long (s).
SCATTER_SPAN_S = 0.7
_H = np.hstack([np.eye(2), np.zeros((2, 2))])
_H_T = _H.T
_EYE4 = np.eye(4)
_FLOOR_M2 = np.eye(2) * WHITE_FLOOR_M**2  # the white floor's covariance (m²)
_MID = SCATTER_FIXES // 2
_OTHERS = np.arange(SCATTER_FIXES) != _MID  # the fixes a Scatter's line goes through


def fix_covariance_m2(
    sigma_n_m: float, sigma_e_m: float, cov_ne_m2: float, h_acc_m: float
) -> np.ndarray:
    """A fix's 2×2 north-east covariance (m²); isotropic from ``h_acc_m`` (half its 95 % circle's radius:
    :func:`~localizer.uncertainty.isotropic_sigma_m` per axis) when the per-axis values are missing (a
    positions.csv of another tool)."""
    if math.isfinite(sigma_n_m) and math.isfinite(sigma_e_m):
        c = cov_ne_m2 if math.isfinite(cov_ne_m2) else 0.0
        return np.array([[sigma_n_m**2, c], [c, sigma_e_m**2]])
    return np.eye(2) * float(isotropic_sigma_m(h_acc_m)) ** 2


def common_change_share(gap_s: float) -> float:
    """The covariance of the change of a common error over ``gap_s`` seconds, as a share of the error's own
    covariance: a smooth error (correlation ``exp(−Δ²/2τ²)``, τ = :data:`TAU_COMMON_S`), so a frame's change is
    tiny and a minute's is as large as the error itself."""
    return 2.0 * (1.0 - math.exp(-0.5 * (gap_s / TAU_COMMON_S) ** 2))


class Scatter:
    """How much of the fixes' claimed covariance changes from frame to frame, measured on the fixes.

    Each fix in the middle of :data:`SCATTER_FIXES` consecutive ones (spanning at most
    :data:`SCATTER_SPAN_S`) is compared with the straight line fitted through the others
    (least squares in time): the line takes out the position, the velocity and every slowly
    changing error; what is left is the white part (its noise correlated over a frame or two
    too, as telemetry interpolated between samples is; plus the UUV's acceleration times the
    span squared over 12: under a centimetre at 1 m/s² and 0.3 s). With the white part
    ``s²·C`` of each fix, ``q = rᵀ (C·(1 + h))⁻¹ r`` (``h``: the line's own variance at that
    time, in units of one fix's) is ``s²`` times a chi-square with 2 degrees of freedom, so
    ``s² = mean(q) / 2`` over the last :data:`SCATTER_KEEP`. The mean, not a median: a
    tracker's jitter is heavy-tailed (on the generated sessions most frames move by a tenth
    of a pixel and single frames by half a pixel: the 99th percentile of ``q`` is up to 100
    times its median, 6.6 for a Gaussian), and the gates must cover the tail.
    """

    def __init__(self, keep: int = SCATTER_KEEP):
        """``keep``: how many second differences the share is the mean of (offline: all of a recording's)."""
        self._q: deque[float] = deque(maxlen=keep)
        self._last: deque[tuple[float, np.ndarray, np.ndarray]] = deque(maxlen=SCATTER_FIXES)

    def add(self, t: float, z: np.ndarray, C: np.ndarray) -> None:
        """A fix of the stream (time, north-east position, covariance)."""
        self._last.append((t, z, C))
        if len(self._last) < SCATTER_FIXES or t - self._last[0][0] > SCATTER_SPAN_S:
            return
        ts = np.array([f[0] for f in self._last])
        zs = np.array([f[1] for f in self._last])
        t_others, z_others = ts[_OTHERS], zs[_OTHERS]
        t_mean = t_others.sum() / (SCATTER_FIXES - 1)
        tc = t_others - t_mean
        sxx = float(tc @ tc)
        slope = tc @ z_others / sxx
        dt = ts[_MID] - t_mean
        r = zs[_MID] - (z_others.sum(axis=0) / (SCATTER_FIXES - 1) + slope * dt)
        h = 1.0 / (SCATTER_FIXES - 1) + dt * dt / sxx
        Cn = self._last[_MID][2] * (1.0 + h) + _FLOOR_M2 * (1.0 + h)
        self._q.append(float(r @ np.linalg.solve(Cn, r)))

    def restart(self) -> None:
        """The next fix does not follow the last one (another target, a gap): measured shares stay."""
        self._last.clear()

    @property
    def samples(self) -> int:
        return len(self._q)

    @property
    def ratio(self) -> float | None:
        """``s²`` as measured, not capped: above 1 the fixes scatter from frame to frame by more than their whole
        claimed covariance; None until :data:`SCATTER_MIN` fixes were measured."""
        n = len(self._q)
        return float(np.fromiter(self._q, float, n).mean()) / 2.0 if n >= SCATTER_MIN else None

    @property
    def share(self) -> float:
        """``s²``, at most 1; 1 until :data:`SCATTER_MIN` fixes were measured."""
        ratio = self.ratio
        return 1.0 if ratio is None else min(1.0, ratio)


class UuvTrack:
    """The fixes' position and velocity (north, east; m, m/s) at time :attr:`t`, with covariance :attr:`P`.

    Started from one fix ``z`` (covariance ``C``) at ``t``, the white share ``share`` of ``C``
    taken as the position's uncertainty.
    """

    def __init__(
        self,
        max_speed_mps: float,
        max_accel_mps2: float,
        t: float,
        z: np.ndarray,
        C: np.ndarray,
        share: float,
        max_reach_m: float = math.inf,
    ):
        self.max_speed_mps = max_speed_mps
        # however long since its last fix, the UUV is taken within this (m) of it
        self.max_reach_m = max_reach_m
        self.max_accel_mps2 = max_accel_mps2
        self.t = t
        self.x = np.array([z[0], z[1], 0.0, 0.0])
        self.P = np.zeros((4, 4))
        self.P[:2, :2] = self.white_m2(C, share)
        self.P[2:, 2:] = np.eye(2) * max_speed_mps**2
        self.C = C  # the newest fix's covariance (m²) ...
        self.common = (1.0 - share) * C  # ... and its common part
        # its last step was judged (and filtered) with a bound tighter than the vehicle's
        self.tight = False

    @staticmethod
    def white_m2(C: np.ndarray, share: float) -> np.ndarray:
        """The white part of a fix's covariance ``C`` (m²): ``share·C`` and the floor."""
        return share * C + _FLOOR_M2

    def predict(self, t: float, accel_mps2: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """State and covariance at ``t`` (not before :attr:`t`), the acceleration's process noise included
        (``accel_mps2``: the bound over this step, if not :attr:`max_accel_mps2`)."""
        a = self.max_accel_mps2 if accel_mps2 is None else accel_mps2
        dt = max(0.0, t - self.t)
        F = transition(dt)
        return F @ self.x, F @ self.P @ F.T + _process_noise(a, dt)

    def coast(
        self, t: float, accel_mps2: float | None = None, predicted: tuple | None = None
    ) -> None:
        """Move on to ``t`` without a fix (the prediction becomes the state; ``accel_mps2`` as in :meth:`predict`;
        ``predicted``: :meth:`predict`'s result for them, when the caller has it)."""
        self.x, self.P = self.predict(t, accel_mps2) if predicted is None else predicted
        self.t = max(self.t, t)

    def update(
        self,
        t: float,
        z: np.ndarray,
        C: np.ndarray,
        share: float,
        accel_mps2: float | None = None,
        predicted: tuple | None = None,
    ) -> None:
        """Take the fix ``z`` (covariance ``C``) at ``t``; the velocity is held within the top speed (``predicted``
        as in :meth:`coast`)."""
        R = self.white_m2(C, share)
        x, P = self.predict(t, accel_mps2) if predicted is None else predicted
        S = P[:2, :2] + R
        K = P @ _H_T @ np.linalg.inv(S)
        x = x + K @ (z - x[:2])
        IKH = _EYE4 - K @ _H
        P = IKH @ P @ IKH.T + K @ R @ K.T  # Joseph form: stays symmetric and positive
        speed = math.hypot(x[2], x[3])
        if speed > self.max_speed_mps:
            x[2:] *= self.max_speed_mps / speed
        self.t, self.x, self.P, self.C, self.common = t, x, P, C, (1.0 - share) * C

    def distance(
        self, t: float, z: np.ndarray, C: np.ndarray, share: float, accel_mps2: float | None = None
    ) -> tuple[float, float, float]:
        """How far a fix ``z`` (covariance ``C``) at ``t`` is from where the fixes can be: ``(d, radius_m, margin_m)``.

        Two bounds, both must hold: the UUV is at most ``v_top·Δ`` from the track's position
        (its top speed; at most :attr:`max_reach_m`, however long Δ), and at most ``½·a·Δ²``
        from that position moved on with the track's velocity (its acceleration bound). For
        each, the fix's offset beyond the
        bound, over its covariance — the track's own (carried over Δ for the second), the
        fix's white part and how much the common error can have changed
        (:func:`common_change_share`) — is a Mahalanobis distance; ``d`` is the larger.
        ``radius_m`` and ``margin_m`` (1-sigma of that covariance along its widest axis) are
        those of the bound that gives ``d``. ``accel_mps2``: the acceleration bound over this
        step, if not :attr:`max_accel_mps2`.
        """
        return max(_beyond(*bound) for bound in self._bounds(t, z, C, share, accel_mps2))

    def sigmas(
        self, t: float, z: np.ndarray, C: np.ndarray, share: float, accel_mps2: float | None = None
    ) -> float:
        """:meth:`distance`'s ``d`` alone (the same number, without the radius and the margin)."""
        return max(_sigmas_beyond(*bound) for bound in self._bounds(t, z, C, share, accel_mps2))

    def _bounds(self, t, z, C, share, accel_mps2) -> tuple[tuple, tuple]:
        """:meth:`distance`'s two bounds: each the fix's offset (north, east; m), the bound's radius (m) and the
        covariance (m²: north², north·east, east²).

        Written out in floats (the transition's structure: the moved-on covariance is ``P_pos + Δ·(P_pv + P_vp) +
        Δ²·P_vel``): the gates compare ``d`` with a bound, and numpy's per-call cost on 2×2 and 4×4 arrays was most
        of a fix's gating."""
        a = self.max_accel_mps2 if accel_mps2 is None else accel_mps2
        dt = max(0.0, t - self.t)
        (cnn, cne), (_, cee) = C.tolist()
        # the fix's white part (white_m2) and how much the common error can have changed
        grow = share + common_change_share(dt)
        floor = WHITE_FLOOR_M**2
        enn, ene, eee = grow * cnn + floor, grow * cne, grow * cee + floor
        (pnn, pne, pnvn, pnve), (_, pee, pevn, peve), (_, _, pvnvn, pvnve), (_, _, _, pveve) = (
            self.P.tolist()
        )
        n, e, vn, ve = self.x.tolist()
        zn, ze = z.tolist() if isinstance(z, np.ndarray) else z
        dt2 = dt * dt
        return (
            (zn - n, ze - e, self.reach_m(t), pnn + enn, pne + ene, pee + eee),
            (
                zn - (n + dt * vn),
                ze - (e + dt * ve),
                0.5 * a * dt2,
                pnn + 2.0 * dt * pnvn + dt2 * pvnvn + enn,
                pne + dt * (pnve + pevn) + dt2 * pvnve + ene,
                pee + 2.0 * dt * peve + dt2 * pveve + eee,
            ),
        )

    def widen(self, seconds: float) -> None:
        """The vehicle's acceleration bound may have held for ``seconds`` that the track was filtered with a
        tighter one (a push heard of late): its covariance grows by that much process noise."""
        self.P = self.P + _process_noise(self.max_accel_mps2, seconds)

    def reach_m(self, t: float) -> float:
        """How far from the track's position the UUV can be at ``t``: its top speed times the time since, at most
        :attr:`max_reach_m`."""
        return min(self.max_speed_mps * max(0.0, t - self.t), self.max_reach_m)

    def absolute_m2(self) -> np.ndarray:
        """The position's covariance against the truth (m²): the track's own plus the common error."""
        return self.P[:2, :2] + self.common


def transition(dt: float) -> np.ndarray:
    """The state's (north, east, v_north, v_east) constant-velocity transition over ``dt`` seconds (4×4)."""
    F = _EYE4.copy()
    F[0, 2] = F[1, 3] = dt
    return F


def _process_noise(accel_mps2: float, dt: float) -> np.ndarray:
    """The process noise (4×4) of a white acceleration of 1-sigma :data:`PROCESS_ACCEL_SHARE` × ``accel_mps2`` over
    ``dt`` seconds (see the module doc)."""
    g_pos, g_vel = dt * dt / 2.0, dt  # G = [g_pos·I; g_vel·I]: G Gᵀ written out
    Q = np.zeros((4, 4))
    Q[0, 0] = Q[1, 1] = g_pos * g_pos
    Q[0, 2] = Q[2, 0] = Q[1, 3] = Q[3, 1] = g_pos * g_vel
    Q[2, 2] = Q[3, 3] = g_vel * g_vel
    return (PROCESS_ACCEL_SHARE * accel_mps2) ** 2 * Q


def _beyond(
    dn: float, de: float, radius_m: float, unn: float, une: float, uee: float
) -> tuple[float, float, float]:
    """``(d, radius_m, margin_m)``: the Mahalanobis distance (covariance ``[[unn, une], [une, uee]]``) of the part of
    the offset (``dn``, ``de``) beyond ``radius_m``, and 1-sigma of the covariance along its widest axis."""
    widest = 0.5 * (unn + uee) + math.hypot(0.5 * (unn - uee), une)
    return _sigmas_beyond(dn, de, radius_m, unn, une, uee), radius_m, math.sqrt(widest)


def _sigmas_beyond(
    dn: float, de: float, radius_m: float, unn: float, une: float, uee: float
) -> float:
    """:func:`_beyond`'s Mahalanobis distance alone (the 2×2 inverse written out)."""
    off = math.hypot(dn, de)
    if off > 0:
        keep = max(0.0, off - radius_m) / off
        dn, de = dn * keep, de * keep
    q = (uee * dn * dn - 2.0 * une * dn * de + unn * de * de) / (unn * uee - une * une)
    return math.sqrt(max(0.0, q))

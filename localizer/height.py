"""The height of the UAV's reported position above the water, per frame, with its 1-sigma and its sources.

The EKF's height (GLOBAL_POSITION_INT ``relative_alt`` + ``[water] takeoff_height_above_surface_m``,
or ``alt`` − ``[water] surface_amsl_m``: :mod:`localizer.surface`) is the smooth reference at the
telemetry's rate. With the barometer as the EKF's height source (ArduPilot's EK3_SRC1_POSZ = 1)
both follow the barometer, which drifts. Its error ``b`` = EKF height − true height is estimated
by a small Kalman filter (:class:`HeightEstimator`) over whatever measures it, and a frame's
height is the EKF height − ``b`` − the EKF height's own white noise (:mod:`localizer.height_noise`: the answers'
``bias_m`` hold both, their sigma both). States ``x = (e, d, s, g, w)``, metres (``d`` m/s):

- ``e``: the EKF height's own error. 0 ± ``[uncertainty] height_m`` when its reference was set (less the
  wander's share, ``w``'s):
  the take-off (ArduPilot sets home, so ``relative_alt`` 0, when it arms: an arming seen in
  the HEARTBEATs starts ``e`` again) or, in the amsl reference or when no arming was seen, the
  autopilot's boot (its EKF origin): a conservative bound on the flight time. It then drifts at
  the rate ``d``.
- ``d``: the barometer's drift rate (the weather's pressure tendency, the sensor warming up),
  first-order Gauss-Markov of correlation time :data:`DRIFT_RATE_TAU_S`, its 1-sigma such that
  the drift's 1-sigma is ``[uncertainty] baro_drift_10min_m`` 10 minutes after the reference
  (:func:`drift_variance_m2`): without any measurement the height's sigma grows in proportion to
  the time at first, with its square root after :data:`DRIFT_RATE_TAU_S`. A drift, smooth over
  seconds, not a random walk (which moves centimetres in a second): the barometer carries the
  short term, and a GNSS altitude's white noise is averaged over minutes, not followed from
  message to message. A rate learnt is forgotten over :data:`DRIFT_RATE_TAU_S`, not extrapolated
  over the whole flight; it is kept across an arming (the weather does not start again).
- ``s``: the water's altitude minus the reference used for GNSS altitudes: with ``[water]
  surface_amsl_m`` ± ``[uncertainty] surface_amsl_m``; with the take-off reference unknown
  (± :data:`SURFACE_UNKNOWN_M`), so that GNSS altitudes give the barometer's drift (their trend
  since the first, or since the arming: ``s`` starts again then), not its offset; the drift before
  the first is not inferred from the rate they show (``e``'s correlation with ``d`` is dropped then).
- ``g``: the GNSS altitude's slow error, first-order Gauss-Markov of correlation time
  :data:`GNSS_TAU_S`; with each fix's own white noise (:data:`GNSS_WHITE`) its 1-sigma is the
  receiver's vertical accuracy (:func:`localizer.gnss.vertical_sigma_m`). It starts afresh when
  the fix type changes. The white noise is the larger of that share and what the GNSS altitudes
  scatter against the EKF's height from one message to the next (:func:`_scattered`): an RTK
  receiver's claimed v_acc can be optimistic.

- ``w``: the barometer's wander (the prop wash, gusts, the air's temperature: centimetres to decimetres back
  and forth over tens of seconds, which the drift's 600-s rate cannot follow), first-order Gauss-Markov of
  1-sigma ``[uncertainty] baro_wander_m`` (a share of ``height_m``: at most all of it, so the height's sigma
  without measurements is what it was) and correlation time ``baro_wander_s``. It is kept across an arming
  (ArduPilot zeroes the height, the air goes on); in the take-off reference, with GNSS altitudes fine enough
  to see it (below), the wander so far joins ``e`` at the first and ``w`` starts there from 0: they give its
  changes, and its return to its mean must not say where the level was (as the drift's rate learnt from them
  must not say what the drift was before). Whether it moves is
  measured (:meth:`HeightEstimator._bent`): it moves (first-order Gauss-Markov) only while GNSS altitudes fine
  enough to see it (the white noise in a difference of the means of two successive :data:`WANDER_LAG_S` spans
  under a quarter of what the wander moves over :data:`WANDER_LAG_S`) show it, those means moving by at least an
  eighth of that beyond their white noise; else (before that, beside a steady barometer, with a plain fix that cannot
  see it, with no GNSS) it is held as it is, neither decaying nor growing, its share of the sigma kept: an RTK
  receiver's white noise does not move the height, a plain fix's metres move it by little more than nothing,
  and a rangefinder's readings do not make a mean-reverting wander absorb the drift.

The height's error is ``b = e + w`` (take-off reference) or ``e + w + s`` (amsl). Measurements:

- a GNSS altitude ``a`` (GPS_RAW_INT, 3D fix or better): ``a − h_ekf − S = s + g − e − w`` (take-off;
  ``S`` the first such difference) or ``g − e − w`` (amsl, ``S`` = ``surface_amsl_m``). An RTK fix's
  centimetre accuracy makes it the height when the water's altitude is known; a plain fix's
  metres give little more than the barometer;
- an absolute height ``h`` (:attr:`Telemetry.height_fixes`: a downward rangefinder, the UUV's
  size in the image, ...): ``h_ekf − h = b`` ± its own sigma.

Cross-check: a measurement more than :data:`GATE_SIGMAS` sigmas from the estimate is not used,
and its source's next ones are used only within :data:`AGREE_SIGMAS` (so a wrong source cannot
slip in as the barometer's sigma grows). After :data:`CONFLICT_AFTER` refused in a row the source
disagrees: until :data:`CONFLICT_HOLD_S` after its last refused one, the height's sigma covers
both (``hypot(sigma, disagreement / 2)``); which one is right is not known, so h_acc says so
(when in doubt, no fix: GPS_INPUT's gate on h_acc). A disagreement starting and ending is one
line each (:func:`take_notices`), naming both heights; a single glitch is neither.
Live, the filter is causal: a frame's height uses the measurements up to its time; measurements that arrive late
(the UUV's size is measured after the frame) are fused in time order by re-running the filter from just before them.
Offline (:attr:`Telemetry.height_two_sided`: the whole recording) a frame's height uses the measurements after it
too: a Rauch-Tung-Striebel smoother over the filter's states (:meth:`HeightEstimator._smoothed`), with the same model;
it does not reach back past a take-off reference's first GNSS altitude (the drift before it, and the level, are not
inferred from them), and the wander moves from the start when the causal filter found it moving over most of the
recording (:meth:`HeightEstimator._both_ways`).

A frame's source word names what updated the estimate within :data:`SOURCE_WINDOW_S` before it,
joined by ``+``: ``rangefinder``, ``size`` (any absolute source by its name), ``gnss_rtk`` / ``gnss``
(amsl reference: RTK, or plain GNSS altitudes), ``baro+gnss_rtk`` / ``baro+gnss`` (take-off
reference: the barometer's drift followed against the GNSS altitude's trend); with none,
``takeoff`` or ``amsl``: the EKF height by the calibration's reference, its sigma grown with time.

Downward rangefinders: :func:`rangefinder_height_m` (the slant range along the body's down axis
times its vertical component, over flat water), :func:`rangefinder_sigma_m`. The rangefinder is
taken to sit at the reported position.
"""

from __future__ import annotations

import bisect
import copy
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from . import gnss
from .calibration import Sigmas, Water
from .height_noise import HeightNoise
from .surface import height_above_surface_m
from .timeline import OK

if TYPE_CHECKING:
    from .telemetry import Telemetry

DRIFT_REFERENCE_S = 600.0  # [uncertainty] baro_drift_10min_m is the drift's 1-sigma after this long
DRIFT_RATE_TAU_S = 600.0  # correlation time of the barometer's drift rate (a pressure tendency, the sensor's warming)
GNSS_TAU_S = 300.0  # correlation time of a GNSS altitude's error (satellite geometry, multipath)
GNSS_WHITE = 0.3  # share of a GNSS altitude's 1-sigma that is new with each fix (multipath, its timing against
# the EKF's height): white noise of GNSS_WHITE·sigma, the slow error g the rest, sqrt(1 − GNSS_WHITE²)·sigma
SCATTER_N = 50  # GNSS messages over which their white noise is measured (10 s at 5 Hz)
SURFACE_UNKNOWN_M = 1000.0  # 1-sigma of a water altitude nobody gave
GATE_SIGMAS = 5.0  # a measurement this far from the estimate is refused ...
AGREE_SIGMAS = 3.0  # ... and its source's next ones until one comes within this
CONFLICT_AFTER = 3  # a source disagrees once this many of its measurements in a row were refused (not one glitch)
CONFLICT_HOLD_S = 10.0  # a disagreement counts in the sigma until this long after the source's last refused measurement
SOURCE_WINDOW_S = 30.0
# the span over which GNSS altitudes are averaged to see the barometer's wander ...
WANDER_LAG_S = 2.0
BEND_N = 20  # ... and the differences of such means averaged (40 s)
RANGEFINDER_FLOOR_M = 0.05  # laser rangefinders' data sheets: ±5 cm up to a few metres ...
RANGEFINDER_SHARE = 0.01  # ... and 1 % of the range beyond (e.g. Benewake TFmini Plus, TF03)

_ARM, _GNSS, _FIX = 0, 1, 2
_E, _D, _S, _G, _W = range(5)  # the state's indices
_N = 5


def drift_variance_m2(dt_s, rate_sigma_mps, tau_s=DRIFT_RATE_TAU_S):
    """Variance (m²) of the drift over ``dt_s`` seconds of a first-order Gauss-Markov rate of stationary 1-sigma
    ``rate_sigma_mps`` and correlation time ``tau_s``: ``2·σ²·τ²·(x − 1 + e^−x)``, ``x = dt/τ``
    (``σ²·dt²`` for ``dt`` ≪ ``τ``, ``2·σ²·τ·dt`` for ``dt`` ≫ ``τ``)."""
    x = np.asarray(dt_s, dtype=float) / tau_s
    return 2.0 * rate_sigma_mps**2 * tau_s**2 * (x + np.expm1(-x))


def drift_rate_sigma_mps(drift_10min_m: float) -> float:
    """The drift rate's stationary 1-sigma (m/s) that makes the drift's 1-sigma ``drift_10min_m`` after
    :data:`DRIFT_REFERENCE_S`."""
    return drift_10min_m / math.sqrt(float(drift_variance_m2(DRIFT_REFERENCE_S, 1.0)))


def difference_var(sigma_m, lag_s, tau_s):
    """Variance (m²) of ``x(t) − x(t − lag)`` for a first-order Gauss-Markov ``x`` of stationary 1-sigma ``sigma_m``
    and correlation time ``tau_s``: ``2σ²·(1 − e^(−lag/τ))``."""
    return -2.0 * sigma_m**2 * math.expm1(-lag_s / tau_s)


def rangefinder_height_m(distance_m, roll_rad, pitch_rad):
    """Height above flat water (m) of a rangefinder looking down the body's z axis that reads ``distance_m``:
    the distance times the axis's vertical component (cos roll · cos pitch): a tilted airframe reads long."""
    return np.asarray(distance_m, dtype=float) * np.cos(roll_rad) * np.cos(pitch_rad)


def rangefinder_sigma_m(distance_m):
    """1-sigma of a rangefinder's reading (m) when it states none: :data:`RANGEFINDER_FLOOR_M` and
    :data:`RANGEFINDER_SHARE` of the range, together."""
    return np.hypot(RANGEFINDER_FLOOR_M, RANGEFINDER_SHARE * np.asarray(distance_m, dtype=float))


def ekf_height_m(water: Water, tel: Telemetry, t_uav) -> np.ndarray:
    """The EKF's height of the reported position above the water at UAV-scale times (NaN where
    GLOBAL_POSITION_INT has no fresh sample)."""
    p, status, _ = tel.position.sample(np.asarray(t_uav, dtype=float))
    h = height_above_surface_m(
        p[..., 2], p[..., 3], water.takeoff_height_above_surface_m, water.surface_amsl_m
    )
    return np.where(status == OK, h, np.nan)


@dataclass
class HeightAt:
    """The EKF height's estimated error at some times: height = EKF height − ``bias_m``."""

    bias_m: np.ndarray
    sigma_m: np.ndarray
    source: np.ndarray  # object array of words


class _Aux(NamedTuple):
    """What the filter carries besides its state, after an entry."""

    sigma_g: float  # the GNSS altitude's slow error's 1-sigma in force (NaN before one came)
    fix: int  # its fix type (-1 before)
    # the water altitude GNSS altitudes are referred to (take-off: the first difference)
    S: float | None
    refused: tuple = ()  # (source, measurements refused in a row) of the sources whose newest was refused
    # the previous GNSS measurement (NaN: none since the fix type or the reference changed)
    z_prev: float = math.nan
    scatter: tuple = (
        0,
        0.0,
    )  # (differences counted, the running mean of half their squares): see _scattered
    # the barometer's wander: whether it is in the model (see _bent), the GNSS measurements (t, z) of the last
    # 2·WANDER_LAG_S since the fix type or the reference changed, and (differences counted, the running mean of
    # what they show beyond the white noise and g, the time of the newest)
    wander: bool = False
    window: tuple = ()
    bend: tuple = (0, 0.0, -math.inf)


class HeightEstimator:
    """The Kalman filter of the module doc over a :class:`~localizer.telemetry.Telemetry`'s measurements.

    :meth:`at` pulls what arrived since the last call and answers for UAV-scale times. Entries
    (measurements and armings) are kept in time order with the filter's state after each; a
    measurement older than the newest processed one re-runs the filter from there.
    """

    def __init__(self, water: Water, sigmas: Sigmas):
        self.water, self.sigmas = water, sigmas
        self.key = (water, sigmas)
        self.amsl = water.surface_amsl_m is not None
        self.word = "amsl" if self.amsl else "takeoff"
        self.c = np.array([1.0, 0.0, 1.0 if self.amsl else 0.0, 0.0, 1.0])  # b = c·x
        self.rate_sigma_mps = drift_rate_sigma_mps(sigmas.baro_drift_10min_m)
        # the wander's share of height_m, and what is left of it for e
        self.wander_m = min(sigmas.baro_wander_m, sigmas.height_m)
        self.e0_var_m2 = sigmas.height_m**2 - self.wander_m**2
        # what the wander puts in a difference of GNSS altitudes over WANDER_LAG_S
        self.wander_d_m2 = difference_var(self.wander_m, WANDER_LAG_S, sigmas.baro_wander_s)
        self._base: tuple | None = None  # (t, x, P, aux) at the autopilot's boot
        self._entries: list[tuple] = []  # (t, kind, data), sorted by t
        self._entry_t: list[float] = []  # their times
        self._n = 0  # entries processed: their states are valid
        self._t = np.empty(0)
        self._x = np.empty((0, _N))
        self._P = np.empty((0, _N, _N))
        self._aux: list[_Aux] = []  # per processed entry
        self._pre: list[
            tuple
        ] = []  # ... the state and covariance predicted to it, before it (x, P)
        self._resets: list[tuple | None] = []  # ... what it reset (see _step)
        # offline: the filter that answers for the two-sided states (see _both_ways), ...
        self._smooth: HeightEstimator | None = None
        self.two_sided = False  # ... which it is
        self.moves = False  # ... its barometer's wander moving throughout
        self._rts: tuple | None = None  # ... its two-sided states (see _smoothed)
        self._src: list[str | None] = []  # per processed entry: the source word of its measurement
        self._ok: list[bool] = []  # ... whether it was used
        self._gap: list[float] = []  # ... the disagreement (m) of a refused one, else NaN
        self._cache: dict | None = None  # numpy views of the three above for the answers
        self._taken: dict[str, float] = {}  # per input: the time of the newest sample taken
        self._arms_taken = 0
        self._told: set = set()  # notices given, by (source, entry time): a re-run repeats none
        self.notices: list[str] = []
        self.noise = HeightNoise(water)  # the EKF height's white noise (localizer.height_noise)

    def __deepcopy__(self, memo) -> HeightEstimator:
        """A copy for another thread (the live latency estimate copies the telemetry once a second), made in
        microseconds: the containers are copied, their items are immutable (tuples, floats, words) and the
        arrays are never written in place (each update makes new ones)."""
        new = object.__new__(HeightEstimator)
        new.__dict__ = {
            k: type(v)(v) if isinstance(v, (list, dict, set)) else v
            for k, v in self.__dict__.items()
        }
        new.noise = copy.deepcopy(self.noise)
        return new

    # -- inputs ---------------------------------------------------------------------------------
    def _pull(self, tel: Telemetry) -> list[tuple]:
        new = []
        if tel.gnss.last_t is not None and tel.gnss.last_t > self._taken.get("gnss", -math.inf):
            times, values = tel.gnss.times, tel.gnss.values
            sel = times > self._taken.get("gnss", -math.inf)
            for t, v in zip(times[sel], values[sel]):
                fix, alt, v_acc, vdop = v[2], v[3], v[4], v[6]
                sigma = float(gnss.vertical_sigma_m(fix, v_acc, vdop))
                if math.isfinite(alt) and math.isfinite(sigma):
                    new.append((float(t), _GNSS, (int(fix), float(alt), sigma)))
            self._taken["gnss"] = tel.gnss.last_t
        for name, series in tel.height_fixes.items():
            if series.last_t is None or series.last_t <= self._taken.get(name, -math.inf):
                continue
            sel = series.times > self._taken.get(name, -math.inf)
            new += [
                (float(t), _FIX, (name, float(h), float(s)))
                for t, (h, s) in zip(series.times[sel], series.values[sel])
            ]
            self._taken[name] = series.last_t
        if not self.amsl:
            new += [(t, _ARM, None) for t in tel.arm_times[self._arms_taken :]]
        self._arms_taken = len(tel.arm_times)
        return new

    def update(self, tel: Telemetry) -> None:
        """Fuse what arrived since the last call (re-running the filter from the earliest new time)."""
        self.noise.update(tel)
        if self._base is None:
            boot = tel.uav_clock.offset_s  # the autopilot's boot on the UAV buffers' scale
            if boot is None:
                return
            P = np.diag(
                [
                    self.e0_var_m2,
                    self.rate_sigma_mps**2,
                    (self.sigmas.surface_amsl_m if self.amsl else SURFACE_UNKNOWN_M) ** 2,
                    0.0,
                    self.wander_m**2,
                ]
            )
            self._base = (boot, np.zeros(_N), P, _Aux(math.nan, -1, self.water.surface_amsl_m))
        new = sorted(self._pull(tel), key=lambda e: e[0])
        if new:
            first = len(self._entries)
            for e in new:
                i = bisect.bisect_right(self._entry_t, e[0])
                self._entry_t.insert(i, e[0])
                self._entries.insert(i, e)
                first = min(first, i)
            self._n = min(self._n, first)
        if self._n < len(self._entries):
            self._run(tel)
        self._trim(tel)

    # -- the filter -----------------------------------------------------------------------------
    def _predict(self, x, P, dt, sigma_g, wander=True):
        """State and covariance ``dt`` s later (arrays broadcast over leading axes): see :meth:`_transition`."""
        F, Q = self._transition(dt, sigma_g, wander)
        x = np.einsum("...ij,...j->...i", F, x)
        P = F @ P @ np.swapaxes(F, -1, -2) + Q
        return x, P

    def _transition(self, dt, sigma_g, wander=True):
        """The transition matrix ``F`` and process noise ``Q`` over ``dt`` s (arrays broadcast over leading axes):
        ``e`` integrates the rate ``d`` (the exact discretisation of an integrated first-order Gauss-Markov
        process), ``g`` decays, ``w`` decays while it moves (else it is held)."""
        dt = np.asarray(dt, dtype=float)
        tau, var_d = DRIFT_RATE_TAU_S, self.rate_sigma_mps**2
        m1, m2 = (
            np.expm1(-dt / tau),
            np.expm1(-2.0 * dt / tau),
        )  # φ − 1, φ² − 1 (φ = e^(−dt/τ)), without cancellation
        phi_g = np.exp(-dt / GNSS_TAU_S)
        F = np.zeros(dt.shape + (_N, _N))
        F[..., _E, _E] = F[..., _S, _S] = 1.0
        F[..., _E, _D] = -tau * m1
        F[..., _D, _D] = 1.0 + m1
        F[..., _G, _G] = phi_g
        Q = np.zeros_like(F)
        Q[..., _E, _E] = var_d * tau**2 * (2.0 * dt / tau + 4.0 * m1 - m2)
        Q[..., _E, _D] = Q[..., _D, _E] = var_d * tau * m1**2
        Q[..., _D, _D] = -var_d * m2
        Q[..., _G, _G] = np.nan_to_num(np.asarray(sigma_g, dtype=float)) ** 2 * (1.0 - phi_g**2)
        phi_w = np.where(wander, np.exp(-dt / self.sigmas.baro_wander_s), 1.0)  # else held as it is
        F[..., _W, _W] = phi_w
        Q[..., _W, _W] = self.wander_m**2 * (1.0 - phi_w**2)
        return F, Q

    def _run(self, tel: Telemetry) -> None:
        k = self._n
        for col in (self._aux, self._src, self._ok, self._gap, self._resets):
            del col[k:]
        t0, x, P, aux = (
            self._base
            if k == 0
            else (self._t[k - 1], self._x[k - 1], self._P[k - 1], self._aux[k - 1])
        )
        entries = self._entries[k:]
        h_ekf = ekf_height_m(self.water, tel, [e[0] for e in entries])
        ts, xs, Ps, pre = [], [], [], []
        for (t, kind, data), h_e in zip(entries, h_ekf):
            x, P = self._predict(x, P, max(0.0, t - t0), aux.sigma_g, aux.wander or self.moves)
            pre.append((x, P))
            x, P, aux, word, ok, gap, reset = self._step(t, kind, data, float(h_e), x, P, aux)
            self._resets.append(reset)
            ts.append(t)
            xs.append(x)
            Ps.append(P)
            self._aux.append(aux)
            self._src.append(word)
            self._ok.append(ok)
            self._gap.append(gap)
            t0 = t
        self._t = np.concatenate([self._t[:k], ts])
        self._x = np.concatenate([self._x[:k], np.reshape(xs, (-1, _N))])
        self._P = np.concatenate([self._P[:k], np.reshape(Ps, (-1, _N, _N))])
        self._pre = self._pre[:k] + pre
        self._n = len(self._entries)
        self._cache = self._smooth = None

    def _step(self, t, kind, data, h_e, x, P, aux: _Aux):
        """One entry: ``(x, P, aux, source word or None, used, disagreement m or NaN, reset)``; ``reset``: None, or
        ``(A, P_r)`` when the entry changed what the state means before its measurement (the state then ``A·x``,
        its covariance ``P_r``: an arming, a GNSS error source started afresh or rescaled, the wander joining ``e``)."""
        if (
            kind == _ARM
        ):  # the take-off reference is set again: e starts over, and GNSS altitudes count from here
            x, P = x.copy(), P.copy()
            x[_E] = x[_S] = 0.0
            P[_E, :] = P[:, _E] = P[_S, :] = P[:, _S] = 0.0
            # the height's sigma is height_m again: what the wander's own share is not (it may have joined e)
            P[_E, _E] = max(self.sigmas.height_m**2 - P[_W, _W], 0.0)
            P[_S, _S] = SURFACE_UNKNOWN_M**2
            A = np.diag([0.0, 1.0, 0.0, 1.0, 1.0])
            return x, P, aux._replace(z_prev=math.nan, window=()), None, False, math.nan, (A, P)
        if not math.isfinite(h_e):
            return x, P, aux, None, False, math.nan, None
        A = np.eye(_N)
        if kind == _GNSS:
            fix, alt, stated = data
            sigma = stated * math.sqrt(1.0 - GNSS_WHITE**2)
            x, P = x.copy(), P.copy()
            if fix != aux.fix or not math.isfinite(
                aux.sigma_g
            ):  # a new error source: g starts afresh
                x[_G] = A[_G, _G] = 0.0
                P[_G, :] = P[:, _G] = 0.0
                P[_G, _G] = sigma**2
                aux = aux._replace(
                    z_prev=math.nan, scatter=(0, 0.0), window=(), bend=(0, 0.0, -math.inf)
                )
            elif sigma != aux.sigma_g:  # the receiver's accuracy changed: the same error, rescaled
                x[_G] *= sigma / aux.sigma_g
                A[_G, _G] = sigma / aux.sigma_g
                P[_G, :] *= sigma / aux.sigma_g
                P[:, _G] *= sigma / aux.sigma_g
            if (
                aux.S is None
            ):  # the first: GNSS altitudes give the drift from here on; the drift so far, if its rate
                # is learnt, is not inferred from it (only a take-off reference's S is unset); nor is the level
                # from the wander's return to its mean where they can see the wander: the wander so far joins
                # e, the wander from here starts at 0
                # d made independent of the rest (of e alone could leave P indefinite)
                var_d = P[_D, _D]
                P[_D, :] = P[:, _D] = 0.0
                P[_D, _D] = var_d
                if 2.0 * (GNSS_WHITE * stated) ** 2 < self.wander_d_m2 / 4.0:  # a difference of two
                    T = np.eye(_N)
                    T[_E, _W], T[_W, _W] = 1.0, 0.0
                    x, P = T @ x, T @ P @ T.T
                A = None  # the two-sided states do not reach back past it either
            S = alt - h_e if aux.S is None else aux.S
            z = alt - h_e - S
            scatter = _scattered(aux, z)
            r, said_m = max((GNSS_WHITE * stated) ** 2, scatter[1]) + 1e-6, alt - S
            aux = self._bent(
                aux._replace(sigma_g=sigma, fix=fix, S=S, z_prev=z, scatter=scatter), t, z, r
            )
            word = ("" if self.amsl else "baro+") + ("gnss_rtk" if gnss.is_rtk(fix) else "gnss")
            row = np.array([-1.0, 0.0, 0.0 if self.amsl else 1.0, 1.0, -1.0])
        else:
            word, said_m, stated = data
            row, z, r = self.c, h_e - said_m, stated**2
        reset = None if A is not None and np.array_equal(A, np.eye(_N)) else (A, P)
        innovation = z - row @ x
        s = row @ P @ row + r
        apart = abs(innovation) / math.sqrt(s)
        streaks = dict(aux.refused)
        streak = streaks.pop(word, 0)
        if apart > (
            AGREE_SIGMAS if streak else GATE_SIGMAS
        ):  # once refused, back only within AGREE_SIGMAS
            if streak + 1 == CONFLICT_AFTER:
                est, sigma = h_e - self.c @ x, math.sqrt(self.c @ P @ self.c)
                self._tell(
                    word,
                    t,
                    f"height: {word} gives {said_m:.2f} ± {stated:.2f} m above the water, the estimate "
                    f"{est:.2f} ± {sigma:.2f} m (EKF height {h_e:.2f} m): {apart:.1f} sigma apart; not used "
                    "while they disagree, the height's sigma covers both",
                )
            streaks[word] = streak + 1
            return (
                x,
                P,
                aux._replace(refused=tuple(sorted(streaks.items()))),
                word,
                False,
                innovation,
                reset,
            )
        if streak >= CONFLICT_AFTER:
            self._tell(
                word, t, f"height: {word} agrees with the estimate again ({apart:.1f} sigma): used"
            )
        aux = aux._replace(refused=tuple(sorted(streaks.items())))
        K = P @ row / s
        x = x + K * innovation
        J = np.eye(_N) - np.outer(K, row)
        P = J @ P @ J.T + np.outer(K, K) * r
        return x, P, aux, word, True, math.nan, reset

    def _bent(self, aux: _Aux, t: float, z: float, r: float) -> _Aux:
        """``aux`` with the GNSS measurement ``z`` (m, at ``t``; white noise of variance ``r``) in its window, and
        whether the barometer's wander moves in the model. Every :data:`WANDER_LAG_S` the means of the measurements
        in the last two such spans give a difference; what its square shows beyond what the white noise and the
        GNSS's slow error ``g`` put in it is averaged over about the last :data:`BEND_N`. The wander moves while these
        GNSS altitudes can see it (the white noise in a difference of the spans' means under a quarter of what the
        configured wander puts there) and do (that average at least an eighth of it: a wander smoother than a
        first-order process, or slower, shows less over a short span); else it is held as it is, its sigma with it:
        an exact barometer beside an RTK receiver is not made to follow the receiver's white noise (nor a drift:
        over :data:`WANDER_LAG_S` it moves millimetres), and a plain receiver's or a rangefinder's readings do not
        make it absorb the drift."""
        lag = WANDER_LAG_S
        window = tuple(m for m in aux.window if m[0] > t - 2.0 * lag) + ((t, z),)
        n, mean, newest = aux.bend
        spans = [[zz for tt, zz in window if t - (k + 1) * lag < tt <= t - k * lag] for k in (1, 0)]
        # the white noise in the difference of the spans' means
        white = r * sum(1.0 / max(len(v), 1) for v in spans)
        if t - newest >= lag and window[0][0] <= t - 1.5 * lag and min(map(len, spans)) >= 2:
            a, b = (sum(v) / len(v) for v in spans)
            g = difference_var(aux.sigma_g, lag, GNSS_TAU_S)
            n += 1
            mean += ((b - a) ** 2 - white - g - mean) / min(n, BEND_N)
            newest = t
        wander = white < self.wander_d_m2 / 4.0 and n > 0 and mean >= self.wander_d_m2 / 8.0
        return aux._replace(window=window, bend=(n, mean, newest), wander=wander)

    def _tell(self, source: str, t: float, text: str) -> None:
        if (source, t) not in self._told:
            self._told.add((source, t))
            self.notices.append(text)

    def _trim(self, tel: Telemetry) -> None:
        """Live: forget entries older than twice the telemetry's history; the newest forgotten becomes the base."""
        keep = tel.keep_s
        if keep is None or self._n < 2 or self._t[0] >= self._t[self._n - 1] - 2 * keep:
            return
        k = int(np.searchsorted(self._t[: self._n], self._t[self._n - 1] - keep)) - 1
        if k < 0:
            return
        self._base = (self._t[k], self._x[k], self._P[k], self._aux[k])
        for col in (
            self._entries,
            self._entry_t,
            self._aux,
            self._src,
            self._ok,
            self._gap,
            self._pre,
            self._resets,
        ):
            del col[: k + 1]
        self._t, self._x, self._P = self._t[k + 1 :], self._x[k + 1 :], self._P[k + 1 :]
        self._n -= k + 1
        self._told = {told for told in self._told if told[1] > self._base[0]}
        self._cache = self._smooth = None

    # -- answers --------------------------------------------------------------------------------
    def _columns(self) -> dict:
        """Per source word: the times of its measurements, whether each was used, and the disagreement of each
        refused one that was the :data:`CONFLICT_AFTER`-th or later in a row (NaN otherwise)."""
        if self._cache is None:
            src = np.array(self._src, dtype=object)
            ok, gap = np.array(self._ok, dtype=bool), np.array(self._gap, dtype=float)
            self._cache = {}
            for w in sorted(
                {w for w in self._src if w is not None}, key=lambda w: ("gnss" in w, w)
            ):
                sel = src == w
                refused_in_a_row = np.zeros(sel.sum(), int)
                for i, used in enumerate(ok[sel]):
                    refused_in_a_row[i] = 0 if used else (refused_in_a_row[i - 1] if i else 0) + 1
                self._cache[w] = (
                    self._t[sel],
                    ok[sel],
                    np.where(refused_in_a_row >= CONFLICT_AFTER, gap[sel], np.nan),
                )
        return self._cache

    def at(self, tel: Telemetry, t_uav) -> HeightAt:
        """The EKF height's error at UAV-scale times (see the module doc); NaN before the autopilot is heard."""
        self.update(tel)
        tq = np.atleast_1d(np.asarray(t_uav, dtype=float))
        n = len(tq)
        if self._base is None:
            return HeightAt(
                np.full(n, np.nan), np.full(n, np.nan), np.full(n, self.word, dtype=object)
            )
        out = (self._both_ways(tel) if tel.height_two_sided else self)._answer(tq)
        noise_m, sigma_m = self.noise.at(
            tq, tel.height_two_sided
        )  # the EKF height's white noise, taken out
        return HeightAt(out.bias_m + noise_m, np.hypot(out.sigma_m, sigma_m), out.source)

    def _answer(self, tq) -> HeightAt:
        """:meth:`at` once the filter has run; the two-sided states where :attr:`two_sided`."""
        n = len(tq)
        i = np.searchsorted(self._t[: self._n], tq, side="right") - 1
        t0b, xb, Pb, auxb = self._base
        j = np.maximum(i, 0)
        t0 = np.where(i >= 0, self._t[j] if self._n else t0b, t0b)
        x = np.where((i >= 0)[:, None], self._x[j] if self._n else xb, xb)
        P = np.where((i >= 0)[:, None, None], self._P[j] if self._n else Pb, Pb)
        sigma_g = np.array([self._aux[k].sigma_g if k >= 0 else auxb.sigma_g for k in i])
        wander = np.array([self._aux[k].wander if k >= 0 else auxb.wander for k in i], dtype=bool)
        wander |= self.moves
        x, P = self._predict(x, P, np.maximum(np.nan_to_num(tq - t0), 0.0), sigma_g, wander)
        if self.two_sided:
            x, P = self._two_sided(tq, i, x, P, sigma_g, wander)
        bias = x @ self.c
        sigma = np.sqrt(np.einsum("i,nij,j->n", self.c, P, self.c))
        words = np.full(n, self.word, dtype=object)
        for word, (times, ok, gap) in self._columns().items():
            recent = _age(times[ok], tq) <= SOURCE_WINDOW_S
            words = np.where(recent, np.where(words == self.word, word, words + "+" + word), words)
            # its newest measurement refused, lately: the two disagree, the sigma covers both
            k = np.searchsorted(times, tq, side="right") - 1
            lately = (k >= 0) & (_age(times, tq) <= CONFLICT_HOLD_S)
            gaps = np.where(lately, gap[np.maximum(k, 0)], np.nan)
            sigma = np.where(np.isfinite(gaps), np.hypot(sigma, np.nan_to_num(gaps) / 2), sigma)
        bad = ~np.isfinite(tq)
        bias[bad] = sigma[bad] = np.nan
        return HeightAt(bias, sigma, words)

    def _both_ways(self, tel: Telemetry) -> HeightEstimator:
        """Offline (the whole recording): the filter run again over the same entries for the two-sided states, its
        barometer's wander moving from the start if the causal filter found it moving over most of the recording
        since it first did (the causal filter holds it until GNSS altitudes have shown it moves, then follows it
        late: in the first seconds the height follows the barometer)."""
        if self._smooth is None:
            est = self._smooth = HeightEstimator(self.water, self.sigmas)
            moved = np.array([a.wander for a in self._aux[: self._n]], dtype=bool)
            # moving over at least half of the entries since it was first seen (not a few flickers)
            est.moves = bool(moved.any() and moved[np.argmax(moved) :].mean() >= 0.5)
            est.two_sided = True
            est._base, est._entries, est._entry_t = self._base, self._entries, self._entry_t
            est._run(tel)
        return self._smooth

    def _smoothed(self) -> tuple:
        """Two-sided (Rauch-Tung-Striebel) over all the entries: per entry the state and covariance predicted to it
        before its resets, given the filter's and given every measurement before and after it (``x⁻, P⁻, xˢ, Pˢ``)."""
        if self._rts is None:
            n = self._n
            x_pre = np.reshape([p[0] for p in self._pre], (n, _N))
            P_pre = np.reshape([p[1] for p in self._pre], (n, _N, _N))
            xs, Ps = np.empty((n, _N)), np.empty((n, _N, _N))
            for k in range(n - 1, -1, -1):
                x_k, P_k = (
                    self._x[k],
                    self._P[k],
                )  # after the entry: the two-sided from the next one's
                if k < n - 1:
                    aux = self._aux[k]
                    wander = aux.wander or self.moves
                    F, _ = self._transition(self._t[k + 1] - self._t[k], aux.sigma_g, wander)
                    C = P_k @ F.T @ _pinv(P_pre[k + 1])
                    x_k, P_k = (
                        x_k + C @ (xs[k + 1] - x_pre[k + 1]),
                        P_k + C @ (Ps[k + 1] - P_pre[k + 1]) @ C.T,
                    )
                A, P_r = self._resets[k] or (np.eye(_N), None)
                if P_r is None:  # a measurement does not change the state
                    xs[k], Ps[k] = x_k, P_k
                elif (
                    A is None
                ):  # the first GNSS altitude of a take-off reference: nothing reaches back
                    xs[k], Ps[k] = x_pre[k], P_pre[k]
                else:  # back through what the entry reset: the state was A·x, of covariance P_r
                    J = P_pre[k] @ A.T @ _pinv(P_r)
                    xs[k] = x_pre[k] + J @ (x_k - A @ x_pre[k])
                    Ps[k] = P_pre[k] + J @ (P_k - P_r) @ J.T
            self._rts = (x_pre, P_pre, xs, Ps)
        return self._rts

    def _two_sided(self, tq, i, x, P, sigma_g, wander) -> tuple:
        """The states ``x``, ``P`` at ``tq`` predicted from the entry ``i`` before each (-1: the base), given the
        entries after them too: a Rauch-Tung-Striebel step back from the next entry's two-sided state (offline:
        the whole recording; the frames after the newest entry keep the prediction)."""
        has = (i + 1 < self._n) & np.isfinite(tq)
        if not has.any():
            return x, P
        x_pre, P_pre, xs, Ps = self._smoothed()
        k = i[has] + 1
        F, _ = self._transition(self._t[k] - tq[has], sigma_g[has], wander[has])
        C = P[has] @ np.swapaxes(F, -1, -2) @ _pinv(P_pre[k])
        x, P = x.copy(), P.copy()
        x[has] += np.einsum("nij,nj->ni", C, xs[k] - x_pre[k])
        P[has] += C @ (Ps[k] - P_pre[k]) @ np.swapaxes(C, -1, -2)
        return x, P

    def summary(self, tel: Telemetry, t_uav: float) -> dict:
        """The estimate at ``t_uav`` and what went into it (for the status): the EKF's height and the corrected
        one (the reported position's, metres above the water), the reference and how long ago it was set,
        and each source's measurements used and refused (over the history kept), the newest's age and,
        while it disagrees, by how much."""
        at = self.at(tel, [t_uav])
        h_ekf = float(ekf_height_m(self.water, tel, [t_uav])[0])
        anchor = "boot" if self.amsl or not tel.arm_times else "arming"
        since = tel.arm_times[-1] if anchor == "arming" else (self._base[0] if self._base else None)
        sources = {
            word: {
                "used": int(ok.sum()),
                "refused": int((~ok).sum()),
                "age_s": round(max(0.0, t_uav - times[-1]), 2),
                "disagrees_m": _num(gap[-1]),
            }
            for word, (times, ok, gap) in self._columns().items()
        }
        return {
            "height_m": _num(h_ekf - at.bias_m[0]),
            "sigma_m": _num(at.sigma_m[0]),
            "source": at.source[0],
            "ekf_height_m": _num(h_ekf),
            "bias_m": _num(at.bias_m[0]),
            "reference": self.word,
            "reference_set_at": anchor,
            "armed": tel.armed,
            "since_reference_s": None if since is None else round(max(0.0, t_uav - since), 1),
            "rangefinder_out_of_range": tel.rangefinder_out_of_range,
            "sources": sources,
        }


def _scattered(aux: _Aux, z: float) -> tuple:
    """``aux.scatter`` with the GNSS measurement ``z`` (m) counted: the variance of the white noise a GNSS altitude
    shows against the EKF's height, half the mean square of successive differences (the barometer carries the
    short term: what changes from one GPS_RAW_INT to the next is the GNSS's noise), over about the last
    :data:`SCATTER_N`. A receiver's claimed accuracy can be optimistic: the white noise is the larger of the two."""
    n, mean = aux.scatter
    if not math.isfinite(aux.z_prev):
        return n, mean
    n += 1
    return n, mean + ((z - aux.z_prev) ** 2 / 2.0 - mean) / min(n, SCATTER_N)


def _pinv(P) -> np.ndarray:
    """Pseudo-inverse of (stacked) covariances, scaled by their diagonals (the states' variances span 1e-8 to 1e6 m²;
    a state set or reset exactly has none)."""
    d = np.sqrt(np.diagonal(P, axis1=-2, axis2=-1))
    d = np.where(d > 0.0, 1.0 / np.where(d > 0.0, d, 1.0), 1.0)
    scaled = np.linalg.pinv(d[..., :, None] * P * d[..., None, :], rcond=1e-12, hermitian=True)
    return d[..., :, None] * scaled * d[..., None, :]


def _age(times, tq) -> np.ndarray:
    """Seconds from the newest of ``times`` (sorted) at or before each of ``tq`` to it; inf where none."""
    k = np.searchsorted(times, tq, side="right") - 1
    return tq - (times[np.maximum(k, 0)] if len(times) else 0.0) + np.where(k >= 0, 0.0, np.inf)


def _num(x: float, digits: int = 3) -> float | None:
    return round(float(x), digits) if math.isfinite(x) else None


def estimator(water: Water, sigmas: Sigmas, tel: Telemetry) -> HeightEstimator:
    """The telemetry's :class:`HeightEstimator` for this calibration (made on first use, or anew when the
    calibration's water reference or sigmas differ)."""
    est = tel.height_estimator
    if est is None or est.key != (water, sigmas):
        est = tel.height_estimator = HeightEstimator(water, sigmas)
    return est


def share(tel: Telemetry, source: Telemetry) -> bool:
    """Give ``tel`` a copy of ``source``'s height filter, made and updated, where ``tel`` has none yet and the filter
    reads the same from both (:func:`_reads`): the UUVs of one video each have a copy of the UAV's telemetry, whose
    filter is then run once, not once a UUV (the same states, the same notices; a copy whose telemetry gains inputs
    later, e.g. heights from size, re-runs from them as any filter does). Whether it was given."""
    est = source.height_estimator
    if est is None or tel.height_estimator is not None or not _same(_reads(tel), _reads(source)):
        return False
    tel.height_estimator = copy.deepcopy(est)
    return True


def _reads(tel: Telemetry) -> list:
    """Everything of ``tel`` its height filter reads (:class:`HeightEstimator` and its
    :class:`~localizer.height_noise.HeightNoise`): the autopilot's boot on the buffers' scale, the history kept,
    whether two-sided, the arming times, and GLOBAL_POSITION_INT, GPS_RAW_INT and each absolute height source in
    their order (each series' times, values and sampling bounds)."""
    series = [("position", tel.position), ("gnss", tel.gnss), *tel.height_fixes.items()]
    return [
        tel.uav_clock.offset_s,
        tel.keep_s,
        tel.height_two_sided,
        tel.arm_times,
        *(
            (name, s.kinds, s.max_gap_s, s.max_hold_s, s.keep_s, s.times, s.values)
            for name, s in series
        ),
    ]


def _same(a, b) -> bool:
    """Equal, item by item (arrays and floats: NaN equal to NaN)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.array_equal(a, b, equal_nan=True)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(map(_same, a, b))
    return a == b or (
        isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b)
    )


def ekf_height_error(water: Water, sigmas: Sigmas, tel: Telemetry, t_uav) -> HeightAt:
    """The EKF height's estimated error at UAV-scale times (the telemetry's :class:`HeightEstimator`)."""
    return estimator(water, sigmas, tel).at(tel, t_uav)


def take_notices(tel: Telemetry) -> list[str]:
    """The height estimator's one-line news since the last call (sources that disagree), taken out."""
    est = tel.height_estimator
    if est is None or not est.notices:
        return []
    out, est.notices = est.notices, []
    return out


def status(water: Water, sigmas: Sigmas, tel: Telemetry) -> dict | None:
    """:meth:`HeightEstimator.summary` at the newest GLOBAL_POSITION_INT (None before one came)."""
    t = tel.position.last_t
    return None if t is None else estimator(water, sigmas, tel).summary(tel, t)

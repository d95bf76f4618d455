"""The UUV's smoothed track, offline: a fixed-interval Rauch–Tung–Striebel smoother over a recording's fixes.

Live, a fix can only use the frames before it (``positions.csv``); offline the whole
recording is there, so each frame's position can be estimated from the fixes before
*and* after it. The model is the safety gates' track (:class:`~localizer.uuv_track.UuvTrack`:
constant velocity in metres north and east, the UUV's acceleration bound as a white
acceleration's process noise, its top speed): the forward pass is that filter over every
frame (a fix updates it, a frame without one moves it on), the backward pass the RTS
smoother's (Rauch, Tung & Striebel 1965; Bar-Shalom et al. 2001, §8.6)::

    G_k = P_k Fᵀ (P⁻_{k+1})⁻¹,   x̂_k = x_k + G_k (x̂_{k+1} − x⁻_{k+1}),   P̂_k = P_k + G_k (P̂_{k+1} − P⁻_{k+1}) G_kᵀ

What a fix is made of (see :mod:`localizer.uuv_track`): the UUV, an error every frame
shares (the camera's attitude bias, the height's, the depth's, the UAV's GNSS: the bulk
of ``h_acc``) and a white part that changes from frame to frame. Only the white part is
the smoother's measurement noise: its share ``s²`` of each fix's covariance ``C`` is
measured over the whole recording (:class:`~localizer.uuv_track.Scatter`: each fix
against a line through its six neighbours). The shared part ``(1 − s²)·C`` does not
average out: the smoothed position's covariance is its own (``P̂``, the white part
smoothed) plus the shared part, so the claim never says that averaging removed a bias.

Frames between fixes (a loss, fixes refused) are bridged while the smoothed position's
own 1-sigma stays within :data:`BRIDGE_SIGMA_M`; elsewhere, and before the first fix or
after the last, the smoothed track has no position either. Pure computation: times are
station-clock UNIX seconds, positions metres (north, east) of the first fix.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import pairwise

import numpy as np

from .fix import Fixes
from .geodesy import geodetic_to_ned, ned_to_geodetic
from .uncertainty import h_acc_from_cov_m
from .uuv_track import (
    SCATTER_MIN,
    WHITE_FLOOR_M,
    Scatter,
    UuvTrack,
    fix_covariance_m2,
    transition,
)

#: A frame without a fix of its own is bridged while the smoothed position's own 1-sigma (its widest axis, the
#: shared error not included) is within this (m): a tracker's frame-to-frame jitter in waves (3.5–8.7 cm RMS per
#: frame at 1–3.5 m depth). With a BlueROV2's bounds (1.5 m/s, 3 m/s²) and 0.5–2 cm of white noise on fixes at 30 fps,
#: gaps up to about 1.7 s are bridged whole (the fixes on both sides hold the middle), and the first and last
#: 0.4–0.5 s of a longer one.
BRIDGE_SIGMA_M = 0.05
#: The fixes' noise is also measured over a wave's period (:func:`local_fits`): each fix against a quadratic in time
#: through the fixes within this span (s) around it. Wind waves move a fix by refraction with periods of 0.5–2.5 s
#: (their apparent jitter at 2–8 m/s of wind, 96–99 % of its power above 0.4 Hz on the generated sessions).
WAVE_SPAN_S = 2.0
#: A quadratic is fitted through at least this many fixes (else that fix measures nothing).
WAVE_MIN_FIXES = 8
#: The jitter is time-correlated (waves) when the share measured over :data:`WAVE_SPAN_S` is at least this many
#: times the frame-to-frame one (:func:`white_share`); white noise gives 1 (0.9–1.1 over 4–20 s at 30 fps).
CORRELATED_RATIO = 2.0
#: With time-correlated jitter the acceleration bound of the process noise is the data's (:func:`data_accel_mps2`):
#: the local acceleration with this many of its sigmas.
ACCEL_SIGMAS = 2.0


@dataclass(frozen=True)
class Smoothed:
    """The smoothed track at every frame of the fixes it was made from (arrays in their order).

    ``ok``: a smoothed position (the frame's own fix, or bridged); ``gap_s``: 0 at a frame with a fix taken, else the
    time between the fixes around it (inf outside the first and last). Positions and covariances NaN where not ok.
    """

    t_unix: np.ndarray
    ok: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    north_m: np.ndarray  # of the first fix taken
    east_m: np.ndarray
    vn_mps: np.ndarray
    ve_mps: np.ndarray
    cov_own_m2: np.ndarray  # N×2×2: the smoothed white part
    cov_shared_m2: np.ndarray  # N×2×2: the error the fixes share, which smoothing cannot remove
    gap_s: np.ndarray
    white_share: float  # s², measured over the recording: frame to frame, or over a wave's period when that is larger
    wave_share: float  # the share measured over a wave's period (NaN: too few fixes)
    # per frame: the acceleration bound of the process noise over the step to it
    accel_mps2: np.ndarray

    @property
    def cov_m2(self) -> np.ndarray:
        """N×2×2 north-east covariance against the truth (m²): own plus shared."""
        return self.cov_own_m2 + self.cov_shared_m2

    @property
    def h_acc_m(self) -> np.ndarray:
        """Horizontal accuracy (m) as a fix's ``h_acc_m``: half the radius of :attr:`cov_m2`'s 95 % circle."""
        return h_acc_from_cov_m(self.cov_m2)


def smooth_fixes(
    fixes: Fixes,
    taken: np.ndarray,
    max_speed_mps: float,
    max_accel_mps2: float,
    bridge_sigma_m: float = BRIDGE_SIGMA_M,
    recorded: FittedFixes | None = None,
) -> Smoothed:
    """The smoothed track of ``fixes`` (times increasing) from those ``taken`` (ok fixes the gates took, with a
    finite ``h_acc_m``), for a UUV of top speed ``max_speed_mps`` and acceleration bound ``max_accel_mps2``.
    ``recorded``: :func:`recording_fits` of the same fixes, taken as they are where its fixes are the ones taken
    (the same arrays as computing them again)."""
    taken = np.asarray(taken, bool) & (fixes.status == "ok") & np.isfinite(fixes.h_acc_m)
    n = len(fixes)
    nan2 = np.full((n, 2, 2), np.nan)
    idx = np.flatnonzero(taken)
    if not len(idx):
        empty = np.full(n, np.nan)
        return Smoothed(
            fixes.t_unix,
            np.zeros(n, bool),
            empty,
            empty,
            empty,
            empty,
            empty,
            empty,
            nan2,
            nan2.copy(),
            np.full(n, np.inf),
            1.0,
            np.nan,
            np.full(n, float(max_accel_mps2)),
        )
    fitted = (
        recorded
        if recorded is not None and np.array_equal(recorded.idx, idx)
        else fitted_fixes(fixes, idx)
    )
    ref, z, C, fits = fitted.ref, fitted.z, fitted.C, fitted.fits
    share = white_share(fixes.t_unix[idx], z[idx], C[idx])
    wave = jitter_share(fits, C[idx])
    gap = _gaps(fixes.t_unix, idx)
    accel = np.full(n, float(max_accel_mps2))
    # the noise does not average from frame to frame: waves' jitter
    correlated = wave >= CORRELATED_RATIO * share
    if correlated:
        share = min(1.0, wave)
        accel = data_accel_mps2(fixes.t_unix, idx, gap, fits, C[idx], share, max_accel_mps2)
    x, P = _rts(fixes.t_unix, z, C, taken, idx[0], idx[-1], share, max_speed_mps, accel)
    shared = _shared(C, idx, share)
    own = P[:, :2, :2]
    if correlated:
        own = (
            own
            * _passed_jitter_scale(
                fixes.t_unix, idx, fits, C, taken, share, max_speed_mps, accel, own
            )[:, None, None]
        )
    finite = np.all(np.isfinite(own), axis=(1, 2))
    widest = np.full(n, np.inf)
    widest[finite] = np.linalg.eigvalsh(own[finite])[:, -1]
    ok = taken | (np.isfinite(gap) & (widest <= bridge_sigma_m**2))
    x[~ok], own[~ok], shared[~ok] = np.nan, np.nan, np.nan
    lat, lon, _ = ned_to_geodetic(x[:, 0], x[:, 1], 0.0, *ref, 0.0)
    return Smoothed(
        fixes.t_unix,
        ok,
        np.asarray(lat),
        np.asarray(lon),
        x[:, 0],
        x[:, 1],
        x[:, 2],
        x[:, 3],
        own,
        shared,
        gap,
        share,
        wave,
        accel,
    )


def through_smoother(
    fixes: Fixes, taken: np.ndarray, smoothed: Smoothed, max_speed_mps: float, z_ne_m: np.ndarray
) -> np.ndarray:
    """Another series ``z_ne_m`` (N×2, m, at the frames of ``fixes``) through the very smoother that made
    ``smoothed`` from ``fixes`` (its noise share and acceleration bounds, the fixes' covariances, the frames
    ``taken``): N×2, NaN where ``smoothed`` has no position. The smoother is linear in the positions, so an error's
    share of the smoothed track is this of its per-frame series (an error budget)."""
    taken = np.asarray(taken, bool) & (fixes.status == "ok") & np.isfinite(fixes.h_acc_m)
    idx = np.flatnonzero(taken)
    z = np.where(taken[:, None], np.nan_to_num(np.asarray(z_ne_m, float)), 0.0)
    x, _ = _rts(
        fixes.t_unix,
        z,
        _covariances(fixes, idx),
        taken,
        idx[0],
        idx[-1],
        smoothed.white_share,
        max_speed_mps,
        smoothed.accel_mps2,
    )
    return np.where(smoothed.ok[:, None], x[:, :2], np.nan)


@dataclass(frozen=True)
class FittedFixes:
    """The fixes ``idx`` of a recording as the smoother reads them: the first one's (lat, lon) ``ref``, every
    frame's (north, east) from it ``z`` (N×2, m), the covariances ``C`` (N×2×2, NaN at the other frames) and the
    :class:`LocalFits` of the fixes ``idx``."""

    idx: np.ndarray
    ref: tuple[float, float]
    z: np.ndarray
    C: np.ndarray
    fits: LocalFits


def fitted_fixes(fixes: Fixes, idx: np.ndarray) -> FittedFixes:
    """:class:`FittedFixes` of ``fixes``' frames ``idx`` (not empty)."""
    ref, z = _positions(fixes, idx)
    return FittedFixes(idx, ref, z, _covariances(fixes, idx), local_fits(fixes.t_unix[idx], z[idx]))


def recording_fits(fixes: Fixes, use: np.ndarray) -> FittedFixes | None:
    """:func:`fitted_fixes` of the fixes ``use`` (bool per frame; ok fixes with a finite ``h_acc_m``) of a whole
    recording; None where there is none."""
    idx = np.flatnonzero(
        np.asarray(use, bool) & (fixes.status == "ok") & np.isfinite(fixes.h_acc_m)
    )
    return fitted_fixes(fixes, idx) if len(idx) else None


def recording_jitter_share(fitted: FittedFixes | None) -> float:
    """The share of the fixes' covariance that their jitter over a wave's period shows (:func:`jitter_share`), over
    the fixes of a whole recording (:func:`recording_fits`); NaN from too few."""
    if fitted is None:
        return float("nan")
    return jitter_share(fitted.fits, fitted.C[fitted.idx])


def _positions(fixes: Fixes, idx: np.ndarray) -> tuple[tuple[float, float], np.ndarray]:
    """The first fix ``idx``'s (lat, lon) and every fix's (north, east) from it (N×2, m)."""
    ref = (float(fixes.lat[idx[0]]), float(fixes.lon[idx[0]]))
    zn, ze, _ = geodetic_to_ned(fixes.lat, fixes.lon, 0.0, *ref, 0.0)
    return ref, np.stack([zn, ze], axis=1)


def _covariances(fixes: Fixes, idx: np.ndarray) -> np.ndarray:
    """N×2×2 north-east covariances of the fixes ``idx`` (:func:`~localizer.uuv_track.fix_covariance_m2`), NaN at
    the other frames."""
    C = np.full((len(fixes), 2, 2), np.nan)
    for i in idx:
        C[i] = fix_covariance_m2(
            fixes.sigma_n_m[i], fixes.sigma_e_m[i], fixes.cov_ne_m2[i], fixes.h_acc_m[i]
        )
    return C


def white_share(t: np.ndarray, z: np.ndarray, C: np.ndarray) -> float:
    """``s²``: the share of the fixes' covariance that changes from frame to frame, over all of them
    (:class:`~localizer.uuv_track.Scatter`)."""
    scatter = Scatter(keep=max(1, len(t)))
    for ti, zi, Ci in zip(t, z, C):
        scatter.add(float(ti), zi, Ci)
    return scatter.share


@dataclass(frozen=True)
class LocalFits:
    """Per fix, a quadratic in time (least squares, each axis) through the fixes within half of :data:`WAVE_SPAN_S`
    of it, itself included; NaN where fewer than :data:`WAVE_MIN_FIXES`."""

    resid_m: np.ndarray  # N×2: the fix minus the quadratic at its time
    # N: the quadratic's weight on its own fix (the residual's variance: 1 − this of the noise's)
    leverage: np.ndarray
    accel_mps2: np.ndarray  # N×2: the quadratic's acceleration (twice its second-order coefficient)
    # N: the acceleration's variance per unit variance of the noise on one axis
    accel_gain: np.ndarray


def local_fits(t: np.ndarray, z: np.ndarray, span_s: float = WAVE_SPAN_S) -> LocalFits:
    """:class:`LocalFits` of fixes at times ``t`` (s, increasing) and positions ``z`` (N×2, m)."""
    n = len(t)
    resid, accel = np.full((n, 2), np.nan), np.full((n, 2), np.nan)
    leverage, gain = np.full(n, np.nan), np.full(n, np.nan)
    lo = np.searchsorted(t, t - span_s / 2.0, side="left")
    hi = np.searchsorted(t, t + span_s / 2.0, side="right")
    for k in np.flatnonzero(hi - lo >= WAVE_MIN_FIXES):
        dt = t[lo[k] : hi[k]] - t[k]
        X = np.column_stack([np.ones_like(dt), dt, dt * dt])
        inv = np.linalg.inv(X.T @ X)
        coef = inv @ (
            X.T @ z[lo[k] : hi[k]]
        )  # at its own time (dt = 0) the quadratic is its constant term
        resid[k], leverage[k] = z[k] - coef[0], inv[0, 0]
        accel[k], gain[k] = 2.0 * coef[2], 4.0 * inv[2, 2]
    return LocalFits(resid, leverage, accel, gain)


def jitter_share(fits: LocalFits, C: np.ndarray) -> float:
    """The share of the fixes' covariances ``C`` (N×2×2) that their residuals about the local quadratics show, as
    :class:`~localizer.uuv_track.Scatter` measures the frame-to-frame one (``q = rᵀ C⁻¹ r / (1 − h)``, a chi-square
    with 2 degrees of freedom per unit share, the floor added to ``C``), but from their median (``2 ln 2`` per unit
    share): a manoeuvre the quadratics cannot follow is not jitter; NaN from fewer than
    :data:`~localizer.uuv_track.SCATTER_MIN` fixes."""
    ok = np.isfinite(fits.leverage)
    if ok.sum() < SCATTER_MIN:
        return float("nan")
    r, Cn = fits.resid_m[ok], C[ok] + np.eye(2) * WHITE_FLOOR_M**2
    q = np.einsum("ki,ki->k", r, np.linalg.solve(Cn, r[..., None])[..., 0]) / (
        1.0 - fits.leverage[ok]
    )
    return float(np.median(q)) / (2.0 * math.log(2.0))


def data_accel_mps2(
    t: np.ndarray,
    idx: np.ndarray,
    gap_s: np.ndarray,
    fits: LocalFits,
    C: np.ndarray,
    share: float,
    max_accel_mps2: float,
) -> np.ndarray:
    """Per frame of ``t`` (the fixes taken at ``idx``, with their :class:`LocalFits` and covariances ``C``), the
    acceleration bound the data give, in place of the vehicle's ``max_accel_mps2`` (at most that).

    At a fix: the largest acceleration the local quadratics find within half of :data:`WAVE_SPAN_S` of it, each
    with :data:`ACCEL_SIGMAS` of its own sigma (the noise ``share·C`` through the fit). A frame without a fix of
    its own takes the larger of the fixes around it when they are within the span, else (a longer gap: the UUV
    unseen, it may have done anything) the vehicle's bound; so does a fix without a quadratic of its own, and
    every frame before the first fix or after the last.
    """
    noise_m2 = np.trace(share * C + np.eye(2) * WHITE_FLOOR_M**2, axis1=1, axis2=2)
    seen = np.hypot(*fits.accel_mps2.T) + ACCEL_SIGMAS * np.sqrt(fits.accel_gain * noise_m2)
    seen = np.where(np.isfinite(seen), seen, np.inf)
    ti = t[idx]
    lo = np.searchsorted(ti, ti - WAVE_SPAN_S / 2.0, side="left")
    hi = np.searchsorted(ti, ti + WAVE_SPAN_S / 2.0, side="right")
    level = np.array([seen[a:b].max() for a, b in zip(lo, hi)])
    per_frame = np.full(len(t), np.inf)
    per_frame[idx] = level
    for (a, b), la, lb in zip(pairwise(idx), level[:-1], level[1:]):
        if b > a + 1 and t[b] - t[a] <= WAVE_SPAN_S:
            per_frame[a + 1 : b] = max(la, lb)
    per_frame[~np.isfinite(gap_s)] = np.inf
    return np.minimum(per_frame, max_accel_mps2)


def _passed_jitter_scale(
    t,
    idx,
    fits: LocalFits,
    C,
    taken,
    share: float,
    max_speed_mps: float,
    accel_mps2,
    own_m2: np.ndarray,
) -> np.ndarray:
    """Per frame, the factor (at least 1) that makes the smoothed track's own covariance ``own_m2`` cover the jitter
    the smoother lets through: the fixes' residuals about their local quadratics (the jitter, time-correlated as it
    is) smoothed as the fixes were, their mean square over :data:`WAVE_SPAN_S` around the frame. The model's own
    covariance takes the noise as white, which a wave's jitter is not: where the data's acceleration is high (a
    manoeuvre) the smoother follows some of it."""
    resid = np.zeros((len(t), 2))
    resid[idx] = np.nan_to_num(fits.resid_m)
    through, _ = _rts(t, resid, C, taken, idx[0], idx[-1], share, max_speed_mps, accel_mps2)
    sq = np.where(np.isfinite(through[:, 0]), np.sum(through[:, :2] ** 2, axis=1), 0.0)
    counted = np.cumsum(np.r_[0, np.isfinite(through[:, 0])])
    summed = np.cumsum(np.r_[0.0, sq])
    lo = np.searchsorted(t, t - WAVE_SPAN_S / 2.0, side="left")
    hi = np.searchsorted(t, t + WAVE_SPAN_S / 2.0, side="right")
    with np.errstate(divide="ignore", invalid="ignore"):
        passed = (summed[hi] - summed[lo]) / (counted[hi] - counted[lo])
        scale = passed / np.trace(own_m2, axis1=1, axis2=2)
    return np.where(np.isfinite(scale), np.maximum(1.0, scale), 1.0)


def _rts(
    t,
    z,
    C,
    taken,
    first: int,
    last: int,
    share: float,
    max_speed_mps: float,
    accel_mps2: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Smoothed states (N×4) and covariances (N×4×4) from frame ``first`` to ``last`` (NaN outside); ``accel_mps2``:
    per frame, the acceleration bound over the step to it."""
    n = len(t)
    xf, Pf = np.full((n, 4), np.nan), np.full((n, 4, 4), np.nan)
    xp, Pp = xf.copy(), Pf.copy()
    track = UuvTrack(
        max_speed_mps, float(np.max(accel_mps2)), float(t[first]), z[first], C[first], share
    )
    xf[first], Pf[first] = track.x, track.P
    for k in range(first + 1, last + 1):
        a = float(accel_mps2[k])
        predicted = track.predict(float(t[k]), a)
        xp[k], Pp[k] = predicted
        if taken[k]:
            track.update(float(t[k]), z[k], C[k], share, a, predicted)
        else:
            track.coast(float(t[k]), a, predicted)
        xf[k], Pf[k] = track.x, track.P
    xs, Ps = xf.copy(), Pf.copy()
    for k in range(last - 1, first - 1, -1):
        F = transition(max(0.0, float(t[k + 1] - t[k])))
        G = np.linalg.solve(Pp[k + 1], F @ Pf[k]).T  # P_k Fᵀ (P⁻)⁻¹, both symmetric
        xs[k] = xf[k] + G @ (xs[k + 1] - xp[k + 1])
        Ps[k] = Pf[k] + G @ (Ps[k + 1] - Pp[k + 1]) @ G.T
    return xs, Ps


def _gaps(t: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Per frame: 0 at a fix taken (``idx``), the time between the fixes around it, inf before the first or after
    the last."""
    gap = np.full(len(t), np.inf)
    gap[idx] = 0.0
    for a, b in pairwise(idx):
        if b > a + 1:
            gap[a + 1 : b] = t[b] - t[a]
    return gap


def _shared(C: np.ndarray, idx: np.ndarray, share: float) -> np.ndarray:
    """Per frame, the shared part ``(1 − s²)·C`` of its fix's covariance; between fixes the larger (by trace) of
    the two around it. NaN outside the first and last."""
    out = np.full_like(C, np.nan)
    out[idx] = (1.0 - share) * C[idx]
    for a, b in pairwise(idx):
        if b > a + 1:
            out[a + 1 : b] = out[a] if np.trace(out[a]) >= np.trace(out[b]) else out[b]
    return out

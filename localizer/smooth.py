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

from dataclasses import dataclass
from itertools import pairwise

import numpy as np

from .fix import Fixes
from .geodesy import geodetic_to_ned, ned_to_geodetic
from .uuv_track import Scatter, UuvTrack, fix_covariance_m2, transition

#: A frame without a fix of its own is bridged while the smoothed position's own 1-sigma (its widest axis, the
#: shared error not included) is within this (m): a tracker's frame-to-frame jitter in waves (3.5–8.7 cm RMS per
#: frame at 1–3.5 m depth). With a BlueROV2's bounds (1.5 m/s, 3 m/s²) and 0.5–2 cm of white noise on fixes at 30 fps,
#: gaps up to about 1.7 s are bridged whole (the fixes on both sides hold the middle), and the first and last
#: 0.4–0.5 s of a longer one.
BRIDGE_SIGMA_M = 0.05


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
    white_share: float  # s², measured over the recording

    @property
    def cov_m2(self) -> np.ndarray:
        """N×2×2 north-east covariance against the truth (m²): own plus shared."""
        return self.cov_own_m2 + self.cov_shared_m2

    @property
    def h_acc_m(self) -> np.ndarray:
        """Horizontal accuracy (m, DRMS as a fix's ``h_acc_m``)."""
        C = self.cov_m2
        return np.sqrt(C[:, 0, 0] + C[:, 1, 1])


def smooth_fixes(fixes: Fixes, taken: np.ndarray, max_speed_mps: float, max_accel_mps2: float,
                 bridge_sigma_m: float = BRIDGE_SIGMA_M) -> Smoothed:
    """The smoothed track of ``fixes`` (times increasing) from those ``taken`` (ok fixes the gates took, with a
    finite ``h_acc_m``), for a UUV of top speed ``max_speed_mps`` and acceleration bound ``max_accel_mps2``."""
    taken = np.asarray(taken, bool) & (fixes.status == "ok") & np.isfinite(fixes.h_acc_m)
    n = len(fixes)
    nan2 = np.full((n, 2, 2), np.nan)
    idx = np.flatnonzero(taken)
    if not len(idx):
        empty = np.full(n, np.nan)
        return Smoothed(fixes.t_unix, np.zeros(n, bool), empty, empty, empty, empty, empty, empty, nan2, nan2.copy(),
                        np.full(n, np.inf), 1.0)
    ref = (float(fixes.lat[idx[0]]), float(fixes.lon[idx[0]]))
    zn, ze, _ = geodetic_to_ned(fixes.lat, fixes.lon, 0.0, *ref, 0.0)
    z = np.stack([zn, ze], axis=1)
    C = nan2.copy()
    for i in idx:
        C[i] = fix_covariance_m2(fixes.sigma_n_m[i], fixes.sigma_e_m[i], fixes.cov_ne_m2[i], fixes.h_acc_m[i])
    share = white_share(fixes.t_unix[idx], z[idx], C[idx])
    x, P = _rts(fixes.t_unix, z, C, taken, idx[0], idx[-1], share, max_speed_mps, max_accel_mps2)
    gap = _gaps(fixes.t_unix, idx)
    shared = _shared(C, idx, share)
    own = P[:, :2, :2]
    widest = np.array([np.linalg.eigvalsh(p)[-1] if np.all(np.isfinite(p)) else np.inf for p in own])
    ok = taken | (np.isfinite(gap) & (widest <= bridge_sigma_m**2))
    x[~ok], own[~ok], shared[~ok] = np.nan, np.nan, np.nan
    lat, lon, _ = ned_to_geodetic(x[:, 0], x[:, 1], 0.0, *ref, 0.0)
    return Smoothed(fixes.t_unix, ok, np.asarray(lat), np.asarray(lon), x[:, 0], x[:, 1], x[:, 2], x[:, 3], own,
                    shared, gap, share)


def white_share(t: np.ndarray, z: np.ndarray, C: np.ndarray) -> float:
    """``s²``: the share of the fixes' covariance that changes from frame to frame, over all of them
    (:class:`~localizer.uuv_track.Scatter`)."""
    scatter = Scatter(keep=max(1, len(t)))
    for ti, zi, Ci in zip(t, z, C):
        scatter.add(float(ti), zi, Ci)
    return scatter.share


def _rts(t, z, C, taken, first: int, last: int, share: float, max_speed_mps: float,
         max_accel_mps2: float) -> tuple[np.ndarray, np.ndarray]:
    """Smoothed states (N×4) and covariances (N×4×4) from frame ``first`` to ``last`` (NaN outside)."""
    n = len(t)
    xf, Pf = np.full((n, 4), np.nan), np.full((n, 4, 4), np.nan)
    xp, Pp = xf.copy(), Pf.copy()
    track = UuvTrack(max_speed_mps, max_accel_mps2, float(t[first]), z[first], C[first], share)
    xf[first], Pf[first] = track.x, track.P
    for k in range(first + 1, last + 1):
        xp[k], Pp[k] = track.predict(float(t[k]))
        if taken[k]:
            track.update(float(t[k]), z[k], C[k], share)
        else:
            track.coast(float(t[k]))
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
            gap[a + 1:b] = t[b] - t[a]
    return gap


def _shared(C: np.ndarray, idx: np.ndarray, share: float) -> np.ndarray:
    """Per frame, the shared part ``(1 − s²)·C`` of its fix's covariance; between fixes the larger (by trace) of
    the two around it. NaN outside the first and last."""
    out = np.full_like(C, np.nan)
    out[idx] = (1.0 - share) * C[idx]
    for a, b in pairwise(idx):
        if b > a + 1:
            out[a + 1:b] = out[a] if np.trace(out[a]) >= np.trace(out[b]) else out[b]
    return out

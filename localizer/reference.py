"""A reference of known position in view: the drone's absolute offset, and the fixes corrected by it.

The errors of the drone's pose that do not average out (the GNSS's walk, a compass or tilt bias, the height) put
everything the camera sees in the wrong place by about the same amount. A reference whose position is known (a
surveyed marker on the seafloor, a buoy or boat reporting its own GNSS) is located through the very geometry that
locates the UUV (:func:`localizer.fix.locate`: the reported pose, refraction at the surface, the reference's known
depth); ``known − located`` is then the offset the UUV's fixes share, and adding it to them removes it.

A moving reference (a buoy or boat reporting its GNSS) is where its reports put it at each frame's time
(:func:`reported_at`: interpolated between them, its 1-sigma theirs with its speed times how well their times are
known); the rest is the same.

The offset is taken over a window of :data:`WINDOW_S` around each fix (a plain GNSS walks over tens of seconds);
its 1-sigma per axis is the standard error of the window's 1-second means (:data:`BLOCK_S`: the waves' jitter of the
reference is correlated over about a second), at least the reference's own surveyed 1-sigma and :data:`MIN_SIGMA_M`.

A corrected fix's claim (:func:`correct`): the UAV position's term goes (the offset took it whole); of the camera's
tilt, heading and height errors, shared by the reference's sightings and the UUV's fix, what is left is what they
move the two differently: the difference of the UUV's and the reference's sensitivities (:func:`pose_jacobian`,
the latter averaged over the window's sightings, as the offset is) times the calibration's sigmas; the fix's own
terms (pixel, depth, time, waves, extrapolated attitude) stay; the offset's sigma is added. A fix is corrected only
where that claim is smaller than its own (:func:`applied`): a drone whose pose is already better than the
reference's offset (RTK, a reference seen far off or briefly) keeps its own fix.

North/east metres, seconds on the station clock.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .attitude import rotation_about
from .calibration import Calibration
from .fix import Fixes, locate
from .geodesy import geodetic_to_ned, ned_to_geodetic
from .pose import CameraPose
from .ray import pixel_to_offset
from .uncertainty import h_acc_from_cov_m

#: the offset at a fix is taken from the reference's sightings this long around it (s)
WINDOW_S = 10.0
#: sightings are averaged over blocks this long before their scatter is taken (s)
BLOCK_S = 1.0
#: the offset's 1-sigma per axis is never claimed below this (m)
MIN_SIGMA_M = 0.01
#: fewer blocks than this in a window: no offset there
MIN_BLOCKS = 3
#: a moving reference's position is interpolated only between reports at most this far apart (s)
MAX_GAP_S = 2.0
_ANGLE = 1e-4  # rad, the finite differences of pose_jacobian
_HEIGHT = 1e-3  # m


@dataclass(frozen=True)
class Reference:
    """A point of known position: WGS84 degrees, its depth below the water surface (m; 0 on it, a buoy), and how
    well it is known (1-sigma per horizontal axis, m). A moving reference's ``lat_deg``, ``lon_deg`` and ``sigma_m``
    are arrays (N,), one per frame (:func:`reported_at`; NaN where it has no position)."""

    lat_deg: float | np.ndarray
    lon_deg: float | np.ndarray
    depth_m: float
    sigma_m: float | np.ndarray = 0.0


@dataclass(frozen=True)
class Reports:
    """A moving reference's reported positions (a buoy's or boat's GNSS fixes): their times on the station clock
    (s, increasing), WGS84 degrees, and each one's stated 1-sigma per horizontal axis (m)."""

    t_unix: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    sigma_m: np.ndarray


def reported_at(reports: Reports, t_unix, depth_m: float, time_sigma_s: float) -> Reference:
    """Where a moving reference's ``reports`` put it at times ``t_unix`` (s, station clock): linear between the two
    reports around each time (north/east metres), NaN before the first, after the last or across a gap of more than
    :data:`MAX_GAP_S`; its ``sigma_m`` the larger of the two reports' with its speed there times ``time_sigma_s``
    (how well the reports' times are known: the GNSS's latency) added in quadrature."""
    t = np.asarray(t_unix, dtype=float)
    nan = np.full(t.shape, np.nan)
    tr = np.asarray(reports.t_unix, dtype=float)
    if len(tr) < 2:
        return Reference(nan, nan.copy(), depth_m, nan.copy())
    lat0, lon0 = float(reports.lat_deg[0]), float(reports.lon_deg[0])
    north, east, _ = geodetic_to_ned(reports.lat_deg, reports.lon_deg, 0.0, lat0, lon0, 0.0)
    i = np.clip(np.searchsorted(tr, t), 1, len(tr) - 1)
    gap = tr[i] - tr[i - 1]
    w = (t - tr[i - 1]) / gap
    dn, de = north[i] - north[i - 1], east[i] - east[i - 1]
    lat, lon, _ = ned_to_geodetic(north[i - 1] + w * dn, east[i - 1] + w * de, 0.0, lat0, lon0, 0.0)
    stated = np.maximum(reports.sigma_m[i - 1], reports.sigma_m[i])
    sigma = np.hypot(stated, np.hypot(dn, de) / gap * time_sigma_s)
    inside = (w >= 0) & (w <= 1) & (gap <= MAX_GAP_S)
    return Reference(
        np.where(inside, lat, np.nan),
        np.where(inside, lon, np.nan),
        depth_m,
        np.where(inside, sigma, np.nan),
    )


@dataclass(frozen=True)
class Offsets:
    """The absolute offset at N times: ``offset_ne_m`` (N, 2) known − located (NaN where none), ``sigma_ne_m`` (N, 2)
    its 1-sigma per axis, ``sightings`` (N,) the reference's located frames in each window; ``jacobian`` how the
    reference's located position moved with the camera's tilt, heading and height, as averaged into the offset."""

    t_unix: np.ndarray
    offset_ne_m: np.ndarray
    sigma_ne_m: np.ndarray
    sightings: np.ndarray
    # (N, 2, 4) the sightings' pose_jacobian averaged as the offset is (NaN where none)
    jacobian: np.ndarray

    def describe(self) -> str:
        """One line: the offset found (median over the times that have one) and its 1-sigma."""
        have = np.isfinite(self.offset_ne_m[:, 0])
        if not have.any():
            return "reference: no offset (too few sightings)"
        o = np.median(self.offset_ne_m[have], axis=0)
        s = np.median(self.sigma_ne_m[have], axis=0)
        return (
            f"reference: the drone's absolute offset north {o[0]:+.3f} ± {s[0]:.3f} m, east {o[1]:+.3f} ± {s[1]:.3f} m "
            f"(median over {have.sum()} of {len(have)} fixes; "
            f"{int(np.median(self.sightings[have]))} sightings a window of {WINDOW_S:g} s)"
        )


def pose_jacobian(cal: Calibration, pose: CameraPose, u, v, depth_m) -> np.ndarray:
    """How the point seen at pixels ``u``, ``v`` at ``depth_m`` moves (north, east; m) with the camera turned about
    North, East and Down (per radian) and raised (per metre): (N, 2, 4), NaN where it is not located."""
    n = cal.water.refractive_index
    R, h = pose.R_ned_from_cv, pose.height_m
    d = np.broadcast_to(np.asarray(depth_m, dtype=float), h.shape)
    with np.errstate(invalid="ignore"):
        base, _ = pixel_to_offset(cal.camera, R, u, v, h, d, n)
        cols = [
            (pixel_to_offset(cal.camera, rotation_about(axis, _ANGLE) @ R, u, v, h, d, n)[0] - base)
            / _ANGLE
            for axis in np.eye(3)
        ]
        cols.append((pixel_to_offset(cal.camera, R, u, v, h + _HEIGHT, d, n)[0] - base) / _HEIGHT)
    return np.stack(cols, axis=-1)


def sightings(cal: Calibration, pose: CameraPose, u, v, ref: Reference):
    """Each frame's offset (N, 2) known − located of the reference seen at pixels ``u``, ``v`` (NaN: not seen), whether
    it was located there (and the reference's position known), and its :func:`pose_jacobian` (N, 2, 4). ``pose`` is
    the frames' (its UUV depth is replaced by the reference's)."""
    n = len(pose.t_unix)
    at_ref = dataclasses.replace(
        pose, depth_m=np.full(n, float(ref.depth_m)), sigma_depth_m=np.zeros(n)
    )
    located = locate(cal, at_ref, u, v)
    lat0, lon0 = (
        np.broadcast_to(np.asarray(x, dtype=float), (n,)) for x in (ref.lat_deg, ref.lon_deg)
    )
    ok = (located.status == "ok") & np.isfinite(lat0)
    off = np.full((n, 2), np.nan)
    if ok.any():
        north, east, _ = geodetic_to_ned(
            located.lat[ok], located.lon[ok], 0.0, lat0[ok], lon0[ok], 0.0
        )
        off[ok] = -np.column_stack([north, east])
    return off, ok, pose_jacobian(cal, pose, u, v, ref.depth_m)


def offsets(t_sight, offset_ne_m, jacobian, t_unix, ref_sigma_m: float = 0.0) -> Offsets:
    """The offset, its 1-sigma and the averaged jacobian at times ``t_unix`` from the sightings' (``offset_ne_m``
    (M, 2) and ``jacobian`` (M, 2, 4) at ``t_sight``, NaN rows ignored): the mean of the :data:`BLOCK_S` means within
    :data:`WINDOW_S`, its standard error (see the module doc)."""
    t_sight = np.asarray(t_sight, dtype=float)
    o = np.asarray(offset_ne_m, dtype=float)
    jac = np.asarray(jacobian, dtype=float).reshape(len(o), 8)
    keep = np.all(np.isfinite(o), axis=1) & np.all(np.isfinite(jac), axis=1)
    t_sight, o, jac = t_sight[keep], o[keep], jac[keep]
    t = np.asarray(t_unix, dtype=float)
    out = np.full((len(t), 2), np.nan)
    sig = np.full((len(t), 2), np.nan)
    mean_jac = np.full((len(t), 8), np.nan)
    count = np.zeros(len(t), int)
    for i, ti in enumerate(t):
        near = np.abs(t_sight - ti) <= WINDOW_S / 2
        count[i] = int(near.sum())
        if not near.any():
            continue
        block = np.floor((t_sight[near] - (ti - WINDOW_S / 2)) / BLOCK_S).astype(int)
        # the window's end joins its last block
        block = np.minimum(block, round(WINDOW_S / BLOCK_S) - 1)
        labels, which = np.unique(block, return_inverse=True)
        if len(labels) < MIN_BLOCKS:
            continue
        per = np.bincount(which)
        means = np.stack(
            [np.bincount(which, weights=x) / per for x in np.column_stack([o[near], jac[near]]).T],
            axis=1,
        )
        out[i] = means[:, :2].mean(axis=0)
        mean_jac[i] = means[:, 2:].mean(axis=0)
        error = means[:, :2].std(axis=0, ddof=1) / np.sqrt(len(labels))
        sig[i] = np.maximum(np.hypot(error, ref_sigma_m), MIN_SIGMA_M)
    return Offsets(t, out, sig, count, mean_jac.reshape(len(t), 2, 4))


def applied(fixes: Fixes, better: Fixes) -> np.ndarray:
    """Where :func:`correct` moved ``fixes`` into ``better`` (its claim smaller than the fix's own), (N,) bool."""
    return better.h_acc_m < fixes.h_acc_m


def correct(cal: Calibration, pose: CameraPose, fixes: Fixes, found: Offsets) -> Fixes:
    """``fixes`` (made from ``pose`` and ``cal``) moved by the offset where there is one and its claim of the module
    doc is smaller than the fix's own; elsewhere unchanged."""
    use = (fixes.status == "ok") & np.all(np.isfinite(found.jacobian), axis=(1, 2))
    out = dataclasses.replace(fixes)
    for name in ("lat", "lon", "h_acc_m", "sigma_n_m", "sigma_e_m", "cov_ne_m2", "sigma_uav_m"):
        setattr(out, name, getattr(fixes, name).copy())
    if not use.any():
        return out
    n = len(pose.t_unix)
    # the shared terms taken out: ...
    own = dataclasses.replace(pose, sigma_uav_m=np.zeros(n), sigma_height_m=np.zeros(n))
    own_cal = dataclasses.replace(
        cal, sigmas=dataclasses.replace(cal.sigmas, tilt_deg=0.0, yaw_deg=0.0)
    )
    alone = locate(own_cal, own, fixes.u, fixes.v, sigma_px=fixes.sigma_pixel_px)
    # ... and put back as what they move the UUV and the reference differently
    diff = pose_jacobian(cal, pose, fixes.u, fixes.v, pose.depth_m)[use] - found.jacobian[use]
    tilt, yaw = np.radians(cal.sigmas.tilt_deg), np.radians(cal.sigmas.yaw_deg)
    # (K, 4)
    scale = np.stack(np.broadcast_arrays(tilt, tilt, yaw, pose.sigma_height_m[use]), axis=-1)
    js = diff * scale[:, None, :]
    cov = np.einsum("kaj,kbj->kab", js, js)
    s = found.sigma_ne_m[use]
    cov[:, 0, 0] += alone.sigma_n_m[use] ** 2 + s[:, 0] ** 2
    cov[:, 1, 1] += alone.sigma_e_m[use] ** 2 + s[:, 1] ** 2
    cov[:, 0, 1] += alone.cov_ne_m2[use]
    # the reference's claim against the fix's own: only a smaller one is taken
    h_acc = h_acc_from_cov_m(cov)
    smaller = h_acc < fixes.h_acc_m[use]
    use[use] = smaller
    cov, s, o, h_acc = cov[smaller], s[smaller], found.offset_ne_m[use], h_acc[smaller]
    if not use.any():
        return out
    out.lat[use], out.lon[use], _ = ned_to_geodetic(
        o[:, 0], o[:, 1], 0.0, fixes.lat[use], fixes.lon[use], 0.0
    )
    out.sigma_n_m[use], out.sigma_e_m[use] = np.sqrt(cov[:, 0, 0]), np.sqrt(cov[:, 1, 1])
    out.cov_ne_m2[use] = cov[:, 0, 1]
    out.h_acc_m[use] = h_acc
    out.sigma_uav_m[use] = np.hypot(s[:, 0], s[:, 1])
    return out

"""A reference of known position in view: the drone's absolute offset, and the fixes corrected by it.

The errors of the drone's pose that do not average out (the GNSS's walk, a compass or tilt bias, the height) put
everything the camera sees in the wrong place by about the same amount. A reference whose position is known (a
surveyed marker on the seafloor, a buoy or boat reporting its own GNSS) is located through the very geometry that
locates the UUV (:func:`localizer.fix.locate`: the reported pose, refraction at the surface, the reference's known
depth); ``known − located`` is then the offset the UUV's fixes share, and adding it to them removes it.

The offset is taken over a window of :data:`WINDOW_S` around each fix (a plain GNSS walks over tens of seconds);
its 1-sigma per axis is the standard error of the window's 1-second means (:data:`BLOCK_S`: the waves' jitter of the
reference is correlated over about a second), at least the reference's own surveyed 1-sigma and
:data:`MIN_SIGMA_M`. A corrected fix's claim drops the UAV position's term (the offset took it) and adds the
offset's sigma; the attitude's and the height's terms stay whole (the offset takes only their shared part: the
claim allows for them as before, so it only grows looser where the reference is far from the UUV in the image).

North/east metres, seconds on the station clock.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .calibration import Calibration
from .fix import Fixes, locate
from .geodesy import geodetic_to_ned, ned_to_geodetic
from .pose import CameraPose

#: the offset at a fix is taken from the reference's sightings this long around it (s)
WINDOW_S = 10.0
#: sightings are averaged over blocks this long before their scatter is taken (s)
BLOCK_S = 1.0
#: the offset's 1-sigma per axis is never claimed below this (m)
MIN_SIGMA_M = 0.01
#: fewer blocks than this in a window: no offset there
MIN_BLOCKS = 3


@dataclass(frozen=True)
class Reference:
    """A point of known position: WGS84 degrees, its depth below the water surface (m; 0 on it, a buoy), and how
    well it is known (1-sigma per horizontal axis, m)."""

    lat_deg: float
    lon_deg: float
    depth_m: float
    sigma_m: float = 0.0


@dataclass(frozen=True)
class Offsets:
    """The absolute offset at N times: ``offset_ne_m`` (N, 2) known − located (NaN where none), ``sigma_ne_m`` (N, 2)
    its 1-sigma per axis, ``sightings`` (N,) the reference's located frames in each window."""

    t_unix: np.ndarray
    offset_ne_m: np.ndarray
    sigma_ne_m: np.ndarray
    sightings: np.ndarray

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


def sightings(
    cal: Calibration, pose: CameraPose, u, v, ref: Reference
) -> tuple[np.ndarray, np.ndarray]:
    """Each frame's offset (N, 2) known − located of the reference seen at pixels ``u``, ``v`` (NaN: not seen), and
    whether it was located there. ``pose`` is the frames' (its UUV depth is replaced by the reference's)."""
    n = len(pose.t_unix)
    at_ref = dataclasses.replace(
        pose, depth_m=np.full(n, float(ref.depth_m)), sigma_depth_m=np.zeros(n)
    )
    located = locate(cal, at_ref, u, v)
    ok = located.status == "ok"
    off = np.full((n, 2), np.nan)
    if ok.any():
        north, east, _ = geodetic_to_ned(
            located.lat[ok], located.lon[ok], 0.0, ref.lat_deg, ref.lon_deg, 0.0
        )
        off[ok] = -np.column_stack([north, east])
    return off, ok


def offsets(t_sight, offset_ne_m, t_unix, ref_sigma_m: float = 0.0) -> Offsets:
    """The offset and its 1-sigma at times ``t_unix`` from the sightings' offsets (``offset_ne_m`` (M, 2) at
    ``t_sight``, NaN rows ignored): the mean of the :data:`BLOCK_S` means within :data:`WINDOW_S`, its standard
    error (see the module doc)."""
    t_sight = np.asarray(t_sight, dtype=float)
    o = np.asarray(offset_ne_m, dtype=float)
    keep = np.all(np.isfinite(o), axis=1)
    t_sight, o = t_sight[keep], o[keep]
    t = np.asarray(t_unix, dtype=float)
    out = np.full((len(t), 2), np.nan)
    sig = np.full((len(t), 2), np.nan)
    count = np.zeros(len(t), int)
    for i, ti in enumerate(t):
        near = np.abs(t_sight - ti) <= WINDOW_S / 2
        count[i] = int(near.sum())
        if not near.any():
            continue
        block = np.floor((t_sight[near] - (ti - WINDOW_S / 2)) / BLOCK_S).astype(int)
        block = np.minimum(
            block, round(WINDOW_S / BLOCK_S) - 1
        )  # the window's end joins its last block
        labels, which = np.unique(block, return_inverse=True)
        if len(labels) < MIN_BLOCKS:
            continue
        means = np.stack(
            [np.bincount(which, weights=o[near, a]) / np.bincount(which) for a in range(2)], axis=1
        )
        out[i] = means.mean(axis=0)
        error = means.std(axis=0, ddof=1) / np.sqrt(len(labels))
        sig[i] = np.maximum(np.hypot(error, ref_sigma_m), MIN_SIGMA_M)
    return Offsets(t, out, sig, count)


def corrected(fixes: Fixes, without_position: Fixes, found: Offsets) -> Fixes:
    """``fixes`` moved by the offset where there is one; their claim: ``without_position``'s (the same fixes located
    with the UAV position's sigma 0) with the offset's sigma added. Elsewhere unchanged."""
    out = dataclasses.replace(fixes)
    for name in ("lat", "lon", "h_acc_m", "sigma_n_m", "sigma_e_m", "cov_ne_m2", "sigma_uav_m"):
        setattr(out, name, getattr(fixes, name).copy())
    use = (fixes.status == "ok") & np.isfinite(found.offset_ne_m[:, 0])
    if not use.any():
        return out
    o, s = found.offset_ne_m[use], found.sigma_ne_m[use]
    out.lat[use], out.lon[use], _ = ned_to_geodetic(
        o[:, 0], o[:, 1], 0.0, fixes.lat[use], fixes.lon[use], 0.0
    )
    sn = np.hypot(without_position.sigma_n_m[use], s[:, 0])
    se = np.hypot(without_position.sigma_e_m[use], s[:, 1])
    out.sigma_n_m[use], out.sigma_e_m[use] = sn, se
    out.cov_ne_m2[use] = without_position.cov_ne_m2[use]
    out.h_acc_m[use] = np.hypot(sn, se)
    out.sigma_uav_m[use] = np.hypot(s[:, 0], s[:, 1])
    return out

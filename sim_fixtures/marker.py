"""A surveyed marker on the seafloor (``[marker]``): a reference of known position in the image.

The marker is a bullseye painted into the floor's texture (a white disc, a black centre of half its radius), so it is
seen through the same water, waves and caustics as the floor. The session gets what a team that surveyed it would
state, ``reference.toml`` (its WGS84 position, its depth, the survey's 1-sigma), and the simulator's truth of its
centre's pixel per frame, ``reference_track.csv`` (``t,u,v``; empty where it is outside the image), projected as
track.csv's (:func:`~sim_fixtures.generate.reference_pixel` through the flat surface).
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from .geometry import ned_to_geodetic
from .scenario import Scenario

REFERENCE_TOML = "reference.toml"
REFERENCE_TRACK_CSV = "reference_track.csv"
WHITE_BGR = (235.0, 235.0, 235.0)
BLACK_BGR = (20.0, 20.0, 20.0)


def marker_ned(sc: Scenario) -> np.ndarray:
    """The marker's centre (3,), world NED: on the seafloor."""
    m = sc.marker
    return np.array(
        [sc.uuv.north_m + m.north_m, sc.uuv.east_m + m.east_m, sc.site.floor_depth_m], dtype=float
    )


def paint(floor: np.ndarray, sc: Scenario, m_per_px: float) -> None:
    """Paint the marker into the floor texture (H, W, 3 uint8; pixel x = east / m_per_px, y = −north / m_per_px,
    wrapped), in place; nothing without ``[marker] enabled``."""
    if not sc.marker.enabled:
        return
    size_y, size_x = floor.shape[:2]
    n, e, _ = marker_ned(sc)
    x0, y0 = (e / m_per_px) % size_x, (-n / m_per_px) % size_y
    r = sc.marker.radius_m / m_per_px
    yy, xx = np.mgrid[0:size_y, 0:size_x].astype(np.float32)
    dist = np.hypot(
        (xx - x0 + size_x / 2) % size_x - size_x / 2, (yy - y0 + size_y / 2) % size_y - size_y / 2
    )
    floor[dist <= r] = WHITE_BGR
    floor[dist <= r / 2] = BLACK_BGR


def write_reference(out: Path, sc: Scenario, t_unix, u, v, width: int, height: int) -> None:
    """``reference.toml`` and ``reference_track.csv`` (see the module doc) into ``out``; removes an earlier
    generated session's when the scenario has no marker."""
    toml, track = out / REFERENCE_TOML, out / REFERENCE_TRACK_CSV
    if not sc.marker.enabled:
        toml.unlink(missing_ok=True)
        track.unlink(missing_ok=True)
        return
    lat, lon, _ = ned_to_geodetic(marker_ned(sc), sc.site.lat_deg, sc.site.lon_deg, 0.0)
    toml.write_text(
        f"# a surveyed marker on the seafloor (skyfix sim, scenario {sc.name!r})\n"
        f"lat_deg = {float(lat)!r}\nlon_deg = {float(lon)!r}\n"
        f"depth_m = {float(sc.site.floor_depth_m)!r}\nsigma_m = 0.0\n"
        f"radius_m = {float(sc.marker.radius_m)!r}\n"
    )
    write_track(track, t_unix, u, v, width, height)


def write_track(track: Path, t_unix, u, v, width: int, height: int) -> None:
    """A reference's pixel per frame (``t,u,v``) into ``track``, empty where it is outside the image."""
    inside = (u >= 0) & (u <= width - 1) & (v >= 0) & (v <= height - 1)
    with open(track, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(("t", "u", "v"))
        for t, a, b, ok in zip(t_unix, u, v, inside):
            w.writerow((f"{t:.6f}", f"{a:.4f}" if ok else "", f"{b:.4f}" if ok else ""))

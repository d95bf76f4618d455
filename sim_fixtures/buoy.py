"""A buoy drifting on the surface that reports its GNSS over MAVLink (``[buoy]``): a moving reference of known
position in the image.

Motion: its marked top's centre, at ``depth_m`` below the still surface, starts ``north_m``, ``east_m`` from the
UUV's path centre, drifts at ``drift_mps`` and swings on its mooring, ``swing_m`` · sin(2π τ / ``swing_period_s``)
north and ``swing_m`` · sin(2π τ / (1.6 ``swing_period_s``) + 1) east (:func:`buoy_ned`).

Look: a level square hull 2.6 ``radius_m`` across and ``draft_m`` deep whose top is painted as the seafloor marker
(:mod:`sim_fixtures.marker`): a white disc of ``radius_m``, a black centre of half of it, the dark hull around
(:func:`albedo`; ray cast by :mod:`sim_fixtures.render` as the vehicles are).

GNSS: GPS_RAW_INT from system ``system_id`` (component 1) at ``gnss_hz``: the antenna over the bullseye's centre,
its error per axis a first-order Gauss-Markov process of ``gnss_sigma_m`` and ``gnss_correlation_s`` (an RTK
receiver's multipath wanders; the white part is small), ``fix_type`` 6 (RTK fixed), ``h_acc`` √2 · ``gnss_sigma_m``
(mm: its horizontal 1-sigma, both axes), ``time_usec`` the fix's true UNIX µs; received by the station after
``link_delay_s`` plus an exponential jitter of mean ``link_jitter_s`` (its own radio), in order: records the
generator merges into ``uav.tlog`` (:func:`gnss_records`), as a ground station records everything it hears.

The session gets what a team would configure, ``reference.toml`` (the buoy's system id, its marking's depth and
radius: :mod:`groundstation.offline.reference`), the simulator's truth of the bullseye's pixel per frame,
``reference_track.csv`` (as the marker's), and its true position per frame, ``buoy_truth.csv`` (``t,lat,lon``).
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from groundstation.mavlink.ingest import mavutil

from .geometry import ned_to_geodetic
from .marker import BLACK_BGR, REFERENCE_TOML, REFERENCE_TRACK_CSV, WHITE_BGR, write_track
from .scenario import Scenario
from .tlog import SEND_LATENCY_US, Clock, exponential

BUOY_TRUTH_CSV = "buoy_truth.csv"
HULL_PER_RADIUS = 2.6  # the hull's side over the white disc's radius
HULL_BGR = (40.0, 45.0, 110.0)  # a dark red hull
GPS_FIX_TYPE_RTK_FIXED = 6


def rng(sc: Scenario, k: int) -> np.random.Generator:
    """The buoy's own random streams (its GNSS error, its link)."""
    return np.random.default_rng([sc.seed, 505, k])


def buoy_ned(sc: Scenario, tau_s) -> np.ndarray:
    """The centre of the buoy's marked top at scenario times ``tau_s``, world NED (..., 3)."""
    b = sc.buoy
    tau = np.asarray(tau_s, dtype=float)
    w = 2 * np.pi * tau / b.swing_period_s
    north = sc.uuv.north_m + b.north_m + b.drift_mps[0] * tau + b.swing_m * np.sin(w)
    east = sc.uuv.east_m + b.east_m + b.drift_mps[1] * tau + b.swing_m * np.sin(w / 1.6 + 1.0)
    return np.stack([north, east, np.full_like(tau, b.depth_m)], axis=-1)


def hull_m(sc: Scenario) -> tuple[float, float, float]:
    """The hull's length, width and height (m): a square :data:`HULL_PER_RADIUS` of the disc's radius across."""
    side = HULL_PER_RADIUS * sc.buoy.radius_m
    return side, side, sc.buoy.draft_m


def albedo(point, face_axis, radius_m: float):
    """The buoy seen from above (BGR): the bullseye on its top (white disc of ``radius_m``, black centre of half
    of it), the dark hull around and on its sides; ``point`` (N, 3) in its body frame."""
    r = np.hypot(point[:, 0], point[:, 1])
    col = np.tile(np.array(HULL_BGR), (len(r), 1))
    top = face_axis == 2
    col[top & (r <= radius_m)] = WHITE_BGR
    col[top & (r <= radius_m / 2)] = BLACK_BGR
    return col * np.where(top, 1.0, 0.55)[:, None]


def gnss_error_ne_m(sc: Scenario, tau_s) -> np.ndarray:
    """The GNSS's error (north, east; m) at increasing times ``tau_s``: per axis a first-order Gauss-Markov process
    of 1-sigma ``gnss_sigma_m`` and correlation time ``gnss_correlation_s``, stationary from the first sample."""
    b = sc.buoy
    tau = np.asarray(tau_s, dtype=float)
    white = rng(sc, 1).standard_normal((len(tau), 2))
    keep = np.exp(-np.diff(tau, prepend=tau[:1]) / b.gnss_correlation_s)
    out = white.copy()
    for i in range(1, len(tau)):
        out[i] = keep[i] * out[i - 1] + np.sqrt(1.0 - keep[i] ** 2) * white[i]
    return b.gnss_sigma_m * out


def gnss_records(sc: Scenario, clock: Clock, tau0_s: float) -> list[tuple[int, bytes]]:
    """The buoy's GPS_RAW_INT as tlog records ``(station µs received, MAVLink 2 frame)`` from scenario time
    ``tau0_s`` to the end (see the module doc); none without ``[buoy] enabled``."""
    b, s = sc.buoy, sc.site
    if not b.enabled:
        return []
    tau = np.arange(tau0_s, sc.duration_s, 1.0 / b.gnss_hz)
    true_us = clock.true_us(tau)
    ned = buoy_ned(sc, tau)
    ned[:, :2] += gnss_error_ne_m(sc, tau)
    lat, lon, alt = ned_to_geodetic(ned, s.lat_deg, s.lon_deg, s.surface_amsl_m)
    dt = 1e-3
    vel = (buoy_ned(sc, tau + dt) - buoy_ned(sc, tau - dt)) / (2 * dt)
    speed = np.hypot(vel[:, 0], vel[:, 1])
    cog = np.round(np.degrees(np.arctan2(vel[:, 1], vel[:, 0])) % 360 * 100).astype(int) % 36000
    delay = b.link_delay_s + exponential(rng(sc, 2), b.link_jitter_s, len(tau))
    recv_us = np.maximum.accumulate(true_us + SEND_LATENCY_US + np.round(delay * 1e6).astype(int))
    h_acc = round(np.sqrt(2.0) * b.gnss_sigma_m * 1000)
    mav = mavutil().mavlink.MAVLink(None, srcSystem=b.system_id, srcComponent=1)
    out = []
    for tu, la, lo, a, v, c, r in zip(
        true_us, lat, lon, alt, speed, cog, clock.station_us(recv_us)
    ):
        msg = mav.gps_raw_int_encode(
            int(tu),
            GPS_FIX_TYPE_RTK_FIXED,
            round(la * 1e7),
            round(lo * 1e7),
            round(a * 1000),
            70,
            120,
            round(v * 100),
            int(c),
            20,
            round((a + s.geoid_separation_m) * 1000),
            h_acc,
            2 * h_acc,
            30,
            0,
            0,
        )
        out.append((int(r), msg.pack(mav)))
    return out


def write_buoy(out: Path, sc: Scenario, t_unix, ned, u, v, width: int, height: int) -> None:
    """``reference.toml``, ``reference_track.csv`` and ``buoy_truth.csv`` (see the module doc) into ``out``, the
    buoy's true position ``ned`` (N, 3) and its bullseye's pixel ``u``, ``v`` at the frames' times ``t_unix``;
    removes an earlier generated session's buoy_truth.csv when the scenario has no buoy."""
    truth = out / BUOY_TRUTH_CSV
    if not sc.buoy.enabled:
        truth.unlink(missing_ok=True)
        return
    b = sc.buoy
    (out / REFERENCE_TOML).write_text(
        f"# a buoy reporting its GNSS over MAVLink (skyfix sim, scenario {sc.name!r})\n"
        f"system_id = {b.system_id}\ndepth_m = {float(b.depth_m)!r}\n"
        f"radius_m = {float(b.radius_m)!r}\n"
    )
    write_track(out / REFERENCE_TRACK_CSV, t_unix, u, v, width, height)
    lat, lon, _ = ned_to_geodetic(ned, sc.site.lat_deg, sc.site.lon_deg, 0.0)
    with open(truth, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(("t", "lat", "lon"))
        for row in zip(t_unix, lat, lon):
            w.writerow((f"{row[0]:.6f}", f"{row[1]:.9f}", f"{row[2]:.9f}"))

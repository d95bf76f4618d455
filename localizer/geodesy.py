"""Local North-East-Down offsets ↔ WGS84 latitude/longitude, through pymap3d.

Altitudes are treated as ellipsoidal heights: over the tens of metres a camera
sees, the geoid's separation is a constant that shifts nothing horizontally.
Degrees and metres; scalars or arrays.
"""

from __future__ import annotations

import numpy as np
import pymap3d


def ned_to_geodetic(north_m, east_m, down_m, lat0_deg, lon0_deg, alt0_m):
    """Latitude, longitude (degrees) and altitude (m) of a point at a NED offset from an origin."""
    lat, lon, alt = pymap3d.ned2geodetic(
        np.asarray(north_m, float),
        np.asarray(east_m, float),
        np.asarray(down_m, float),
        lat0_deg,
        lon0_deg,
        alt0_m,
    )
    return np.asarray(lat), np.asarray(lon), np.asarray(alt)


def geodetic_to_ned(lat_deg, lon_deg, alt_m, lat0_deg, lon0_deg, alt0_m):
    """NED offset (m) of a geodetic point from an origin."""
    n, e, d = pymap3d.geodetic2ned(
        np.asarray(lat_deg, float),
        np.asarray(lon_deg, float),
        np.asarray(alt_m, float),
        lat0_deg,
        lon0_deg,
        alt0_m,
    )
    return np.asarray(n), np.asarray(e), np.asarray(d)


def horizontal_error_m(lat_deg, lon_deg, lat_true_deg, lon_true_deg):
    """Horizontal distance (m) between estimated and true positions (local tangent plane)."""
    n, e, _ = geodetic_to_ned(lat_deg, lon_deg, 0.0, lat_true_deg, lon_true_deg, 0.0)
    return np.hypot(n, e)

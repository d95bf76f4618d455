"""localizer.geodesy (pymap3d) against pyproj: ECEF transforms and geodesics on WGS84."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pyproj import Geod, Transformer

from localizer.geodesy import geodetic_to_ned, horizontal_error_m, ned_to_geodetic

TO_ECEF = Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)
FROM_ECEF = Transformer.from_crs("EPSG:4978", "EPSG:4979", always_xy=True)
GEOD = Geod(ellps="WGS84")


def ecef_from_ned_axes(lat_deg, lon_deg):
    """Columns: North, East, Down unit vectors in ECEF at a geodetic point."""
    p, lam = math.radians(lat_deg), math.radians(lon_deg)
    north = [-math.sin(p) * math.cos(lam), -math.sin(p) * math.sin(lam), math.cos(p)]
    east = [-math.sin(lam), math.cos(lam), 0.0]
    down = [-math.cos(p) * math.cos(lam), -math.cos(p) * math.sin(lam), -math.sin(p)]
    return np.array([north, east, down]).T


def pyproj_ned_to_geodetic(n, e, d, lat0, lon0, alt0):
    origin = np.array(TO_ECEF.transform(lon0, lat0, alt0))
    x, y, z = origin + ecef_from_ned_axes(lat0, lon0) @ [n, e, d]
    lon, lat, alt = FROM_ECEF.transform(x, y, z)
    return lat, lon, alt


def metres_apart(lat1, lon1, lat2, lon2):
    return GEOD.inv(lon1, lat1, lon2, lat2)[2]


origin = {
    "lat0": st.sampled_from([0.0, 23.4, 47.5, -33.9, 60.2, 78.2]) | st.floats(-80, 80),
    "lon0": st.floats(-179.9, 179.9),
    "alt0": st.floats(-50, 3000),
}
offset = {
    "n": st.floats(-3000, 3000),
    "e": st.floats(-3000, 3000),
    "d": st.floats(-100, 200),
}


@settings(max_examples=200, deadline=None)
@given(**origin, **offset)
def test_ned_to_geodetic_matches_pyproj_ecef(lat0, lon0, alt0, n, e, d):
    lat, lon, alt = ned_to_geodetic(n, e, d, lat0, lon0, alt0)
    lat_p, lon_p, alt_p = pyproj_ned_to_geodetic(n, e, d, lat0, lon0, alt0)
    assert metres_apart(lat, lon, lat_p, lon_p) < 1e-3
    assert abs(alt - alt_p) < 1e-3


@settings(max_examples=200, deadline=None)
@given(**origin, **offset)
def test_geodetic_to_ned_inverts(lat0, lon0, alt0, n, e, d):
    lat, lon, alt = pyproj_ned_to_geodetic(n, e, d, lat0, lon0, alt0)
    n2, e2, d2 = geodetic_to_ned(lat, lon, alt, lat0, lon0, alt0)
    assert math.hypot(n2 - n, e2 - e) < 1e-3 and abs(d2 - d) < 1e-3


@settings(max_examples=200, deadline=None)
@given(
    lat0=st.floats(-80, 80),
    lon0=st.floats(-179.9, 179.9),
    dist=st.floats(0.01, 3000),
    az=st.floats(-180, 180),
)
def test_horizontal_offset_is_the_geodesic(lat0, lon0, dist, az):
    """A tangent-plane offset of a few km lands where pyproj's geodesic does (< 1 mm)."""
    n, e = dist * math.cos(math.radians(az)), dist * math.sin(math.radians(az))
    lat, lon, _ = ned_to_geodetic(n, e, 0.0, lat0, lon0, 0.0)
    lon_g, lat_g, _ = GEOD.fwd(lon0, lat0, az, dist)
    # the tangent plane rises d²/2R above the ellipsoid; its foot is d³/3R² ≈ 0.2 mm short
    assert metres_apart(lat, lon, lat_g, lon_g) < 1e-3
    assert horizontal_error_m(lat, lon, lat0, lon0) == pytest.approx(dist, abs=1e-3)


def test_batched_arrays():
    n = np.array([0.0, 10.0, -250.0])
    e = np.array([0.0, -5.0, 1200.0])
    d = np.array([32.0, 31.5, 30.0])
    lat, lon, alt = ned_to_geodetic(n, e, d, 47.5, 8.5, 412.0)
    assert lat.shape == lon.shape == alt.shape == (3,)
    for i in range(3):
        exp = pyproj_ned_to_geodetic(n[i], e[i], d[i], 47.5, 8.5, 412.0)
        assert metres_apart(lat[i], lon[i], exp[0], exp[1]) < 1e-3
    err = horizontal_error_m(lat, lon, np.full(3, 47.5), np.full(3, 8.5))
    # along the ellipsoid, not at 380 m altitude where the offsets were measured (h/R shorter)
    assert np.allclose(err, [metres_apart(lat[i], lon[i], 47.5, 8.5) for i in range(3)], atol=1e-3)

"""Geometry-only processing of every bundled session recovers the truth; the straight ray does not.

Pixels from track.csv, telemetry from the tlog as any recorded session: what is
left is the telemetry's own quantization (lat/lon 1e-7 degrees, altitude 1 mm,
float32 angles) and interpolation between samples, a few millimetres.
"""

import numpy as np
import pytest
from pyproj import Geod

from groundstation.offline.evaluate import errors_m
from groundstation.offline.process import process_session
from groundstation.session.read import load_session
from sim_fixtures.bundle import BUNDLED, BUNDLED_DIR, SCENARIOS
from sim_fixtures.generate import camera_of, frame_truth
from sim_fixtures.motion import Motion
from sim_fixtures.scenario import load_scenario

GEOD = Geod(ellps="WGS84")


@pytest.mark.parametrize("name", BUNDLED)
def test_geometry_only_recovers_truth_within_5_mm(name):
    session = load_session(BUNDLED_DIR / name)
    # only clock_offset's warnings, which are its point: clocks that disagree
    assert all("GNSS time" in w or "UUV's clock" in w for w in session.warnings) and (
        bool(session.warnings) == (name == "clock_offset")
    )
    fixes = process_session(session, use_track=True, refraction=True)
    ok = fixes.status == "ok"
    seen = np.isfinite(session.track["u"])
    assert np.array_equal(ok, seen)  # a fix exactly where the UUV is visible
    assert set(fixes.status[~seen]) <= {"no_track"}
    lat = np.interp(fixes.t_unix[ok], session.truth["t"], session.truth["lat"])
    lon = np.interp(fixes.t_unix[ok], session.truth["t"], session.truth["lon"])
    _, _, dist = GEOD.inv(fixes.lon[ok], fixes.lat[ok], lon, lat)
    assert np.mean(dist) < 0.005 and np.max(dist) < 0.012, (np.mean(dist), np.max(dist))
    assert np.allclose(errors_m(fixes, session.truth)[ok], dist, atol=1e-6)


def test_straight_ray_error_is_the_refraction_offset():
    """The oblique 2 m case: the straight ray's error is d·(tan θ_air − tan θ_water), ~0.3 m."""
    sc = load_scenario(SCENARIOS / "oblique_2m.toml")
    truth = frame_truth(sc, Motion(sc), camera_of(sc))
    rel = truth.uuv_ned - truth.camera_ned
    session = load_session(BUNDLED_DIR / "oblique_2m")
    fixes = process_session(session, use_track=True, refraction=False)
    err = errors_m(fixes, session.truth)
    # true air angle from the camera to where its ray meets the surface, by bisection on Snell
    h, d, rho = -truth.camera_ned[:, 2], truth.uuv_ned[:, 2], np.hypot(rel[:, 0], rel[:, 1])
    lo, hi = np.zeros_like(rho), rho.copy()
    for _ in range(60):
        x = (lo + hi) / 2
        sin_w = np.sin(np.arctan2(x, h)) / sc.site.refractive_index
        f = x + d * np.tan(np.arcsin(sin_w)) - rho
        lo, hi = np.where(f < 0, x, lo), np.where(f < 0, hi, x)
    tan_a = x / h
    tan_w = np.tan(np.arcsin(np.sin(np.arctan(tan_a)) / sc.site.refractive_index))
    expected = d * (tan_a - tan_w)
    assert 0.2 < np.mean(err) < 0.5
    assert np.allclose(err, expected, atol=0.01)

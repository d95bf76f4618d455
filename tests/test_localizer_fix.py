"""Whole fixes (calibration + telemetry → pose → locate → lat/lon).

Hand-worked views, both water references, no-fix statuses.

Expected positions come from trigonometry by hand and pyproj's geodesic (Geod.fwd).
"""

import math

import numpy as np
import pytest
from conftest import T0_UNIX
from pyproj import Geod

from localizer.fix import locate
from localizer.pose import camera_pose
from localizer.surface import height_above_surface_m

GEOD = Geod(ellps="WGS84")
N_WATER = 1.34
LAT, LON = 47.5, 8.5


def fix_at_principal_point(cal, tel, refraction=True):
    pose = camera_pose(cal, tel, T0_UNIX + 1.0)
    return locate(cal, pose, cal.camera.cx, cal.camera.cy, refraction=refraction)[0]


def metres_from(f, dist_m, az_deg):
    """Metres from the fix to the point ``dist_m`` from the UAV along azimuth ``az_deg``."""
    lon, lat, _ = GEOD.fwd(LON, LAT, az_deg, dist_m)
    return GEOD.inv(f.lon, f.lat, lon, lat)[2]


@pytest.mark.parametrize("heading_deg", [0.0, 30.0, -120.0])
def test_45_degree_oblique_fix(make_cal, make_telemetry, heading_deg):
    h, d = 30.0, 2.0
    cal = make_cal()
    # UAV at h + d above the ellipsoid puts the UUV on it, where pyproj's geodesic runs
    tel = make_telemetry(
        height_m=h,
        gimbal_ypr_deg=(heading_deg, -45.0, 0.0),
        depth_m=d,
        lat=LAT,
        lon=LON,
        alt_amsl_m=h + d,
    )
    bent = fix_at_principal_point(cal, tel)
    straight = fix_at_principal_point(cal, tel, refraction=False)
    assert bent.status == straight.status == "ok"
    theta_w = math.asin(math.sin(math.radians(45.0)) / N_WATER)
    assert metres_from(bent, h * 1.0 + d * math.tan(theta_w), heading_deg) < 1e-3
    assert metres_from(straight, (h + d) * 1.0, heading_deg) < 1e-3
    assert bent.depth_m == d
    assert bent.alt_amsl_m == pytest.approx(0.0, abs=1e-9)


def test_nadir_fix_is_below_the_camera(make_cal, make_telemetry):
    tel = make_telemetry(gimbal_ypr_deg=(77.0, -90.0, 0.0), depth_m=3.0, lat=LAT, lon=LON)
    for refraction in (True, False):
        f = fix_at_principal_point(make_cal(), tel, refraction)
        assert metres_from(f, 0.0, 0.0) < 1e-6


FACTS_TABLE = {20: (0.10, 0.20, 0.30), 30: (0.18, 0.35, 0.53), 35: (0.23, 0.45, 0.68)}  # facts.md


@pytest.mark.parametrize("off_nadir_deg", sorted(FACTS_TABLE))
def test_straight_ray_error_matches_facts_table(make_cal, make_telemetry, off_nadir_deg):
    cal = make_cal()
    for depth_m, table_m in zip((1.0, 2.0, 3.0), FACTS_TABLE[off_nadir_deg]):
        tel = make_telemetry(
            height_m=25.0, gimbal_ypr_deg=(60.0, off_nadir_deg - 90.0, 0.0), depth_m=depth_m
        )
        bent = fix_at_principal_point(cal, tel)
        straight = fix_at_principal_point(cal, tel, refraction=False)
        gap = GEOD.inv(bent.lon, bent.lat, straight.lon, straight.lat)[2]
        assert gap == pytest.approx(table_m, abs=0.006)


def test_both_water_references_give_the_same_fix(make_cal, make_telemetry):
    gimbal = (20.0, -50.0, 3.0)
    a_cal = make_cal(water={"takeoff_height_above_surface_m": 2.0})
    a = make_telemetry(
        height_m=30.0, takeoff_above_surface_m=2.0, alt_amsl_m=30.35, gimbal_ypr_deg=gimbal
    )
    b_cal = make_cal(water={"surface_amsl_m": 0.35})
    b = make_telemetry(height_m=30.0, surface_amsl_m=0.35, gimbal_ypr_deg=gimbal)
    pa = camera_pose(a_cal, a, T0_UNIX + 1.0)
    pb = camera_pose(b_cal, b, T0_UNIX + 1.0)
    assert pa.height_m[0] == pytest.approx(30.0) and pb.height_m[0] == pytest.approx(30.0)
    fa = locate(a_cal, pa, 400.0, 700.0)[0]
    fb = locate(b_cal, pb, 400.0, 700.0)[0]
    assert fa.ok and fb.ok
    assert GEOD.inv(fa.lon, fa.lat, fb.lon, fb.lat)[2] < 1e-3
    assert (fa.north_m, fa.east_m) == pytest.approx((fb.north_m, fb.east_m), abs=1e-9)
    # the UUV's altitude: the surface's altitude minus its depth
    assert fb.alt_amsl_m == pytest.approx(0.35 - 2.0)
    assert fa.alt_amsl_m == pytest.approx(0.35 - 2.0)


def test_height_references_by_hand():
    assert height_above_surface_m(412.0, 28.0, takeoff_height_above_surface_m=2.0) == pytest.approx(
        30.0
    )
    assert height_above_surface_m(30.35, 99.0, surface_amsl_m=0.35) == pytest.approx(30.0)
    with pytest.raises(ValueError):
        height_above_surface_m(1.0, 1.0)
    with pytest.raises(ValueError):
        height_above_surface_m(1.0, 1.0, 2.0, 0.35)


def test_camera_below_surface(make_cal, make_telemetry):
    # the UAV's reported point is 0.1 m above the water, the camera 0.25 m below that point
    cal = make_cal(mount={"attitude_source": "gimbal_device", "camera_offset_m": [0.0, 0.0, 0.25]})
    f = fix_at_principal_point(cal, make_telemetry(height_m=0.1))
    assert f.status == "below_surface" and math.isnan(f.lat)
    f = fix_at_principal_point(make_cal(), make_telemetry(height_m=-3.0))
    assert f.status == "below_surface"


def test_ray_above_horizon_is_no_water(make_cal, make_telemetry):
    cal = make_cal()
    tel = make_telemetry(gimbal_ypr_deg=(0.0, 0.0, 0.0))  # looking at the horizon
    pose = camera_pose(cal, tel, [T0_UNIX + 1.0] * 2)
    fixes = locate(
        cal, pose, [cal.camera.cx, cal.camera.cx], [cal.camera.cy - 300, cal.camera.cy + 300]
    )
    assert list(fixes.status) == ["no_water", "ok"]
    assert np.isnan(fixes.lat[0]) and np.isnan(fixes.h_acc_m[0])


def test_pixel_statuses(make_cal, make_telemetry):
    cal = make_cal()
    pose = camera_pose(cal, make_telemetry(), [T0_UNIX + 1.0] * 4)
    fixes = locate(cal, pose, [np.nan, -3.0, 1919.4, 500.0], [100.0, 100.0, 1079.4, 2000.0])
    assert list(fixes.status) == ["no_track", "bad_pixel", "ok", "bad_pixel"]
    assert np.isfinite(fixes.lat[2]) and np.all(np.isnan(fixes.lat[[0, 1, 3]]))


def test_heights_above_the_ellipsoid_follow_gps_raw_int(make_cal, make_telemetry):
    """alt_ellipsoid_m = alt_amsl_m + the geoid separation GPS_RAW_INT gives; NaN (unknown) without it."""
    cal = make_cal()
    tel = make_telemetry(depth_m=2.0, alt_amsl_m=412.0)
    without = fix_at_principal_point(cal, tel)
    assert without.status == "ok" and math.isnan(without.alt_ellipsoid_m)
    for i in range(
        40
    ):  # GPS_RAW_INT at 10 Hz over the telemetry's span: alt_ellipsoid 47.25 m above alt
        tel.add_gps_raw(0, 3, 412.0, 0.8, 1.6, 0.9, 1.3, 47.25, T0_UNIX + i * 0.1)
    f = fix_at_principal_point(cal, tel)
    # the UUV: the UAV's alt − height − depth
    assert f.alt_amsl_m == pytest.approx(412.0 - 30.0 - 2.0)
    assert f.alt_ellipsoid_m == pytest.approx(f.alt_amsl_m + 47.25)


def test_the_trackers_pixel_sigma_goes_into_the_fix(make_cal, make_telemetry):
    """A pixel's own 1-sigma (the tracker's) is the fix's sigma_pixel_px and its share of h_acc; a pixel without
    one (NaN, or none given) takes the calibration's [uncertainty] pixel_px; no pixel, no pixel sigma."""
    cal = make_cal(
        uncertainty={
            "pixel_px": 2.0,
            "tilt_deg": 0.0,
            "yaw_deg": 0.0,
            "height_m": 0.0,
            "baro_drift_10min_m": 0.0,
            "depth_m": 0.0,
            "time_s": 0.0,
            "uav_horizontal_m": 0.0,
        }
    )
    pose = camera_pose(cal, make_telemetry(), [T0_UNIX + 1.0] * 4)
    u, v = [700.0, 700.0, 700.0, np.nan], [400.0] * 4
    fixes = locate(cal, pose, u, v, sigma_px=[1.0, 4.0, np.nan, 3.0])
    assert np.allclose(fixes.sigma_pixel_px[:3], [1.0, 4.0, 2.0]) and np.isnan(
        fixes.sigma_pixel_px[3]
    )
    # with every other input exact, h_acc is the pixel's share alone: linear in its sigma
    assert fixes.h_acc_m[1] == pytest.approx(4.0 * fixes.h_acc_m[0]) and fixes.h_acc_m[
        2
    ] == pytest.approx(2.0 * fixes.h_acc_m[0])
    assert np.allclose(locate(cal, pose, u, v).sigma_pixel_px[:3], 2.0)

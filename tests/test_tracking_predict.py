"""Telemetry predictions for the tracker: projection of a located UUV, its apparent size, the top-face point."""

import math

import numpy as np
import pytest

from localizer.fix import locate
from localizer.geodesy import ned_to_geodetic
from localizer.pose import camera_pose
from localizer.ray import offset_to_pixel
from localizer.tracking.predict import (
    TURN_MARGIN_DEG,
    UUV_ACCEL_MPS2,
    UUV_TOP_SPEED_MPS,
    UUV_YAW_RATE_DPS,
    VEHICLE_FOOTPRINT_M,
    VEHICLE_HEIGHT_M,
    follow,
    prediction_at,
    project_uuv,
    top_face_pixel,
)

T0 = 1_763_800_000.0


def _pose(make_cal, make_telemetry, times, **kw):
    cal = make_cal()
    tel = make_telemetry(**kw)
    return cal, camera_pose(cal, tel, np.asarray(times, float))


@pytest.mark.parametrize("gimbal", [(0.0, -90.0, 0.0), (30.0, -55.0, 2.0)])
def test_projection_is_where_the_fix_finds_the_uuv(make_cal, make_telemetry, gimbal):
    cal, pose = _pose(
        make_cal,
        make_telemetry,
        [T0 + 0.5, T0 + 1.0],
        height_m=12.0,
        gimbal_ypr_deg=gimbal,
        depth_m=1.7,
    )
    assert list(pose.status) == ["ok", "ok"]
    # a UUV near where the camera looks: take the fix of the image centre, then move it 0.8 m
    centre = locate(cal, pose, [959.5, 959.5], [539.5, 539.5])
    lat, lon, _ = ned_to_geodetic(0.5, -0.6, 0.0, centre.lat[0], centre.lon[0], 0.0)
    u, v, _ = project_uuv(cal, pose, lat, lon)
    # the inverse, by a different code path (undistortion, forward Snell)
    back = locate(cal, pose, u, v)
    n = (back.lat - lat) * 111_320.0
    e = (back.lon - lon) * 111_320.0 * math.cos(math.radians(lat))
    assert np.all(np.hypot(n, e) < 1e-3)


def test_apparent_size_at_nadir_follows_the_apparent_depth(make_cal, make_telemetry):
    h, d, n_water = 20.0, 2.0, 1.34
    cal, pose = _pose(make_cal, make_telemetry, [T0 + 1.0], height_m=h, depth_m=d)
    below = locate(cal, pose, [959.5], [539.5])
    u, v, px_per_m = project_uuv(cal, pose, below.lat[0], below.lon[0])
    p = prediction_at(u[0], v[0], px_per_m[0], sigma_m=0.1)
    # paraxial: a submerged object at depth d looks like one at d / n; the camera's own height is h
    k = cal.camera.fx / (pose.height_m[0] + d / n_water)
    assert p.px_per_m == pytest.approx(k, rel=5e-3)
    assert p.width_px == pytest.approx(VEHICLE_FOOTPRINT_M[0] * k, rel=5e-3)
    assert p.height_px == pytest.approx(VEHICLE_FOOTPRINT_M[1] * k, rel=5e-3)
    assert p.sigma_px == pytest.approx(0.1 * k, rel=5e-3)
    assert (p.u, p.v) == pytest.approx((959.5, 539.5), abs=1e-3)


def test_no_prediction_without_a_pose(make_cal, make_telemetry):
    cal, pose = _pose(make_cal, make_telemetry, [T0 + 1.0, T0 + 60.0])
    assert pose.status[1] != "ok"
    u, v, px_per_m = project_uuv(cal, pose, 47.5, 8.5)
    preds = [prediction_at(u[i], v[i], px_per_m[i], sigma_m=0.1) for i in range(2)]
    assert preds[0] is not None and preds[1] is None


@pytest.mark.parametrize("heading_deg", [0.0, 35.0, 90.0])
def test_top_face_pixel_undoes_the_visible_side(make_cal, make_telemetry, heading_deg):
    """A box around all eight projected corners of the vehicle gives back its top face's centre."""
    cal, pose = _pose(
        make_cal,
        make_telemetry,
        [T0 + 1.0],
        height_m=8.0,
        gimbal_ypr_deg=(0.0, -50.0, 0.0),
        depth_m=2.0,
    )
    L, B = VEHICLE_FOOTPRINT_M
    a = math.radians(heading_deg)
    fwd, right = np.array([math.cos(a), math.sin(a)]), np.array([-math.sin(a), math.cos(a)])
    centre_ne = np.array([9.0, 0.3])  # ahead of the camera, about 45 degrees off nadir
    corners = np.array(
        [centre_ne + sx * L / 2 * fwd + sy * B / 2 * right for sx in (-1, 1) for sy in (-1, 1)]
    )
    R, h, d = pose.R_ned_from_cv[0], pose.height_m[0], pose.depth_m[0]
    u_top, v_top = offset_to_pixel(cal.camera, R, corners, h, d)
    u_bot, v_bot = offset_to_pixel(cal.camera, R, corners, h, d + VEHICLE_HEIGHT_M)
    us, vs = np.r_[u_top, u_bot], np.r_[v_top, v_bot]
    box_u, box_v = (us.min() + us.max()) / 2, (vs.min() + vs.max()) / 2
    u_true, v_true = offset_to_pixel(cal.camera, R, centre_ne, h, d)
    naive = math.hypot(box_u - u_true, box_v - v_true)
    u, v = top_face_pixel(cal, pose, [box_u], [box_v])
    assert naive > 3.0  # the visible side matters at this angle
    assert math.hypot(u[0] - u_true, v[0] - v_true) < 0.15 * naive


def test_follow_carries_the_last_residual_and_widens_with_time():
    """The last pixel moved by the camera's motion: projection now + (pixel then - projection then)."""
    p1 = follow((500.0, 300.0, 40.0), (480.0, 310.0, 40.0), (483.0, 308.5), dt_s=0.1)
    p2 = follow((500.0, 300.0, 40.0), (480.0, 310.0, 40.0), (483.0, 308.5), dt_s=1.1)
    assert (p1.u, p1.v) == pytest.approx((503.0, 298.5))
    # the window (3 sigma) grows by how far a BlueROV2 can go: at its top speed when its speed is unknown
    assert 3.0 * (p2.sigma_px - p1.sigma_px) == pytest.approx(UUV_TOP_SPEED_MPS * 1.0 * 40.0)
    # seen moving at 0.2 m/s: 0.2 m/s on, and up to 3 m/s² faster (never beyond the top speed)
    slow = [
        follow((500.0, 300.0, 40.0), (480.0, 310.0, 40.0), (483.0, 308.5), dt_s=dt, speed_mps=0.2)
        for dt in (0.0, 0.2, 2.0)
    ]
    reach = [3.0 * (p.sigma_px - slow[0].sigma_px) / 40.0 for p in slow[1:]]
    assert reach == pytest.approx(
        [0.2 * 0.2 + 0.5 * UUV_ACCEL_MPS2 * 0.2**2, UUV_TOP_SPEED_MPS * 2.0]
    )
    assert slow[1].turn_deg == pytest.approx(UUV_YAW_RATE_DPS * 0.2 + TURN_MARGIN_DEG)
    assert slow[2].turn_deg == 180.0
    # an unusable residual (no earlier projection) predicts nothing: never the located position's stale place
    assert (
        follow((500.0, 300.0, 40.0), (float("nan"), float("nan")), (483.0, 308.5), dt_s=0.1) is None
    )
    assert follow((float("nan"), 300.0, 40.0), (480.0, 310.0), (483.0, 308.5), dt_s=0.1) is None

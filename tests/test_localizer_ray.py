"""Pixel ↔ submerged point: forward projection vs inverse, and rays traced by hand with Snell's law.

Camera attitudes are built here with cv2.Rodrigues from a hand-written nadir
matrix, not with localizer.attitude, and pixels come from cv2.projectPoints.
"""

import math

import cv2
import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from localizer.camera import Camera, pixel_to_ray
from localizer.ray import offset_to_pixel, pixel_to_offset

N_WATER = 1.34
SPEC = Camera(1920, 1080, 1664.0, 1664.0, 959.5, 539.5, (-0.12, 0.08, 0.0004, -0.0002, -0.01))
WIDE = Camera(1280, 720, 640.0, 645.0, 641.3, 358.2, (-0.30, 0.10, 0.001, -0.0015, -0.01))

# Camera looking straight down, image top to the North: cv x → East, cv y → South, cv z → Down.
R_NADIR = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def rot(axis_ned, angle_rad):
    return cv2.Rodrigues(np.asarray(axis_ned, float) * angle_rad)[0]


def camera_R(tilt_n_deg, tilt_e_deg, yaw_deg):
    """R_ned_from_cv: nadir camera tilted about North and East, then turned about Down."""
    return (
        rot([0, 0, 1], math.radians(yaw_deg))
        @ rot([1, 0, 0], math.radians(tilt_n_deg))
        @ rot([0, 1, 0], math.radians(tilt_e_deg))
        @ R_NADIR
    )


def cv_pixel(cam, ray_cv):
    img, _ = cv2.projectPoints(
        np.asarray(ray_cv, float).reshape(1, 1, 3),
        np.zeros(3),
        np.zeros(3),
        cam.K,
        np.array(cam.distortion),
    )
    return img.reshape(2)


def hand_trace(dir_ned, height_m, depth_m, n):
    """Offset (north, east) of a ray traced by hand: straight in air, bent at the surface."""
    dn, de, dd = dir_ned / np.linalg.norm(dir_ned)
    theta_a = math.acos(dd)
    az = math.atan2(de, dn)
    air = height_m * math.tan(theta_a)
    theta_w = theta_a if n is None else math.asin(math.sin(theta_a) / n)
    water = depth_m * math.tan(theta_w)
    return np.array([(air + water) * math.cos(az), (air + water) * math.sin(az)])


pose = {
    "cam_i": st.sampled_from([0, 1]),
    "tilt_n": st.floats(-40, 40),
    "tilt_e": st.floats(-40, 40),
    "yaw": st.floats(-180, 180),
    "height": st.floats(5, 80),
    "depth": st.floats(0, 5),
    "refraction": st.booleans(),
}


@settings(max_examples=200, deadline=None)
@given(fu=st.floats(0, 1), fv=st.floats(0, 1), **pose)
def test_forward_and_inverse_agree(fu, fv, cam_i, tilt_n, tilt_e, yaw, height, depth, refraction):
    """A UUV anywhere in view: inverse (pixel → offset) then forward (offset → pixel) and back."""
    cam = (SPEC, WIDE)[cam_i]
    n = N_WATER if refraction else None
    R = camera_R(tilt_n, tilt_e, yaw)
    u = -0.5 + fu * cam.width
    v = -0.5 + fv * cam.height
    dir_ned = R @ pixel_to_ray(cam, u, v)
    assume(dir_ned[2] > math.cos(math.radians(80)))  # leaves grazing rays out (offsets > 450 m)
    off, reaches = pixel_to_offset(cam, R, u, v, height, depth, n)
    assert reaches
    u2, v2 = offset_to_pixel(cam, R, off, height, depth, n)
    assert math.hypot(u2 - u, v2 - v) < 1e-5
    off2, _ = pixel_to_offset(cam, R, u2, v2, height, depth, n)
    assert np.hypot(*(off2 - off)) < 1e-3


@settings(max_examples=200, deadline=None)
@given(ax=st.floats(-0.5, 0.5), ay=st.floats(-0.3, 0.3), **pose)
def test_inverse_matches_a_ray_traced_by_hand(
    ax, ay, cam_i, tilt_n, tilt_e, yaw, height, depth, refraction
):
    """Pick a ray in the field of view, trace it with trigonometry, find its pixel with OpenCV."""
    cam = (SPEC, WIDE)[cam_i]
    n = N_WATER if refraction else None
    R = camera_R(tilt_n, tilt_e, yaw)
    ray_cv = np.array([math.tan(ax), math.tan(ay), 1.0])
    dir_ned = R @ ray_cv
    assume(dir_ned[2] / np.linalg.norm(dir_ned) > math.cos(math.radians(80)))
    u, v = cv_pixel(cam, ray_cv)
    assume(cam.contains(u, v))
    expected = hand_trace(dir_ned, height, depth, n)
    off, reaches = pixel_to_offset(cam, R, u, v, height, depth, n)
    assert reaches
    assert np.hypot(*(off - expected)) < 1e-3
    # and the forward projection of the hand-traced point lands on OpenCV's pixel
    u2, v2 = offset_to_pixel(cam, R, expected, height, depth, n)
    assert math.hypot(u2 - u, v2 - v) < 1e-5


@settings(max_examples=200, deadline=None)
@given(a=st.floats(-1.0, 1.0), b=st.floats(-1.0, 1.0), **pose)
def test_uuv_position_projects_and_inverts(
    a, b, cam_i, tilt_n, tilt_e, yaw, height, depth, refraction
):
    """A UUV placed near where the optical axis meets the water, forward-projected, then located."""
    cam = (SPEC, WIDE)[cam_i]
    n = N_WATER if refraction else None
    R = camera_R(tilt_n, tilt_e, yaw)
    axis = R[:, 2]
    centre = axis[:2] / axis[2] * height
    uuv = centre + np.array([a, b]) * 0.6 * height
    u, v = offset_to_pixel(cam, R, uuv, height, depth, n)
    assume(cam.contains(u, v))
    off, reaches = pixel_to_offset(cam, R, u, v, height, depth, n)
    assert reaches
    assert np.hypot(*(off - uuv)) < 1e-3


def test_batched_equals_scalar():
    rng = np.random.default_rng(3)
    k = 50
    R = np.stack([camera_R(*rng.uniform(-30, 30, 2), rng.uniform(-180, 180)) for _ in range(k)])
    u = rng.uniform(0, SPEC.width - 1, k)
    v = rng.uniform(0, SPEC.height - 1, k)
    h = rng.uniform(5, 80, k)
    d = rng.uniform(0, 5, k)
    off, reaches = pixel_to_offset(SPEC, R, u, v, h, d, N_WATER)
    assert off.shape == (k, 2) and reaches.shape == (k,)
    for i in range(k):
        o, r = pixel_to_offset(SPEC, R[i], u[i], v[i], h[i], d[i], N_WATER)
        assert r == reaches[i]
        assert np.allclose(o, off[i], atol=1e-12, equal_nan=True)
    uu, vv = offset_to_pixel(SPEC, R[reaches], off[reaches], h[reaches], d[reaches], N_WATER)
    assert np.max(np.hypot(uu - u[reaches], vv - v[reaches])) < 1e-5


# ---- hand-worked cases ----


@pytest.mark.parametrize("n", [N_WATER, None])
@pytest.mark.parametrize("depth", [0.0, 1.0, 4.5])
def test_nadir_principal_point_is_straight_below(n, depth):
    off, reaches = pixel_to_offset(SPEC, R_NADIR, SPEC.cx, SPEC.cy, 25.0, depth, n)
    assert reaches
    assert np.hypot(*off) < 1e-9


@pytest.mark.parametrize("yaw_deg", [0.0, 90.0, -135.0])
def test_45_degree_oblique_view(yaw_deg):
    """Principal point of a camera tilted 45° from nadir towards heading ``yaw_deg``.

    Straight ray: offset = h·tan45 + d·tan45. Refracted: h·1 + d·tan(asin(sin45/n)).
    """
    h, d = 20.0, 2.0
    # tilting about the East axis by +45° swings the optical axis from Down towards North
    R = camera_R(0.0, 45.0, yaw_deg)
    axis = R @ [0, 0, 1]
    assert np.allclose(
        axis,
        [
            math.cos(math.radians(yaw_deg)) * math.sqrt(0.5),
            math.sin(math.radians(yaw_deg)) * math.sqrt(0.5),
            math.sqrt(0.5),
        ],
    )
    heading = np.array([math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))])
    straight, _ = pixel_to_offset(SPEC, R, SPEC.cx, SPEC.cy, h, d, None)
    assert np.allclose(straight, (h + d) * heading, atol=1e-9)
    bent, _ = pixel_to_offset(SPEC, R, SPEC.cx, SPEC.cy, h, d, N_WATER)
    theta_w = math.asin(math.sin(math.radians(45)) / N_WATER)  # 31.86°
    assert np.allclose(bent, (h + d * math.tan(theta_w)) * heading, atol=1e-9)
    assert np.hypot(*(straight - bent)) == pytest.approx(d * (1 - 0.6212), abs=2e-4)


def test_depth_zero_refraction_changes_nothing():
    R = camera_R(20, -30, 40)
    a, _ = pixel_to_offset(SPEC, R, 300.0, 800.0, 30.0, 0.0, N_WATER)
    b, _ = pixel_to_offset(SPEC, R, 300.0, 800.0, 30.0, 0.0, None)
    assert np.allclose(a, b, atol=1e-12)


# facts.md: horizontal error of ignoring refraction, d·(tan θ_air − tan θ_water), n = 1.34
FACTS_TABLE = {20: (0.10, 0.20, 0.30), 30: (0.18, 0.35, 0.53), 35: (0.23, 0.45, 0.68)}


@pytest.mark.parametrize("off_nadir_deg", sorted(FACTS_TABLE))
def test_refraction_error_matches_facts_table(off_nadir_deg):
    """Straight-ray offset minus the refracted one, for an undistorted pixel at a known angle."""
    cam = Camera(1920, 1080, 1500.0, 1500.0, 959.5, 539.5)
    u = cam.cx + cam.fx * math.tan(math.radians(off_nadir_deg))  # nadir camera, angle along image x
    for depth_m, table_m in zip((1.0, 2.0, 3.0), FACTS_TABLE[off_nadir_deg]):
        straight, _ = pixel_to_offset(cam, R_NADIR, u, cam.cy, 15.0, depth_m, None)
        bent, _ = pixel_to_offset(cam, R_NADIR, u, cam.cy, 15.0, depth_m, N_WATER)
        assert np.hypot(*(straight - bent)) == pytest.approx(table_m, abs=0.006)


def test_ray_above_horizon_does_not_reach_water():
    R = camera_R(0.0, 90.0, 0.0)  # optical axis horizontal, towards North
    off, reaches = pixel_to_offset(SPEC, R, SPEC.cx, SPEC.cy - 200, 30.0, 1.0, N_WATER)
    assert not reaches and np.all(np.isnan(off))
    off, reaches = pixel_to_offset(SPEC, R, SPEC.cx, SPEC.cy + 200, 30.0, 1.0, N_WATER)
    assert reaches and off[0] > 100

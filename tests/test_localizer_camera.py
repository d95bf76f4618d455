"""Camera model: distortion both ways, pixel ↔ ray, checked against OpenCV itself."""

import cv2
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from localizer.camera import (
    SCALAR_POINTS,
    Camera,
    distort,
    pixel_to_ray,
    ray_to_pixel,
    undistort,
)

# the session spec's example lens, and a strongly barrelled wide one
SPEC = Camera(1920, 1080, 1664.0, 1664.0, 959.5, 539.5, (-0.12, 0.08, 0.0004, -0.0002, -0.01))
WIDE = Camera(1280, 720, 640.0, 645.0, 641.3, 358.2, (-0.30, 0.10, 0.001, -0.0015, -0.01))
CAMERAS = [SPEC, WIDE]


def _image_grid(cam, n=41):
    """Pixels covering the whole image, its outer corners (±0.5 px beyond the centres) included."""
    u = np.linspace(-0.5, cam.width - 0.5, n)
    v = np.linspace(-0.5, cam.height - 0.5, n)
    return np.meshgrid(u, v)


def _cv_project(cam, pts_cv):
    img, _ = cv2.projectPoints(
        pts_cv.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.K, np.array(cam.distortion)
    )
    return img.reshape(-1, 2)


def test_undistort_inverts_distort_over_the_whole_image():
    for cam in CAMERAS:
        u, v = _image_grid(cam)
        xd = (u - cam.cx) / cam.fx
        yd = (v - cam.cy) / cam.fy
        x, y = undistort(xd, yd, cam.distortion)
        assert np.all(np.isfinite(x)) and np.all(np.isfinite(y))
        xr, yr = distort(x, y, cam.distortion)
        err_px = np.hypot((xr - xd) * cam.fx, (yr - yd) * cam.fy)
        assert err_px.max() < 1e-6, (cam, err_px.max())
        # and undistortion really moves corner pixels (the test is not vacuous)
        assert np.hypot((x - xd) * cam.fx, (y - yd) * cam.fy).max() > 20


def test_small_arrays_take_the_arrays_steps_in_floats():
    """Up to SCALAR_POINTS points are stepped in plain floats, all together until every one has converged: bit for
    bit what numpy's steps give (an array of one point more, a copy of one of them, takes numpy's over the same
    points), a point outside the lens model NaN in both."""
    for cam in CAMERAS:
        u, v = _image_grid(cam, 9)
        xd = np.append((u.ravel() - cam.cx) / cam.fx, 3.0)  # the last beyond the lens model
        yd = np.append((v.ravel() - cam.cy) / cam.fy, 3.0)
        for a in range(xd.size - SCALAR_POINTS, -1, -4):  # the first with the point beyond
            sx, sy = xd[a : a + SCALAR_POINTS], yd[a : a + SCALAR_POINTS]
            x, y = undistort(sx, sy, cam.distortion)
            ax, ay = undistort(np.append(sx, sx[0]), np.append(sy, sy[0]), cam.distortion)
            assert x.tobytes() == ax[:-1].tobytes() and y.tobytes() == ay[:-1].tobytes(), (cam, a)
            if a == xd.size - SCALAR_POINTS:
                assert np.isnan(x[-1]) and np.isfinite(x[:-1]).all()
        x, y = undistort(xd[40], yd[40], cam.distortion)  # one point: arrays of its shape
        many = undistort(
            np.full(SCALAR_POINTS + 1, xd[40]), np.full(SCALAR_POINTS + 1, yd[40]), cam.distortion
        )
        assert x.shape == () and (x, y) == (many[0][0], many[1][0])


def test_pixel_ray_pixel_round_trip_including_corners():
    for cam in CAMERAS:
        u, v = _image_grid(cam)
        ray = pixel_to_ray(cam, u, v)
        assert ray.shape == u.shape + (3,)
        assert np.allclose(np.linalg.norm(ray, axis=-1), 1.0)
        assert np.all(ray[..., 2] > 0)
        u2, v2 = ray_to_pixel(cam, ray)
        assert np.max(np.hypot(u2 - u, v2 - v)) < 1e-6


def test_ray_to_pixel_matches_cv2_project_points():
    rng = np.random.default_rng(7)
    for cam in CAMERAS:
        # random points in front of the camera, spread over (and a little beyond) the field of view
        z = rng.uniform(0.5, 80.0, 2000)
        x = rng.uniform(-0.7, 0.7, z.size) * z
        y = rng.uniform(-0.45, 0.45, z.size) * z
        pts = np.stack([x, y, z], axis=-1)
        expected = _cv_project(cam, pts)
        u, v = ray_to_pixel(cam, pts)  # a ray need not be unit length
        assert np.max(np.abs(np.stack([u, v], -1) - expected)) < 1e-7


def test_pixel_to_ray_matches_cv2_undistort_points():
    """OpenCV's fixed-point undistortion, run to convergence, is an independent inverse."""
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 500, 1e-15)
    for cam in CAMERAS:
        u, v = _image_grid(cam, 21)
        src = np.stack([u.ravel(), v.ravel()], -1).reshape(-1, 1, 2).astype(np.float64)
        xy = cv2.undistortPoints(src, cam.K, np.array(cam.distortion), criteria=crit).reshape(-1, 2)
        ray = pixel_to_ray(cam, u.ravel(), v.ravel())
        ours = ray[:, :2] / ray[:, 2:3]
        # compared in pixels at the focal length; OpenCV's iteration stops a little short in corners
        assert np.max(np.abs(ours - xy) * cam.fx) < 1e-3


@settings(max_examples=200, deadline=None)
@given(
    cam_i=st.sampled_from([0, 1]),
    fu=st.floats(0.0, 1.0),
    fv=st.floats(0.0, 1.0),
)
def test_round_trip_property(cam_i, fu, fv):
    cam = CAMERAS[cam_i]
    u = -0.5 + fu * cam.width
    v = -0.5 + fv * cam.height
    ray = pixel_to_ray(cam, u, v)
    # the ray projects back through OpenCV to the same pixel
    back = _cv_project(cam, ray.reshape(1, 3))[0]
    assert np.hypot(back[0] - u, back[1] - v) < 1e-6


def test_principal_point_is_the_optical_axis_and_axes_point_the_opencv_way():
    ray = pixel_to_ray(SPEC, SPEC.cx, SPEC.cy)
    assert np.allclose(ray, [0, 0, 1], atol=1e-12)
    right = pixel_to_ray(SPEC, SPEC.cx + 500, SPEC.cy)
    down = pixel_to_ray(SPEC, SPEC.cx, SPEC.cy + 300)
    assert right[0] > 0 and abs(right[1]) < 1e-3
    assert down[1] > 0 and abs(down[0]) < 1e-3


def test_ray_behind_camera_gives_nan():
    u, v = ray_to_pixel(SPEC, np.array([0.1, 0.1, -1.0]))
    assert np.isnan(u) and np.isnan(v)


def test_contains_uses_pixel_edges():
    assert SPEC.contains(-0.5, -0.5) and SPEC.contains(1919.5, 1079.5)
    assert not SPEC.contains(-0.51, 10) and not SPEC.contains(10, 1079.6)

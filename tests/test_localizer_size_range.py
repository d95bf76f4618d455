"""The UUV's outline as a function of the camera's height, and the height bias estimated from measurements.

The box's corners are checked against the simulator's own projection (Fermat's surface crossing and
cv2.projectPoints, independent of the localizer's rays and refraction); the outline, its area and its
edge points against hand-worked polygons; the estimate on synthetic measurements whose bias, noise,
correlation and outliers are known.
"""

import math

import numpy as np
import pytest

from localizer.calibration import Uuv
from localizer.camera import Camera
from localizer.size_range import (
    AT_SURFACE_M,
    EDGE_BIAS_PX,
    MIN_FRAMES,
    SIZE_SIGMA,
    HeightBias,
    SizeHeight,
    box_corners_px,
    edge_points,
    outline,
    polygon_area,
    size_height,
)
from sim_fixtures.geometry import SimCamera, matrix_zyx, project, surface_crossing

N_WATER = 1.34
UUV = Uuv(0.46, 0.34, 0.25)
SIM = SimCamera(1280, 720, 1065.0, 1062.0, 641.3, 357.8, (-0.12, 0.08, 0.0004, -0.0002, -0.01))
CAMERA = Camera(
    width=SIM.width,
    height=SIM.height,
    fx=SIM.fx,
    fy=SIM.fy,
    cx=SIM.cx,
    cy=SIM.cy,
    distortion=SIM.dist.ravel().tolist(),
)
# cv z (optical axis) = gimbal x
R_GIMBAL_FROM_CV = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def _sim_corners(R, camera_ned, top_ned, heading_rad):
    """The eight corners' pixels by the simulator: submerged ones through their light's surface crossing."""
    c, s = math.cos(heading_rad), math.sin(heading_rad)
    pts = []
    for dz in (0.0, UUV.height_m):
        for f, r in ((1, 1), (1, -1), (-1, -1), (-1, 1)):
            x, y = f * UUV.length_m / 2, r * UUV.width_m / 2
            pts.append(top_ned + np.array([c * x - s * y, s * x + c * y, dz]))
    pts = np.array(pts)
    under = pts[:, 2] > 0
    seen = pts.copy()
    # what the camera sees of a submerged point
    seen[under] = surface_crossing(camera_ned, pts[under], N_WATER)
    return np.stack(project(SIM, R, camera_ned, seen), axis=-1)


@pytest.mark.parametrize(
    "pitch_deg, yaw_deg, depth_m, heading_deg",
    [
        (-90.0, 0.0, 1.5, 20.0),  # nadir, 1.5 m deep
        (-58.0, 35.0, 0.1, 120.0),  # 32° off nadir, near the surface
        (-65.0, 200.0, 2.2, -60.0),
        (
            -60.0,
            80.0,
            -0.1,
            45.0,
        ),  # the top face 10 cm above the water: straight rays to the top, refracted below
    ],
)
def test_corners_match_the_simulators_projection(pitch_deg, yaw_deg, depth_m, heading_deg):
    R = matrix_zyx(0.02, math.radians(pitch_deg), math.radians(yaw_deg)) @ R_GIMBAL_FROM_CV
    camera_ned = np.array([3.0, -2.0, -11.5])
    axis = R[:, 2]
    ground = camera_ned + axis * (11.5 / axis[2])  # where the optical axis meets the water ...
    top = np.array([ground[0] + 0.4, ground[1] - 0.3, depth_m])  # ... the UUV near it
    want = _sim_corners(R, camera_ned, top, math.radians(heading_deg))
    # the top face's centre pixel, by the simulator too
    centre = surface_crossing(camera_ned, top[None], N_WATER)[0] if depth_m > 0 else top
    u, v = project(SIM, R, camera_ned, centre)
    got = box_corners_px(CAMERA, R, u, v, math.radians(heading_deg), UUV, 11.5, depth_m, N_WATER)
    assert got.shape == (8, 2)
    assert np.max(np.abs(got - want)) < 1e-4, np.abs(got - want).max()


def test_corners_batch_over_heights_and_headings():
    R = matrix_zyx(0.0, math.radians(-70.0), 0.3) @ R_GIMBAL_FROM_CV
    heights = np.array([[8.0], [12.0]])
    headings = np.array([0.0, 0.5, 1.0])
    got = box_corners_px(CAMERA, R, 600.0, 380.0, headings, UUV, heights, 1.0, N_WATER)
    assert got.shape == (2, 3, 8, 2)
    one = box_corners_px(CAMERA, R, 600.0, 380.0, 0.5, UUV, 12.0, 1.0, N_WATER)
    assert np.allclose(got[1, 1], one)
    # the higher camera sees a smaller vehicle
    assert np.ptp(got[1, 0, :, 0]) < np.ptp(got[0, 0, :, 0])


def test_outline_of_a_square_with_points_inside_turns_its_normals_outwards():
    square = np.array([[10.0, 10.0], [30.0, 10.0], [30.0, 30.0], [10.0, 30.0]])
    pts = np.vstack(
        [[20.0, 20.0], square[2], [15.0, 25.0], square[0], square[3], [29.0, 11.0], square[1]]
    )
    hull = outline(pts)
    assert sorted(hull) == [1, 3, 4, 6]
    for k, i in enumerate(hull):
        j = hull[(k + 1) % len(hull)]
        e = pts[j] - pts[i]
        normal = np.array([e[1], -e[0]]) / np.hypot(*e)
        mid = (pts[i] + pts[j]) / 2
        # away from the centre
        assert np.hypot(*(mid + normal - (20, 20))) > np.hypot(*(mid - (20, 20)))
    assert polygon_area(pts[hull]) == pytest.approx(400.0)
    assert polygon_area(pts[hull][::-1]) == pytest.approx(400.0)


def test_edge_points_leave_out_the_corners_and_follow_moved_corners():
    square = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]] + [[5.0, 5.0]] * 4)
    hull = outline(square)
    pts = edge_points(square, hull, spacing_px=1.0, trim=0.15)
    assert len(pts.xy) == 4 * 8  # 7 px of each 10 px edge, a point every pixel
    along_edge = np.sum(np.abs(pts.normal) * np.abs(pts.xy - 5.0), axis=1)
    assert np.allclose(along_edge, 5.0)  # on the edges
    # at most 3.5 px from an edge's middle
    assert np.all(np.abs(pts.xy - 5.0).min(axis=1) <= 3.5 + 1e-9)
    assert np.allclose(pts.moved(square), pts.xy)
    assert np.allclose(pts.moved(square + (2.0, -1.0)), pts.xy + (2.0, -1.0))
    assert np.allclose(pts.moved(square * 2.0), pts.xy * 2.0)
    assert len(edge_points(square * 0.2, hull).xy) == 0  # 2 px edges: shorter than min_edge_px


def test_size_height_adds_the_errors_all_frames_share():
    h = size_height(
        t_unix=5.0,
        camera_height_m=10.0,
        sigma_fit_m=0.03,
        size_px=50.0,
        camera_below_m=0.2,
        configured_m=11.0,
        configured_sigma_m=0.3,
        depth_m=0.5,
        sigma_depth_m=0.05,
        n_water=1.34,
    )
    # hand-worked: range 10 + 0.5/1.34; relative sqrt(0.005² + (2·0.1/50)²); depth 0.05/1.34
    range_m = 10.0 + 0.5 / 1.34
    relative = math.sqrt(SIZE_SIGMA**2 + (2 * EDGE_BIAS_PX / 50.0) ** 2)
    assert h.uav_height_m == pytest.approx(10.2)
    assert h.sigma_common_m == pytest.approx(math.hypot(range_m * relative, 0.05 / 1.34))
    assert h.sigma_total_m == pytest.approx(math.hypot(0.03, h.sigma_common_m))
    assert h.bias_m == pytest.approx(0.8)
    # top face out of the water
    above = size_height(5.0, 10.0, 0.03, 50.0, 0.2, 11.0, 0.3, -0.1, 0.05, 1.34)
    assert above.sigma_common_m == pytest.approx(math.hypot(10.0 * relative, 0.05 / 1.34))


def _measurements(
    rng, bias, n=300, hz=10.0, sigma=0.1, common=0.05, rho=0.0, outliers=0.0, depth=1.0
):
    """Synthetic measurements: configured 12 m, the true height 12 - bias; noise of ``sigma`` (AR(1) correlated
    ``rho`` frame to frame), one common error of ``common``, a share ``outliers`` locked on the inner structure
    (1-3 m too high)."""
    e, out = rng.normal() * common, []
    noise = 0.0
    for k in range(n):
        noise = rho * noise + math.sqrt(1 - rho**2) * rng.normal() * sigma
        true = 12.0 - bias
        measured = true + e + noise + (rng.uniform(1.0, 3.0) if rng.uniform() < outliers else 0.0)
        out.append(SizeHeight(100.0 + k / hz, measured, sigma, common, 12.0, 0.3, depth))
    return out


def test_bias_recovered_despite_outliers():
    est = HeightBias()
    for h in _measurements(np.random.default_rng(1), bias=0.8, outliers=0.1):
        est.add(h)
    e = est.estimate()
    assert e.sure and abs(e.bias_m - 0.8) <= 2 * e.sigma_m and e.sigma_m < 0.1
    assert 0.05 * 300 < e.outliers < 0.15 * 300  # the 10 % that locked elsewhere, left out
    assert e.frames + e.outliers == 300 and e.blocks == 30
    assert e.at_surface == 0.0 and e.configured_sigma_m == pytest.approx(0.3)
    assert e.sigma_common_m == pytest.approx(0.05)
    assert not e.agrees(SizeHeight(200.0, 12.0 - 0.8 + 1.0, 0.1, 0.05, 12.0, 0.3, 1.0))
    assert e.agrees(SizeHeight(200.0, 12.0 - 0.8 + 0.1, 0.1, 0.05, 12.0, 0.3, 1.0))


def test_sure_only_with_enough_measurements_over_enough_seconds_and_a_small_sigma():
    est = HeightBias()
    for k, h in enumerate(_measurements(np.random.default_rng(2), bias=0.5, n=60, hz=10.0)):
        est.add(h)
        assert est.estimate().sure == (k >= 40), k  # the fifth second begins with the 41st
    far = HeightBias()  # what every frame shares is too large: a small outline, far away
    for h in _measurements(np.random.default_rng(3), bias=0.5, n=300, sigma=0.1, common=0.3):
        far.add(h)
    assert not far.estimate().sure and far.estimate().sigma_m > 0.25
    slow = HeightBias()  # a measurement a second: the blocks are there, the measurements count
    for k, h in enumerate(_measurements(np.random.default_rng(6), bias=0.5, n=15, hz=1.0)):
        slow.add(h)
        assert slow.estimate().sure == (k + 1 >= MIN_FRAMES), k


def test_window_forgets_old_measurements():
    est = HeightBias(window_s=30.0)
    for h in _measurements(np.random.default_rng(4), bias=2.0, n=300, hz=10.0):  # t 100 .. 130
        est.add(h)
    # t 100 .. 140, moved 40 s on
    later = _measurements(np.random.default_rng(5), bias=0.2, n=400, hz=10.0)
    for h in later:
        est.add(
            SizeHeight(
                h.t_unix + 40.0,
                h.uav_height_m,
                h.sigma_m,
                h.sigma_common_m,
                h.configured_m,
                h.configured_sigma_m,
                h.depth_m,
            )
        )
    e = est.estimate()
    newest = max(h.t_unix for h in est.heights)
    assert newest > 179.0 and min(h.t_unix for h in est.heights) > newest - 30.0
    assert abs(e.bias_m - 0.2) <= 2 * e.sigma_m


def test_at_surface_share():
    est = HeightBias()
    rng = np.random.default_rng(6)
    for h in _measurements(rng, bias=0.3, n=100, depth=AT_SURFACE_M) + _measurements(
        rng, bias=0.3, n=100, depth=1.0
    ):
        est.add(h)
    assert est.estimate().at_surface == pytest.approx(0.5)


@pytest.mark.parametrize("rho", [0.0, 0.9])
def test_sigma_holds_the_error_within_two_sigmas_95_percent_of_the_time(rho):
    """Many runs of 20 s, each with its own common error, frame noise (independent, or correlated frame to frame
    as one view and one background are) and outliers: the estimate's 1-sigma is honest."""
    rng = np.random.default_rng(7 if rho else 8)
    inside, n = 0, 300
    for _ in range(n):
        est = HeightBias()
        for h in _measurements(
            rng, bias=0.8, n=100, hz=5.0, sigma=0.15, common=0.06, rho=rho, outliers=0.05
        ):
            est.add(h)
        e = est.estimate()
        inside += abs(e.bias_m - 0.8) <= 2 * e.sigma_m
    assert 0.92 <= inside / n <= 0.995, inside / n

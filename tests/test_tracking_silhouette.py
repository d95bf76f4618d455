"""The camera's height from the UUV's outline, on frames the simulator renders (640x360, no video coding: fast).

The truth is the simulator's: the camera's height, attitude and the UUV's pixel, depth and heading at each
frame (sim_fixtures.generate.frame_truth). The measurement starts from a configured height 12 % off and a
tracked pixel 0.8 px off; it must find the true height (in three frames of four at least; in the others
say why not) within what it says (its fit's 1-sigma and the error every frame shares, three times) and
within 2 %, at the surface and at depth, at nadir and obliquely; where there is no vehicle, or the
vehicle is at the frame's edge, it must say why, not measure.
"""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from localizer.calibration import Uuv
from localizer.camera import Camera
from localizer.size_range import box_corners_px, edge_points, outline, size_height
from localizer.tracking import silhouette
from localizer.tracking.silhouette import REJECTIONS, SilhouetteParams, measure
from sim_fixtures.generate import camera_of, frame_truth
from sim_fixtures.motion import Motion
from sim_fixtures.render import Renderer
from sim_fixtures.scenario import load_scenario, with_overrides

SCENARIOS = Path(__file__).resolve().parents[1] / "sim_fixtures" / "scenarios"
FRAMES = (0, 40, 80, 120)


def _scene(pitch_deg, height_m, depth_m, seed):
    sc = with_overrides(
        load_scenario(SCENARIOS / "size_surface.toml"),
        seed=seed,
        duration_s=4.5,
        camera={"width": 640, "height": 360},
        mount={"pitch_deg": pitch_deg},
        uav={"height_m": height_m},
        uuv={"depth_m": depth_m, "depth_swing_m": 0.02},
    )
    sim = camera_of(sc)
    camera = Camera(
        width=sim.width,
        height=sim.height,
        fx=sim.fx,
        fy=sim.fy,
        cx=sim.cx,
        cy=sim.cy,
        distortion=sim.dist.ravel().tolist(),
    )
    return sc, camera, frame_truth(sc, Motion(sc), sim), Renderer(sc, sim)


@pytest.mark.parametrize(
    "pitch_deg, height_m, depth_m, seed",
    [
        (-90.0, 7.0, 0.1, 71),  # nadir, at the surface
        (-60.0, 7.0, 0.1, 72),  # 30° off nadir, at the surface
        (-68.0, 6.5, 1.5, 73),  # 22° off nadir, 1.5 m deep
    ],
)
def test_height_found_from_a_wrong_start(pitch_deg, height_m, depth_m, seed):
    sc, camera, truth, renderer = _scene(pitch_deg, height_m, depth_m, seed)
    uuv = Uuv(*sc.uuv.size_m)
    n = sc.site.refractive_index
    measured = 0
    for i, wrong in zip(FRAMES, (1.12, 0.88, 1.12, 0.88)):
        image, _ = renderer.render(truth.view(i))
        true_h = -truth.camera_ned[i, 2]
        depth = truth.uuv_ned[i, 2]
        m = measure(
            image,
            camera,
            truth.R_ned_from_cv[i],
            truth.u[i] + 0.8,
            truth.v[i] - 0.5,
            uuv,
            true_h * wrong,
            depth,
            n,
        )
        if isinstance(m, str):  # no measurement, and why: allowed now and then, never a wrong one
            assert m in REJECTIONS
            continue
        measured += 1
        common = size_height(
            0.0, m.camera_height_m, m.sigma_m, m.size_px, 0.0, true_h, 0.3, depth, 0.0, n
        )
        err = m.camera_height_m - true_h
        assert abs(err) <= 3 * common.sigma_total_m and abs(err) <= 0.02 * true_h, (i, err, m)
        # the heading (modulo 180°: the box is symmetric) and the top face's pixel come along
        turn = (m.heading_rad - truth.uuv_heading[i] + np.pi / 2) % np.pi - np.pi / 2
        assert abs(np.degrees(turn)) < 3.0 and np.hypot(m.u - truth.u[i], m.v - truth.v[i]) < 0.5, (
            i,
            m,
        )
    assert measured >= 3


def test_no_vehicle_no_measurement():
    sc, camera, truth, renderer = _scene(-60.0, 7.0, 0.1, 72)
    for i in FRAMES:
        image, _ = renderer.render(replace(truth.view(i), uuv_visible=False))  # the water alone
        m = measure(
            image,
            camera,
            truth.R_ned_from_cv[i],
            truth.u[i],
            truth.v[i],
            Uuv(*sc.uuv.size_m),
            -truth.camera_ned[i, 2],
            truth.uuv_ned[i, 2],
            sc.site.refractive_index,
        )
        assert m in REJECTIONS, (i, m)


def test_at_the_frame_edge_or_too_small_it_says_why():
    sc, camera, truth, renderer = _scene(-90.0, 7.0, 0.1, 71)
    image, _ = renderer.render(truth.view(0))
    args = (camera, truth.R_ned_from_cv[0])
    uuv, h, d, n = (
        Uuv(*sc.uuv.size_m),
        -truth.camera_ned[0, 2],
        truth.uuv_ned[0, 2],
        sc.site.refractive_index,
    )
    assert measure(image, *args, 8.0, 180.0, uuv, h, d, n) == "border"
    # configured 3× too high
    assert measure(image, *args, truth.u[0], truth.v[0], uuv, 3.0 * h, d, n) == "too_small"


def test_the_size_scan_samples_further_out_only_where_it_must():
    """The scan's supports (sampling beyond ``agree_px`` only at the points with an edge within it) are those of
    sampling every point at every offset."""
    sc, camera, truth, renderer = _scene(-68.0, 6.5, 1.5, 73)
    i = 40
    image, _ = renderer.render(truth.view(i))
    p = SilhouetteParams()
    R, u, v = truth.R_ned_from_cv[i], truth.u[i], truth.v[i]
    uuv, h, depth, n = (
        Uuv(*sc.uuv.size_m),
        -truth.camera_ned[i, 2],
        truth.uuv_ned[i, 2],
        sc.site.refractive_index,
    )
    heading = silhouette._headings(image, camera, R, u, v, uuv, h, depth, n, p)[0]
    scales = np.exp(np.linspace(np.log(p.scan_to), np.log(p.scan_from), 25))
    corners = box_corners_px(camera, R, u, v, heading, uuv, h * scales, depth, n)  # (25, 8, 2)
    # beyond the largest outline (the lowest height)
    texture = silhouette._texture(image, corners[-1], p)
    mid = corners[len(corners) // 2]
    pts = edge_points(mid, outline(mid), p.spacing_px, p.trim)
    e = corners[:, pts.second] - corners[:, pts.first]
    normal = np.stack([e[..., 1], -e[..., 0]], axis=-1) / np.linalg.norm(e, axis=-1, keepdims=True)
    window, origin = silhouette._window(
        image, corners.min(axis=(0, 1)), corners.max(axis=(0, 1)), p.clear_px + 1.0
    )
    t = (
        np.arange(-np.ceil(p.agree_px / p.step_px) - 1, round(p.clear_px / p.step_px) + 2)
        * p.step_px
    )
    edges = silhouette._peaks(
        window, pts.moved(corners) - origin, normal, t, p.noise_factor * texture
    )
    every = silhouette._supported(edges, p)
    assert np.array_equal(silhouette._supports(image, corners, texture, p), every.mean(axis=-1))
    is_edge, tm, _ = edges
    edge_near = is_edge[np.abs(tm) <= p.agree_px].any(axis=0)
    assert every.mean(axis=-1).max() > 0.3  # outlines near the vehicle's are supported ...
    # ... and many points with an edge near have one further out
    assert np.mean(edge_near & ~every) > 0.1


def test_windows_of_the_converted_region_sample_as_the_frames_own():
    """The scan's and the passes' windows, read from the region :class:`silhouette._Floats` converts once (views of
    it) or from the frame beyond it, give the colour's changes the frame's own windows give, also at samples beyond
    a window's edge (where ``cv2.remap`` replicates its border) and at the frame's edge."""
    rng = np.random.default_rng(11)
    frame = rng.integers(0, 256, (120, 160, 3), dtype=np.uint8)
    floats = silhouette._Floats(frame, np.array([40.0, 30.0]), np.array([90.0, 70.0]), 7.0)
    # inside the region (its windows views), beyond it at the frame's corner, partly beyond it
    for lo, hi in (
        ((50.3, 40.2), (80.6, 60.1)),
        ((2.0, 1.5), (30.0, 20.0)),
        ((70.0, 50.0), (150.0, 110.0)),
    ):
        want, origin = silhouette._window(frame, np.array(lo), np.array(hi), 7.0)
        got, got_origin = silhouette._window(floats, np.array(lo), np.array(hi), 7.0)
        assert got.dtype == np.float32 and np.array_equal(got, want)
        assert np.array_equal(got_origin, origin)
        xy = rng.uniform(-4.0, 4.0, (300, 2)) + rng.uniform(0.0, 1.0, (300, 1)) * np.array(
            want.shape[1::-1]
        )
        normal = rng.normal(size=(300, 2))
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        t = np.arange(-7, 15) * 0.5
        assert np.array_equal(
            silhouette._changes(got, xy, normal, t), silhouette._changes(want, xy, normal, t)
        )
    assert floats[41:60, 33:50].base is not None  # a view, not a conversion


def test_median_is_numpys():
    """The fit's and the texture's median: ``np.median``'s number, to the bit, for odd and even counts, ties,
    float32 and float64, and NaN."""
    rng = np.random.default_rng(3)
    for n in (1, 2, 3, 8, 9, 250, 251, 1000):
        for dtype in (np.float64, np.float32):
            for x in (
                rng.normal(size=n),
                rng.integers(0, 4, n) * 0.1,
                rng.exponential(size=n) * 1e-3,
            ):
                x = x.astype(dtype)
                assert (
                    np.float64(silhouette._median(x)).tobytes()
                    == np.float64(np.median(x)).tobytes()
                )
    x = rng.normal(size=9)
    x[4] = np.nan
    assert np.isnan(silhouette._median(x))


def test_fourth_power_is_numpys():
    """The axes' ``z ** 4``: numpy's numbers to the bit (signed zeros included), in complex64 (the gradients') and
    complex128, for gradients of every size and exact zeros of either sign."""
    rng = np.random.default_rng(5)
    for dtype in (np.float32, np.float64):
        g = rng.normal(size=(2, 4000)) * rng.choice([0.0, 1.0, 1e-3, 1e3], size=(2, 4000))
        g[:, :40] = rng.choice([0.0, -0.0], size=(2, 40))
        g = g.astype(dtype)
        z = g[0] + 1j * g[1]
        assert silhouette._fourth_power(z).tobytes() == (z**4).tobytes(), dtype

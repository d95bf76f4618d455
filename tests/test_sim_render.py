"""The renderer and the truth agree on where the UUV's reference point appears.

Two paths in the simulator: track.csv's pixel comes from the forward projection
(target → the surface crossing by Fermat's principle → cv2.projectPoints); the
renderer casts rays from pixels (cv2.undistortPoints → rotation → vector Snell →
box). The localizer agrees with both (test_sim_accuracy, test_sim_independent). Newton's method on the
renderer's rays finds the pixel whose ray meets the top face's centre; it must be
track.csv's pixel.
"""

from dataclasses import replace

import numpy as np
import pytest

from groundstation.session.read import read_table
from sim_fixtures import render
from sim_fixtures.bundle import BUNDLED, BUNDLED_DIR, SCENARIOS
from sim_fixtures.generate import camera_of, frame_truth
from sim_fixtures.geometry import pixel_rays
from sim_fixtures.motion import Motion
from sim_fixtures.render import Renderer
from sim_fixtures.scenario import load_scenario, with_overrides


@pytest.fixture(scope="module", params=BUNDLED)
def scene(request):
    sc = load_scenario(SCENARIOS / f"{request.param}.toml")
    camera = camera_of(sc)
    return sc, camera, frame_truth(sc, Motion(sc), camera), Renderer(sc, camera)


def pixel_of_reference_point(renderer, view, u, v, steps=6):
    """Newton's method on the renderer's rays: the pixel whose ray meets the top face at body (0, 0)."""
    p = np.array([u, v], dtype=float)
    h = 0.5
    for _ in range(steps):
        uu = np.array([p[0], p[0] + h, p[0]])
        vv = np.array([p[1], p[1], p[1] + h])
        xy = renderer.top_face_xy(uu, vv, view)
        J = np.column_stack([(xy[1] - xy[0]) / h, (xy[2] - xy[0]) / h])
        p = p - np.linalg.solve(J, xy[0])
    return p


def test_reference_point_lands_on_track_pixel(scene):
    sc, _, truth, renderer = scene
    track = read_table(BUNDLED_DIR / sc.name / "track.csv", ("t", "u", "v"), allow_empty=("u", "v"))
    assert np.allclose(track["t"], truth.t_unix, atol=1e-6, rtol=0)
    seen = np.flatnonzero(np.isfinite(track["u"]))
    assert len(seen) > 0.5 * len(track["t"])
    for i in seen[:: max(1, len(seen) // 6)]:
        start_u, start_v = track["u"][i] + 3.0, track["v"][i] - 2.0  # start off the answer
        p = pixel_of_reference_point(renderer, truth.view(i), start_u, start_v)
        assert np.hypot(p[0] - track["u"][i], p[1] - track["v"][i]) < 1e-4, (
            sc.name,
            i,
            p,
            track["u"][i],
            track["v"][i],
        )


def test_rendered_uuv_covers_track_pixel(scene):
    _, camera, truth, renderer = scene
    i = int(np.flatnonzero(truth.visible)[len(truth.visible) // 3])
    img, box = renderer.render(truth.view(i))
    assert img.shape == (camera.height, camera.width, 3) and img.dtype == np.uint8
    x, y, w, h = box
    assert x <= truth.u[i] <= x + w and y <= truth.v[i] <= y + h
    # the box is about the UUV's apparent size: 0.34-0.46 m seen from ~8-12 m
    assert 8 < max(w, h) < 80


def test_silhouette_centre_near_reference_pixel_at_nadir():
    """Independent of ray details: looking straight down, the pixels the UUV changes are centred on its pixel."""
    sc = with_overrides(load_scenario(SCENARIOS / "nadir_hover.toml"), render={"noise_sigma": 0.0})
    camera = camera_of(sc)
    truth = frame_truth(sc, Motion(sc), camera)
    renderer = Renderer(sc, camera)
    view = truth.view(0)
    with_uuv, _ = renderer.render(view)
    without, box = renderer.render(replace(view, uuv_visible=False))
    assert box is None
    changed = np.abs(with_uuv.astype(int) - without.astype(int)).sum(axis=2) > 6
    ys, xs = np.nonzero(changed)
    assert len(ys) > 200
    assert abs(xs.mean() - truth.u[0]) < 1.5 and abs(ys.mean() - truth.v[0]) < 1.5


def test_occluded_frames_have_no_track_and_no_uuv():
    sc = load_scenario(SCENARIOS / "occlusion.toml")
    track = read_table(
        BUNDLED_DIR / "occlusion" / "track.csv", ("t", "u", "v"), allow_empty=("u", "v")
    )
    truth_csv = read_table(BUNDLED_DIR / "occlusion" / "truth.csv", ("t", "lat", "lon", "depth_m"))
    tau = track["t"] - sc.start_unix
    ((a, b),) = sc.occlusions
    hidden = (tau >= a) & (tau < b)
    assert hidden.sum() == round((b - a) * sc.fps)
    assert np.all(np.isnan(track["u"][hidden])) and np.all(np.isfinite(track["u"][~hidden]))
    assert len(truth_csv["t"]) == len(track["t"]) and np.all(np.isfinite(truth_csv["lat"]))


def test_cached_rays_are_the_rays_computed_for_the_pixels(scene, monkeypatch):
    """The UUV's rays come from a cache of pixel tiles: for any pixels (here scattered over tile edges, the image's
    edges and more tiles than are kept), they are the numbers pixel_rays gives for those pixels' subsamples."""
    sc, camera, _, renderer = scene
    monkeypatch.setattr(render, "RAY_TILES_KEPT", 3)  # eviction on every call below
    rng = np.random.default_rng(5)
    ss = sc.render.supersample
    for _ in range(4):
        rows = np.concatenate([rng.integers(0, camera.height, 200), [0, camera.height - 1, 31, 32]])
        cols = np.concatenate([rng.integers(0, camera.width, 200), [camera.width - 1, 0, 32, 31]])
        su, sv = render.subsamples(rows, cols, ss)
        expected = pixel_rays(camera, su.ravel(), sv.ravel())
        np.testing.assert_array_equal(renderer._rays(rows, cols), expected)
        assert len(renderer._ray_tiles) == 3

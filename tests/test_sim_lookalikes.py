"""The look-alike knobs of the simulator, each checked against the scenario's own truth.

A UAV following a cruising UUV (the seafloor slides through the image), the UUV's shadow on a
shallow sunlit bottom, a second vehicle crossing, a dark rock by the UUV's path. Where they
appear is computed here forward, from the scenario's knobs and truth.csv: box corners (and,
for the shadow, the sunlight refracted by Snell's law written as angles) projected by the
light's surface crossing (Fermat's principle) and cv2.projectPoints — and compared with
what the renderer's per-pixel ray casting drew. No localizer code.
"""

from dataclasses import replace

import cv2
import numpy as np
import pymap3d
import pytest
from test_sim_height_knobs import gpi
from test_sim_knobs import SCENARIOS, read_tlog

from groundstation.session.read import read_table
from localizer.calibration import ConfigError
from sim_fixtures.generate import camera_of, frame_truth, generate, reference_pixel
from sim_fixtures.motion import Motion
from sim_fixtures.render import Renderer
from sim_fixtures.scenario import load_scenario, scenario_from_dict, with_overrides

STILL = {"noise_sigma": 0.0}  # renders compared pixel by pixel: no sensor noise


def local_ned(sc, truth):
    """truth.csv's positions in the scenario's world frame (north, east, down), by pymap3d's NED call."""
    s = sc.site
    n, e, _ = pymap3d.geodetic2ned(
        truth["lat"], truth["lon"], s.surface_amsl_m, s.lat_deg, s.lon_deg, s.surface_amsl_m
    )
    return np.column_stack([n, e, truth["depth_m"]])


def corners(top_centre_ned, heading_rad, size_m):
    """The 8 corners (8, 3) of a level box whose top face is centred on ``top_centre_ned``, its length along the
    heading (radians from North)."""
    L, W, H = size_m
    c, s = np.cos(heading_rad), np.sin(heading_rad)
    return np.array(
        [
            (
                top_centre_ned[0] + c * x - s * y,
                top_centre_ned[1] + s * x + c * y,
                top_centre_ned[2] + z,
            )
            for x in (-L / 2, L / 2)
            for y in (-W / 2, W / 2)
            for z in (0.0, H)
        ]
    )


def pixels(camera, truth, i, points_ned, n_water):
    """Distorted pixels (N, 2) of submerged points seen in frame ``i`` (forward: Fermat + projectPoints)."""
    pts = np.asarray(points_ned, dtype=float).reshape(-1, 3)
    R = np.repeat(truth.R_ned_from_cv[i][None], len(pts), axis=0)
    cam = np.repeat(truth.camera_ned[i][None], len(pts), axis=0)
    return np.column_stack(reference_pixel(camera, R, cam, pts, n_water))


def hull_distance_px(hull_px, shape):
    """Signed distance (px) of every pixel centre of an image ``shape`` to a convex hull (positive inside)."""
    hull = cv2.convexHull(hull_px.astype(np.float32))
    vv, uu = np.mgrid[0 : shape[0], 0 : shape[1]]
    pts = np.column_stack([uu.ravel(), vv.ravel()]).astype(float)
    lo, hi = hull_px.min(axis=0) - 8, hull_px.max(axis=0) + 8  # far pixels: far outside
    out = np.full(len(pts), -99.0)
    near = np.all((pts >= lo) & (pts <= hi), axis=1)
    out[near] = [cv2.pointPolygonTest(hull, (float(u), float(v)), True) for u, v in pts[near]]
    return out.reshape(shape)


def changed(a, b, grey_levels=3.0):
    """Pixels where two renders differ by more than ``grey_levels`` in some channel."""
    return np.abs(a.astype(int) - b.astype(int)).max(axis=2) > grey_levels


def assert_silhouette(mask, hull_px, margin_px=1.5, ignore=None):
    """The changed pixels fill the projected hull (inside it by more than ``margin_px``) and nothing beyond it."""
    dist = hull_distance_px(hull_px, mask.shape)
    keep = np.ones(mask.shape, bool) if ignore is None else ~ignore
    inside, outside = (dist > margin_px) & keep, (dist < -margin_px) & keep
    assert inside.sum() > 40, inside.sum()
    assert mask[inside].all(), (
        f"{(~mask[inside]).sum()} of {inside.sum()} pixels inside the hull unchanged"
    )
    assert not mask[outside].any(), f"{mask[outside].sum()} pixels changed outside the hull"


class Scene:
    """A scenario's camera, truth and renderer."""

    def __init__(self, sc):
        self.sc, self.camera = sc, camera_of(sc)
        self.motion = Motion(sc)
        self.truth = frame_truth(sc, self.motion, self.camera)
        self.renderer = Renderer(sc, self.camera)
        self.n = sc.site.refractive_index

    def frame(self, tau_s):
        return round(tau_s * self.sc.fps)

    def render(self, i, **view_changes):
        return self.renderer.render(replace(self.truth.view(i), **view_changes))


# --- the UAV following a cruising UUV ----------------------------------------------------------------


@pytest.fixture(scope="module")
def follow(tmp_path_factory):
    sc = load_scenario(SCENARIOS / "follow_cruise.toml")
    path = tmp_path_factory.mktemp("follow") / "s"
    generate(sc, path, video=False)
    return sc, path


def test_cruise_speed_and_path_from_truth(follow):
    sc, path = follow
    v = sc.uuv
    truth = read_table(path / "truth.csv", ("t", "lat", "lon", "depth_m"))
    ned = local_ned(sc, truth)
    dt = np.diff(truth["t"])
    speed = np.hypot(*np.diff(ned[:, :2], axis=0).T) / dt
    weave_speed = v.weave_m * 2 * np.pi / v.weave_period_s
    # along the course at speed_mps, plus the weave's sideways speed
    assert (
        v.speed_mps - 0.005 < speed.min()
        and speed.max() < np.hypot(v.speed_mps, weave_speed) + 0.005
    )
    course = np.radians(v.course_deg)
    along = (ned[:, 0] - v.north_m) * np.cos(course) + (ned[:, 1] - v.east_m) * np.sin(course)
    side = -(ned[:, 0] - v.north_m) * np.sin(course) + (ned[:, 1] - v.east_m) * np.cos(course)
    tau = truth["t"] - sc.start_unix
    assert np.abs(along - v.speed_mps * tau).max() < 0.002
    assert np.abs(side - v.weave_m * np.sin(2 * np.pi * tau / v.weave_period_s)).max() < 0.002
    track = read_table(path / "track.csv", ("t", "u", "v"), allow_empty=("u", "v"))
    assert np.isfinite(track["u"]).all()  # the UAV keeps it in view


def test_uav_follows_the_uuv(follow):
    """The UAV's reported position (GLOBAL_POSITION_INT) minus where the UUV was follow_lag_s earlier (truth.csv)
    stays within the hover's drift of one offset, while both travel ~29 m."""
    sc, path = follow
    tau, _, _ = gpi(sc, read_tlog(path / "uav.tlog"))
    msgs = [
        m
        for m in (r[2] for r in read_tlog(path / "uav.tlog"))
        if m.get_type() == "GLOBAL_POSITION_INT"
    ]
    s = sc.site
    n, e, _ = pymap3d.geodetic2ned(
        np.array([m.lat for m in msgs]) / 1e7,
        np.array([m.lon for m in msgs]) / 1e7,
        s.surface_amsl_m,
        s.lat_deg,
        s.lon_deg,
        s.surface_amsl_m,
    )
    truth = read_table(path / "truth.csv", ("t", "lat", "lon", "depth_m"))
    uuv = local_ned(sc, truth)
    t_truth = truth["t"] - sc.start_unix
    lagged = tau - sc.uav.follow_lag_s
    use = (lagged >= t_truth[0]) & (lagged <= t_truth[-1])
    off = np.column_stack(
        [
            n[use] - np.interp(lagged[use], t_truth, uuv[:, 0]),
            e[use] - np.interp(lagged[use], t_truth, uuv[:, 1]),
        ]
    )
    travelled = np.hypot(n[use][-1] - n[use][0], e[use][-1] - e[use][0])
    assert travelled > 0.9 * sc.uuv.speed_mps * (lagged[use][-1] - lagged[use][0])
    spread = np.hypot(*(off - off.mean(axis=0)).T).max()
    assert spread < 2 * sc.uav.drift_m + 0.05, (
        spread
    )  # the drift's two sinusoids, 0.7 + 0.3 of drift_m


def test_seafloor_slides_through_the_image():
    """Two renders 0.5 s apart: the floor around a floor point moves by the shift of that point's forward
    projection (phase correlation of the renderer's images against Fermat + projectPoints)."""
    sc = with_overrides(
        load_scenario(SCENARIOS / "follow_cruise.toml"), render={**STILL, "caustics": 0.0}
    )
    scene = Scene(sc)
    for tau_s in (3.0, 15.0):
        i, j = scene.frame(tau_s), scene.frame(tau_s + 0.5)
        floor_pt = np.append(scene.truth.uuv_ned[i, :2], sc.site.floor_depth_m)
        (ui, vi), (uj, vj) = (
            pixels(scene.camera, scene.truth, k, floor_pt, scene.n)[0] for k in (i, j)
        )
        a, b = (
            cv2.cvtColor(scene.render(k, uuv_visible=False)[0], cv2.COLOR_BGR2GRAY).astype(
                np.float32
            )
            for k in (i, j)
        )
        x, y, half = round(ui), round(vi), 48
        assert half <= x < sc.camera.width - half and half <= y < sc.camera.height - half
        window = cv2.createHanningWindow((2 * half, 2 * half), cv2.CV_32F)
        (dx, dy), _ = cv2.phaseCorrelate(
            a[y - half : y + half, x - half : x + half].copy(),
            b[y - half : y + half, x - half : x + half].copy(),
            window,
        )
        expected = np.array([uj - ui, vj - vi])
        assert np.hypot(*expected) > 15  # it moves
        assert np.hypot(dx - expected[0], dy - expected[1]) < 1.5, (tau_s, (dx, dy), expected)


# --- the shadow on a shallow sunlit bottom -----------------------------------------------------------


@pytest.fixture(scope="module")
def shadow():
    return Scene(with_overrides(load_scenario(SCENARIOS / "shadow_shallow.toml"), render=STILL))


def sunlight_down_ned(sc):
    """The sunlight's direction in the water: zenith angle by Snell's law (sin θw = sin θa / n), azimuth away
    from the sun."""
    r = sc.render
    zenith_air = np.radians(90.0 - r.sun_elevation_deg)
    zenith_water = np.arcsin(np.sin(zenith_air) / sc.site.refractive_index)
    away = np.radians(r.sun_azimuth_deg) + np.pi
    return np.array(
        [
            np.sin(zenith_water) * np.cos(away),
            np.sin(zenith_water) * np.sin(away),
            np.cos(zenith_water),
        ]
    )


@pytest.mark.parametrize("tau_s", [0.0, 8.0, 20.0])
def test_shadow_lands_where_the_refracted_sunlight_through_the_corners_meets_the_floor(
    shadow, tau_s
):
    sc, truth, i = shadow.sc, shadow.truth, shadow.frame(tau_s)
    floor = sc.site.floor_depth_m
    sun = sunlight_down_ned(sc)
    box = corners(truth.uuv_ned[i], truth.uuv_heading[i], sc.uuv.size_m)
    on_floor = box + sun * ((floor - box[:, 2]) / sun[2])[:, None]
    ground = cv2.convexHull(on_floor[:, :2].astype(np.float32))
    # the shadow's place: beside the UUV, away from the sun, by (floor - depth) x tan(zenith in water)
    offset = on_floor[:, :2].mean(axis=0) - box[:, :2].mean(axis=0)
    mid_depth = truth.uuv_ned[i, 2] + sc.uuv.size_m[2] / 2
    assert np.hypot(*offset) == pytest.approx(
        (floor - mid_depth) * np.tan(np.arcsin(np.hypot(*sun[:2]))), rel=1e-6
    )

    lit = with_overrides(sc, render={**STILL, "shadow": 0.0})
    plain = Renderer(lit, shadow.camera)
    with_shadow, _ = shadow.render(i)
    without, _ = plain.render(truth.view(i))
    no_uuv, _ = plain.render(replace(truth.view(i), uuv_visible=False))
    drawn = changed(without, no_uuv, 0.0).astype(np.uint8)
    uuv = cv2.dilate(drawn, np.ones((5, 5), np.uint8)).astype(bool)
    dark = (with_shadow.astype(int) - without.astype(int)).max(
        axis=2
    ) < -3  # darker in every channel

    # floor points on a 1 cm grid around the shadow, their pixels by forward projection
    lo, hi = on_floor[:, :2].min(axis=0) - 0.15, on_floor[:, :2].max(axis=0) + 0.15
    n, e = np.meshgrid(np.arange(lo[0], hi[0], 0.01), np.arange(lo[1], hi[1], 0.01), indexing="ij")
    pts = np.column_stack([n.ravel(), e.ravel(), np.full(n.size, floor)])
    inside_m = np.array(
        [cv2.pointPolygonTest(ground, (float(a), float(b)), True) for a, b in pts[:, :2]]
    )
    uv = np.round(pixels(shadow.camera, truth, i, pts, shadow.n)).astype(int)
    seen = ~uuv[uv[:, 1], uv[:, 0]]
    # about 2.5 pixels on the floor
    footprint_m = 2.5 * (floor - truth.camera_ned[i, 2]) / shadow.camera.fx
    deep_in, far_out = seen & (inside_m > footprint_m), seen & (inside_m < -footprint_m)
    assert deep_in.sum() > 300  # much of the shadow is beside the UUV, not under it
    assert dark[uv[deep_in, 1], uv[deep_in, 0]].all()
    assert not dark[uv[far_out, 1], uv[far_out, 0]].any()
    inner = cv2.erode(drawn, np.ones((3, 3), np.uint8)).astype(bool)  # pixels the UUV covers whole
    # its own shadow is not on it
    assert inner.sum() > 100 and np.array_equal(with_shadow[inner], without[inner])


def test_shadow_touches_the_uuv_at_times(shadow):
    """The scenario's point: seen from above, the shadow touches or overlaps the vehicle's top face in some frames
    and lies more than 0.1 m apart in others (its depth changes, it turns)."""
    sc, truth = shadow.sc, shadow.truth
    sun = sunlight_down_ned(sc)
    L, W, _ = sc.uuv.size_m
    grid = [(x, y) for x in np.linspace(-L / 2, L / 2, 9) for y in np.linspace(-W / 2, W / 2, 7)]
    gaps = []
    for i in range(0, len(truth.tau_s), 15):
        box = corners(truth.uuv_ned[i], truth.uuv_heading[i], sc.uuv.size_m)
        shade = box + sun * ((sc.site.floor_depth_m - box[:, 2]) / sun[2])[:, None]
        hull = cv2.convexHull(shade[:, :2].astype(np.float32))
        c, s = np.cos(truth.uuv_heading[i]), np.sin(truth.uuv_heading[i])
        top = truth.uuv_ned[i, :2] + np.array([(c * x - s * y, s * x + c * y) for x, y in grid])
        gaps.append(
            max(0.0, -max(cv2.pointPolygonTest(hull, (float(a), float(b)), True) for a, b in top))
        )
    gaps = np.array(gaps)
    assert (gaps < 0.02).mean() > 0.2 and (gaps > 0.1).mean() > 0.2, gaps


def test_shadow_falls_on_the_rock_too():
    """With a rock and shadows, the UUV half over the rock (on the rock's side towards the sun) darkens part of the
    rock's top face: shadows fall on the boxes as on the floor."""
    sc = scenario_from_dict(
        {
            "name": "shade_on_rock",
            "duration_s": 1.0,
            "camera": {"width": 320, "height": 180},
            "mount": {"pitch_deg": -90.0},
            "site": {"floor_depth_m": 2.0},
            "uav": {"height_m": 5.0},
            "uuv": {"depth_m": 1.0, "depth_swing_m": 0.0},
            "rock": {"enabled": True, "at_s": 0.0, "offset_m": [0.25, -0.21]},
            "render": {**STILL, "shadow": 0.7, "sun_azimuth_deg": 140.0, "sun_elevation_deg": 60.0},
        }
    )
    scene = Scene(sc)
    lit = Renderer(with_overrides(sc, render={**STILL, "shadow": 0.0}), scene.camera)
    view = scene.truth.view(0)
    rock_only = replace(view, uuv_visible=False)
    rock_top = corners(scene.truth.rock.ned, scene.truth.rock.heading, sc.rock.size_m)[::2]
    hull = pixels(scene.camera, scene.truth, 0, rock_top, scene.n)
    dist = hull_distance_px(hull, (sc.camera.height, sc.camera.width))
    uuv_px = changed(lit.render(view)[0], lit.render(rock_only)[0], 0.0)
    top_seen = (dist > 1.5) & ~cv2.dilate(
        uuv_px.astype(np.uint8), np.ones((5, 5), np.uint8)
    ).astype(bool)
    assert top_seen.sum() > 20
    darker = (scene.renderer.render(view)[0].astype(int) - lit.render(view)[0].astype(int)).max(
        axis=2
    ) < -1
    assert darker[top_seen].any()  # the UUV's shadow on the rock's top
    alone = (
        scene.renderer.render(rock_only)[0].astype(int) - lit.render(rock_only)[0].astype(int)
    ).max(axis=2)
    assert not (alone[top_seen] < -1).any()  # the rock alone is not shadowed on its own top


# --- a second vehicle ------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def second():
    return Scene(with_overrides(load_scenario(SCENARIOS / "second_vehicle.toml"), render=STILL))


def test_second_vehicle_passes_as_its_knobs_say(second):
    """At pass_at_s it is miss_m to the right of its course, its course course_rel_deg from the UUV's heading
    (from truth.csv's positions), and it is in the image for a few seconds."""
    sc, truth, s = second.sc, second.truth, second.sc.second_uuv
    i = second.frame(s.pass_at_s)
    step = truth.uuv_ned[i + 1, :2] - truth.uuv_ned[i - 1, :2]
    uuv_heading = np.arctan2(step[1], step[0])
    way = truth.second_ned[i + 1, :2] - truth.second_ned[i - 1, :2]
    course = np.arctan2(way[1], way[0])
    assert np.degrees((course - uuv_heading) % (2 * np.pi)) == pytest.approx(
        s.course_rel_deg % 360, abs=0.5
    )
    assert np.hypot(*way) * sc.fps / 2 == pytest.approx(s.speed_mps, rel=1e-6)
    rel = truth.second_ned[i, :2] - truth.uuv_ned[i, :2]
    right = np.array([-np.sin(course), np.cos(course)])
    assert rel @ right == pytest.approx(s.miss_m, abs=1e-6) and rel @ way == pytest.approx(
        0.0, abs=1e-6
    )
    assert np.all(truth.second_ned[:, 2] == s.depth_m)
    ref = np.array(
        [
            pixels(second.camera, truth, k, truth.second_ned[k], second.n)[0]
            for k in range(0, len(truth.tau_s), 3)
        ]
    )
    in_view_s = second.camera.contains(*np.nan_to_num(ref, nan=-1.0).T).sum() * 3 / sc.fps
    assert 3.0 < in_view_s < 15.0, in_view_s


@pytest.mark.parametrize("tau_s", [12.8, 15.5])
def test_second_vehicle_appears_where_it_should(second, tau_s):
    """The pixels it changes fill the forward projection of its 8 corners, and no others (the UUV masked)."""
    sc, truth, i = second.sc, second.truth, second.frame(tau_s)
    hull = pixels(
        second.camera,
        truth,
        i,
        corners(truth.second_ned[i], second.motion.second_heading, sc.uuv.size_m),
        second.n,
    )
    assert np.isfinite(hull).all() and second.camera.contains(hull[:, 0], hull[:, 1]).all()
    both, _ = second.render(i)
    alone, _ = second.render(i, others=())
    bare, _ = second.render(i, others=(), uuv_visible=False)
    uuv = cv2.dilate(changed(alone, bare, 0.0).astype(np.uint8), np.ones((5, 5), np.uint8)).astype(
        bool
    )
    assert_silhouette(changed(both, alone), hull, ignore=uuv)


def light_path_blocked(camera_ned, point_ned, box_corners, n_water):
    """Whether the light from a submerged point to the camera passes through a box (its 8 corners, level): the
    path, straight in the water up to its surface crossing (Fermat), sampled every 5 mm against the box."""
    from sim_fixtures.geometry import surface_crossing

    crossing = surface_crossing(camera_ned, point_ned, n_water)
    s = np.linspace(0.0, 1.0, max(2, int(np.linalg.norm(crossing - point_ned) / 0.005)))[1:]
    path = point_ned + s[:, None] * (crossing - point_ned)
    top = box_corners[:, 2].min()
    bottom = box_corners[:, 2].max()
    a, b, d = box_corners[0], box_corners[2], box_corners[4]  # corners differing in y, then in x
    ex, ey = d - a, b - a
    rel = path - a
    x, y = rel @ ex / (ex @ ex), rel @ ey / (ey @ ey)
    return bool(
        np.any(
            (x >= 0) & (x <= 1) & (y >= 0) & (y <= 1) & (path[:, 2] >= top) & (path[:, 2] <= bottom)
        )
    )


def test_uuv_hidden_behind_the_second_vehicle_has_no_track(tmp_path):
    """The second vehicle passes right over the UUV, head on: track.csv is empty where most of the UUV's top face
    is hidden from the camera (its light paths pass through the other box) and filled where little is."""
    sc = scenario_from_dict(
        {
            "name": "cross_over",
            "seed": 3,
            "duration_s": 2.0,
            "camera": {"width": 320, "height": 180},
            "mount": {"pitch_deg": -90.0},
            "uav": {"drift_m": 0.0},
            "uuv": {"depth_m": 1.2, "depth_swing_m": 0.0, "path_n_m": 0.05, "path_e_m": 0.05},
            "second_uuv": {
                "enabled": True,
                "pass_at_s": 1.0,
                "miss_m": 0.0,
                "speed_mps": 1.0,
                "course_rel_deg": 180.0,
                "depth_m": 0.5,
            },
            "render": STILL,
        }
    )
    generate(sc, tmp_path / "s")
    track = read_table(tmp_path / "s" / "track.csv", ("t", "u", "v"), allow_empty=("u", "v"))
    motion, camera = Motion(sc), camera_of(sc)
    truth = frame_truth(sc, motion, camera)
    L, W, _ = sc.uuv.size_m
    grid = [
        (x, y) for x in np.linspace(-0.45, 0.45, 7) * L for y in np.linspace(-0.45, 0.45, 5) * W
    ]
    hidden_share = []
    for i in range(len(truth.tau_s)):
        c, s = np.cos(truth.uuv_heading[i]), np.sin(truth.uuv_heading[i])
        other = corners(truth.second_ned[i], motion.second_heading, sc.uuv.size_m)
        top = [truth.uuv_ned[i] + (c * x - s * y, s * x + c * y, 0.0) for x, y in grid]
        hidden_share.append(
            np.mean(
                [
                    light_path_blocked(truth.camera_ned[i], p, other, sc.site.refractive_index)
                    for p in top
                ]
            )
        )
    hidden_share = np.array(hidden_share)
    tracked = np.isfinite(track["u"])
    assert (hidden_share > 0.75).sum() >= 5 and (hidden_share < 0.25).sum() >= 20
    assert not tracked[hidden_share > 0.75].any()
    assert tracked[hidden_share < 0.25].all()


# --- a rock ----------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def rock():
    return Scene(with_overrides(load_scenario(SCENARIOS / "rock_pass.toml"), render=STILL))


def rock_centre_from_truth(sc, scene):
    """Where the rock's knobs put it: below the UUV's truth.csv position at at_s, shifted by offset_m."""
    r = sc.rock
    i = scene.frame(r.at_s)
    return np.append(
        scene.truth.uuv_ned[i, :2] + np.asarray(r.offset_m), sc.site.floor_depth_m - r.size_m[2]
    )


def test_uuv_passes_close_to_and_over_the_rock(rock):
    sc, truth = rock.sc, rock.truth
    centre = rock_centre_from_truth(sc, rock)
    gap = np.hypot(*(truth.uuv_ned[:, :2] - centre[:2]).T)
    assert gap.min() < 0.5 and (gap < 1.0).sum() / sc.fps > 2.0  # within a metre for seconds
    assert (truth.uuv_ned[:, 2] + sc.uuv.size_m[2]).max() < centre[2]  # over its top, never into it


@pytest.mark.parametrize("tau_s", [0.0, 20.0])
def test_rock_pixels(rock, tau_s):
    """The rock's pixels fill the forward projection of its corners (placed from truth.csv), and it is dark."""
    sc, truth, i = rock.sc, rock.truth, rock.frame(tau_s)
    hull = pixels(
        rock.camera,
        truth,
        i,
        corners(rock_centre_from_truth(sc, rock), np.radians(sc.rock.heading_deg), sc.rock.size_m),
        rock.n,
    )
    with_rock, _ = rock.render(i)
    without, _ = rock.render(i, others=())
    bare, _ = rock.render(i, others=(), uuv_visible=False)
    uuv = cv2.dilate(
        changed(without, bare, 0.0).astype(np.uint8), np.ones((5, 5), np.uint8)
    ).astype(bool)
    mask = changed(with_rock, without)
    assert_silhouette(mask, hull, ignore=uuv)
    grey = cv2.cvtColor(with_rock, cv2.COLOR_BGR2GRAY).astype(float)
    sand = cv2.cvtColor(without, cv2.COLOR_BGR2GRAY).astype(float)
    assert grey[mask & ~uuv].mean() < 0.75 * sand[mask & ~uuv].mean()


# --- the contract ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "changes, key",
    [
        (
            {
                "second_uuv": {"enabled": True, "pass_at_s": 4.0, "depth_m": 1.1},
                "uuv": {"depth_m": 1.0},
            },
            "second_uuv.miss_m",
        ),
        (
            {
                "rock": {"enabled": True, "at_s": 2.0, "offset_m": [0.0, 0.0]},
                "site": {"floor_depth_m": 1.4},
                "uuv": {"depth_m": 1.0, "depth_swing_m": 0.0},
            },
            "rock.offset_m",
        ),
        ({"rock": {"enabled": True, "size_m": [0.5, 0.4, 5.0]}}, "rock.size_m"),
        ({"rock": {"enabled": True, "size_m": [0.5, -0.4, 0.2]}}, "rock.size_m"),
        ({"second_uuv": {"enabled": True, "depth_m": 3.9}}, "second_uuv.depth_m"),
        ({"render": {"shadow": 1.5}}, "render.shadow"),
        ({"uav": {"standoff": "chase"}}, "uav.standoff"),
    ],
)
def test_impossible_lookalikes_are_one_line_errors(changes, key):
    with pytest.raises(ConfigError) as err:
        scenario_from_dict({"name": "bad", **changes}, "bad.toml")
    line = str(err.value)
    assert line.startswith(f"bad.toml: {key} = ") and "\n" not in line, line

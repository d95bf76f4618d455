"""Wind waves in the simulator: the spectrum against Cox & Munk, refraction through a tilted facet, the truth pixel
through the waves, the wavy render, the flat world unchanged, and the downlink's encode.

The checks are independent of the code they check: the slope variance is measured on a realisation (sampled at
random places and times) against the spectrum's integral; Snell's law through a tilted facet is worked by hand and,
for the truth pixel, in angle form with the surface crossing found by bisection; the waves' own error is the
localizer's flat-surface solution of the truth pixel (the simulator never imports the localizer's geometry).
"""

import json
import shutil
import subprocess
import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq

from groundstation.session.read import read_table
from localizer import attitude as latt
from localizer.calibration import Calibration
from localizer.contract import ConfigError
from localizer.ray import pixel_to_offset
from sim_fixtures import waves as w
from sim_fixtures.bundle import SCENARIOS
from sim_fixtures.generate import (
    TRUTH_WAVES_CSV,
    Encoder,
    _session_toml,
    apparent_radius_m,
    camera_of,
    frame_truth,
    generate,
    rate_control,
)
from sim_fixtures.geometry import R_GIMBAL_FROM_CV, facet_normal_up, pixel_rays, refract_into_water
from sim_fixtures.motion import Motion
from sim_fixtures.render import Renderer, floor_div, water_path_ned
from sim_fixtures.scenario import DownlinkSpec, load_scenario, scenario_from_dict, with_overrides

N_WATER = 1.34


def small(name: str, seconds: float = 1.0, **tables):
    """A bundled waves scenario, shortened (and changed by ``tables``)."""
    return with_overrides(load_scenario(SCENARIOS / f"{name}.toml"), duration_s=seconds, **tables)


@pytest.mark.parametrize("wind", [2.0, 5.0, 8.0])
def test_slope_variance_is_cox_and_munks_and_the_realisation_has_the_resolved_bands(wind):
    sc = scenario_from_dict({"name": "x", "waves": {"wind_mps": wind}, "uav": {"height_m": 25.0}})
    spec = w.Spectrum(wind, sc.waves.fetch_m)
    # the whole spectrum's mean-square slope, by adaptive quadrature of B(k)/k: Cox & Munk's at 12.5 m
    total, _ = quad(
        lambda k: spec.saturation(k) / k,
        spec.k_low,
        w.K_TOTAL_MAX,
        limit=400,
        points=[spec.k_peak, w.K_M],
    )
    assert 1.0 < spec.u12_5_mps / wind < 1.04
    assert total == pytest.approx(0.003 + 0.00512 * spec.u12_5_mps, rel=2e-3)
    field = w.wave_field(sc, camera_of(sc).fx)
    resolved, _ = quad(
        lambda k: spec.saturation(k) / k,
        spec.k_low,
        2 * np.pi / field.shortest_wavelength_m,
        limit=400,
        points=[spec.k_peak],
    )
    assert field.resolved_mss == pytest.approx(resolved, rel=2e-3)
    assert field.resolved_mss + field.unresolved_mss == pytest.approx(total, rel=2e-3)
    # a wavelength of 4 pixels from 25 m (19 cm) resolves this much
    assert 0.3 < field.resolved_mss / total < 0.9

    # measured on the realisation: the slopes at random places and times
    rng = np.random.default_rng(3)
    n = 200_000
    slope = field.gradient(
        rng.uniform(-300, 300, n), rng.uniform(-300, 300, n), rng.uniform(0, 600, n)
    )
    assert np.mean(np.sum(slope**2, axis=1)) == pytest.approx(field.resolved_mss, rel=0.04)
    # Cox & Munk's crosswind/upwind ratio of the slope variances, from the spreading (loosely: 300 directions drawn)
    downwind = w.downwind_rad(sc)
    along = slope @ [np.cos(downwind), np.sin(downwind)]
    across = slope @ [-np.sin(downwind), np.cos(downwind)]
    assert np.var(across) / np.var(along) == pytest.approx(
        w.cox_munk_crosswind_ratio(spec.u12_5_mps), abs=0.2
    )


def test_the_floors_gridded_waves_are_the_exact_sums():
    sc = scenario_from_dict({"name": "x", "waves": {"wind_mps": 6.0}, "uav": {"height_m": 20.0}})
    field = w.wave_field(sc, camera_of(sc).fx)
    grid = field.gridded(np.array([-6.0, -9.0]), np.array([5.0, 8.0]), 3.7)
    rng = np.random.default_rng(4)
    ne = np.column_stack([rng.uniform(-6, 5, 5000), rng.uniform(-9, 8, 5000)])
    exact = field.at(3.7)
    assert np.sqrt(np.mean((grid.height(ne) - exact.height(ne)) ** 2)) < 0.06 * field.height_sigma_m
    slope = exact.gradient(ne)
    assert np.sqrt(np.mean((grid.gradient(ne) - slope) ** 2)) < 0.06 * np.sqrt(np.mean(slope**2))


def test_refraction_through_a_tilted_facet_worked_by_hand():
    """A ray straight down meets a facet tilted 20 degrees (rising to the south): sin θt = sin 20° / 1.34,
    θt = 14.7878°, and the ray leaves 20 − 14.7878 = 5.2122 degrees from the vertical, towards the south."""
    normal = facet_normal_up(np.array([-np.tan(np.radians(20.0)), 0.0]))
    np.testing.assert_allclose(
        normal, [np.sin(np.radians(20.0)), 0.0, -np.cos(np.radians(20.0))], atol=1e-15
    )
    t = refract_into_water(np.array([0.0, 0.0, 1.0]), N_WATER, normal)
    off = np.radians(20.0 - 14.787_8)
    np.testing.assert_allclose(t, [-np.sin(off), 0.0, np.cos(off)], atol=2e-6)
    # a level facet is the flat surface, to the last bit
    d = np.array([[0.3, -0.2, 0.9], [0.0, 0.1, 0.7]])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    np.testing.assert_array_equal(
        refract_into_water(d, N_WATER, facet_normal_up(np.zeros((2, 2)))),
        refract_into_water(d, N_WATER),
    )


def snell_angle_form(d, normal_up, n_water):
    """Refraction in angle form (independent of the vector formula): the ray in the plane of incidence, θt from the
    inward normal, sin θt = sin θi / n."""
    inward = -normal_up
    cos_i = d @ inward
    tangent = d - cos_i * inward
    sin_t = np.linalg.norm(tangent) / n_water
    return np.sqrt(1 - sin_t**2) * inward + sin_t * tangent / np.linalg.norm(tangent)


@pytest.fixture(scope="module")
def oblique():
    sc = small("waves_5mps_oblique", 2.0)
    camera = camera_of(sc)
    return sc, camera, frame_truth(sc, Motion(sc), camera)


def test_the_truth_pixel_sees_the_reference_point_through_the_waves(oblique):
    sc, camera, truth = oblique
    field = w.wave_field(sc, camera.fx / floor_div(camera)).averaged(
        apparent_radius_m(sc.uuv.size_m)
    )
    frames = np.arange(0, len(truth.tau_s), 7)
    assert np.isfinite(truth.u[frames]).all()
    ray = pixel_rays(camera, truth.u[frames], truth.v[frames])
    d = np.einsum("nij,nj->ni", truth.R_ned_from_cv[frames], ray)
    # forward, along the renderer's own path for the vehicles' rays
    p = water_path_ned(d, truth.camera_ned[frames], N_WATER, field.at(truth.tau_s[frames]))
    point = truth.uuv_ned[frames]
    land = (
        p.surface_ne + p.dir_water[:, :2] * ((point[:, 2] - p.down_m) / p.dir_water[:, 2])[:, None]
    )
    assert np.abs(land - point[:, :2]).max() < 1e-3
    # independently: the crossing by bisection on the ray, Snell's law in angle form
    for i, (c, di, t_s, pt) in enumerate(
        zip(truth.camera_ned[frames], d, truth.tau_s[frames], point)
    ):

        def below(s, c=c, di=di, t_s=t_s):
            x = c + s * di
            return x[2] + field.height(x[0], x[1], t_s)  # down + η: 0 on the surface

        s = brentq(below, 0.5 * -c[2] / di[2], 2.0 * -c[2] / di[2], xtol=1e-12)
        x = c + s * di
        t = snell_angle_form(di, facet_normal_up(field.gradient(x[0], x[1], t_s)), N_WATER)
        hit = x[:2] + t[:2] * (pt[2] - x[2]) / t[2]
        assert np.hypot(*(hit - pt[:2])) < 1e-3, (i, hit, pt)
    # the waves move it: off the flat surface's pixel by about a pixel or more
    flat = frame_truth(with_overrides(sc, waves={"wind_mps": 0.0}), Motion(sc), camera)
    shift = np.hypot(truth.u - flat.u, truth.v - flat.v)
    assert 0.5 < np.sqrt(np.mean(shift**2)) < 10.0


def test_the_waves_own_error_is_the_localizers_flat_solution_of_the_truth_pixel(oblique, tmp_path):
    sc, camera, truth = oblique
    generate(sc, tmp_path, video=False)
    track = read_table(tmp_path / "track.csv", ("t", "u", "v"), allow_empty=("u", "v"))
    waves = read_table(
        tmp_path / TRUTH_WAVES_CSV,
        ("t", "wave_dn_m", "wave_de_m"),
        allow_empty=("wave_dn_m", "wave_de_m"),
    )
    np.testing.assert_array_equal(np.isnan(waves["wave_dn_m"]), np.isnan(track["u"]))
    ok = np.isfinite(track["u"])
    assert ok.sum() > 0.9 * len(ok)
    loc_cam = Calibration.from_dict(tomllib.loads(_session_toml(sc, camera, None, None))).camera
    R_loc = latt.R_ned_from_cv(truth.R_ned_from_cv[ok] @ R_GIMBAL_FROM_CV.T)
    off, reaches = pixel_to_offset(
        loc_cam,
        R_loc,
        track["u"][ok],
        track["v"][ok],
        -truth.camera_ned[ok, 2],
        truth.uuv_ned[ok, 2],
        N_WATER,
    )
    assert reaches.all()
    error = truth.camera_ned[ok, :2] + off - truth.uuv_ned[ok, :2]
    np.testing.assert_allclose(
        error, np.column_stack([waves["wave_dn_m"][ok], waves["wave_de_m"][ok]]), atol=2e-4
    )
    rms = np.sqrt(np.mean(error**2, axis=0))
    assert (0.01 < rms).all() and (rms < 0.15).all()  # centimetres at 2 m deep in a 5 m/s wind


def test_a_wavy_scene_renders_and_no_wind_is_the_flat_world_to_the_byte():
    sc = small("waves_2mps_nadir", 0.2, camera={"width": 320, "height": 180, "hfov_deg": 20.0})
    camera = camera_of(sc)
    flat = with_overrides(sc, waves={"wind_mps": 0.0})
    no_table = with_overrides(sc, waves=type(sc.waves)(), downlink=DownlinkSpec())
    truth = frame_truth(sc, Motion(sc), camera)
    flat_truth = frame_truth(flat, Motion(flat), camera)
    np.testing.assert_array_equal(flat_truth.u, frame_truth(no_table, Motion(no_table), camera).u)
    assert flat_truth.wave_error_ne is None
    wavy_r, flat_r, none_r = (
        Renderer(sc, camera),
        Renderer(flat, camera),
        Renderer(no_table, camera),
    )
    assert wavy_r.waves is not None and flat_r.waves is None
    for i in (0, 5):
        wavy, box = wavy_r.render(truth.view(i))
        still, flat_box = flat_r.render(flat_truth.view(i))
        np.testing.assert_array_equal(still, none_r.render(flat_truth.view(i))[0])
        assert box is not None and flat_box is not None
        x, y, bw, bh = flat_box
        window = (slice(max(0, y - 4), y + bh + 4), slice(max(0, x - 4), x + bw + 4))
        change = np.abs(wavy[window].astype(int) - still[window].astype(int))
        assert change.mean() > 5.0  # the UUV (and the floor around it) seen through the waves
        # ... and the UUV is still where the truth says
        x, y, bw, bh = box
        assert x - 1 <= truth.u[i] <= x + bw + 1 and y - 1 <= truth.v[i] <= y + bh + 1


def test_caustics_flicker_on_the_vehicle_and_fade_with_depth():
    sc = small("waves_2mps_nadir", 1.0, render={"noise_sigma": 0.0, "caustics": 1.0})
    renderer = Renderer(sc, camera_of(sc))
    rng = np.random.default_rng(6)
    points = np.column_stack([rng.uniform(-3, 3, (20000, 2)), np.zeros(20000)])
    light = {}
    for depth in (0.3, 3.0):
        points[:, 2] = depth
        light[depth] = np.array(
            [renderer._caustic_light(renderer._caustic_texture(t), points) for t in (0.0, 0.5)]
        )
    # at a point, from frame to frame (0.5 s apart) the light changes by about its mean just below the surface ...
    change = {d: np.std(light[d][1] - light[d][0]) for d in light}
    assert change[0.3] / np.mean(light[0.3]) > 0.5
    # ... and exp(-0.4/m x 2.7 m) = 0.34 times that at 3 m
    assert change[3.0] / change[0.3] == pytest.approx(
        np.exp(-sc.waves.caustic_fade_per_m * 2.7), rel=1e-6
    )


def test_scenario_keys_are_checked():
    with pytest.raises(ConfigError, match=r"waves.wind_mps = 20"):
        scenario_from_dict({"name": "x", "waves": {"wind_mps": 20}}, "bad.toml")
    with pytest.raises(ConfigError, match=r"downlink.bitrate_mbps = 0"):
        scenario_from_dict({"name": "x", "downlink": {"bitrate_mbps": 0}}, "bad.toml")


def test_the_downlink_encode_has_its_bitrate_and_no_b_frames(tmp_path):
    assert rate_control(23, None, 30.0) == ["-crf", "23", "-g", "30"]  # the default: as before
    link = DownlinkSpec(bitrate_mbps=4.0, buffer_s=0.5, keyframe_s=2.0)
    assert rate_control(23, link, 30.0) == [
        "-b:v",
        "4000000",
        "-maxrate",
        "4000000",
        "-bufsize",
        "2000000",
        "-bf",
        "0",
        "-g",
        "60",
        "-threads",
        "1",
    ]
    if shutil.which("ffprobe") is None:
        pytest.skip("ffprobe not installed")
    rng = np.random.default_rng(2)
    base = rng.integers(0, 255, (180, 320, 3), dtype=np.uint8)
    noise = rng.integers(-20, 20, (90, 180, 320, 3))
    videos = [tmp_path / "v.mp4", tmp_path / "again.mp4"]
    for path in videos:
        enc = Encoder(path, 320, 180, 30.0, 23, link)
        for i in range(90):
            enc.write(np.clip(np.roll(base, 2 * i, axis=1) + noise[i], 0, 255).astype(np.uint8))
        enc.close()
    # the same frames, the same video (on several frame threads the buffer's rate control made them differ)
    assert videos[0].read_bytes() == videos[1].read_bytes()
    video = videos[0]
    out = subprocess.run(
        [
            "ffprobe",
            "-v",
            "error",
            "-select_streams",
            "v:0",
            "-show_entries",
            "frame=pict_type",
            "-of",
            "json",
            str(video),
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    types = [f["pict_type"] for f in json.loads(out.stdout)["frames"]]
    assert len(types) == 90 and "B" not in types
    keyframes = [i for i, t in enumerate(types) if t == "I"]
    assert {0, 60} <= set(keyframes) and max(
        np.diff([*keyframes, 90])
    ) <= 60  # (x264 may add one at a scene cut)


def test_the_waves_scenarios_load():
    for path in sorted(Path(SCENARIOS).glob("waves_*.toml")):
        sc = load_scenario(path)
        assert sc.waves.wind_mps > 0 and sc.downlink.bitrate_mbps is not None
        assert replace(sc.waves, wind_mps=0.0).wind_mps == 0.0

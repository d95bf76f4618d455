"""The simulator's geometry and the localizer's are two derivations, and they agree.

The simulator (scipy rotations, OpenCV projection and undistortion, vector Snell and
Fermat's principle, pymap3d through ENU) must not import the localizer's geometry,
so that its sessions check the localizer instead of echoing it. Here the localizer
(its attitude composition, the calibration's camera, ``pixel_to_offset``) maps the
pixels the simulator projects back to the submerged points they came from.
"""

import re
import tomllib
from pathlib import Path

import numpy as np
import pytest

from localizer import attitude as latt
from localizer.calibration import Calibration
from localizer.geodesy import ned_to_geodetic as l_ned_to_geodetic
from localizer.ray import pixel_to_offset
from sim_fixtures import geometry as g
from sim_fixtures.generate import _session_toml, camera_of, reference_pixel
from sim_fixtures.scenario import scenario_from_dict

SIM = Path(__file__).resolve().parents[1] / "sim_fixtures"
FORBIDDEN = ("attitude", "camera", "ray", "refraction", "geodesy", "pose", "fix")
N_WATER = 1.34


def test_the_simulator_does_not_import_the_localizers_geometry():
    pattern = re.compile(
        rf"^\s*(from\s+localizer\.({'|'.join(FORBIDDEN)})\b"
        rf"|import\s+localizer\.({'|'.join(FORBIDDEN)})\b"
        rf"|from\s+localizer\s+import\s+.*\b({'|'.join(FORBIDDEN)})\b)",
        re.MULTILINE,
    )
    offenders = {p.name: pattern.findall(p.read_text()) for p in SIM.rglob("*.py")}
    assert not {k: v for k, v in offenders.items() if v}


def calibration_camera(sc):
    """The camera as the localizer reads it from the session.toml the simulator writes."""
    return Calibration.from_dict(tomllib.loads(_session_toml(sc, camera_of(sc), None, None))).camera


def random_poses(rng, n):
    """Gimbal roll, pitch (a fifth exactly -90 deg), yaw relative to the vehicle, vehicle yaw (radians)."""
    pitch = np.radians(rng.uniform(-90.0, -30.0, n))
    pitch[::5] = -np.pi / 2
    return (
        np.radians(rng.uniform(-4.0, 4.0, n)),
        pitch,
        np.radians(rng.uniform(-180, 180, n)),
        np.radians(rng.uniform(-180, 180, n)),
    )


@pytest.mark.parametrize("size", [(640, 360), (1920, 1080)])
def test_projected_pixels_map_back_to_their_points_within_a_millimetre(size):
    rng = np.random.default_rng(8)
    sc = scenario_from_dict({"name": "x", "camera": {"width": size[0], "height": size[1]}})
    sim_cam, loc_cam = camera_of(sc), calibration_camera(sc)
    n = 400
    roll, pitch, yaw_rel, vehicle_yaw = random_poses(rng, n)
    height, depth = rng.uniform(5.0, 40.0, n), rng.uniform(0.2, 5.0, n)
    camera_ned = np.column_stack([rng.uniform(-20, 20, (n, 2)), -height])
    yaw = vehicle_yaw + yaw_rel
    R_sim = g.matrix_zyx(roll, pitch, yaw) @ g.R_GIMBAL_FROM_CV
    # a submerged point somewhere in the view: a random undistorted direction, refracted down to its depth
    xy = rng.uniform(-0.95, 0.95, (n, 2)) * [sim_cam.cx / sim_cam.fx, sim_cam.cy / sim_cam.fy]
    ray_ned = np.einsum("nij,nj->ni", R_sim, np.column_stack([xy, np.ones(n)]))
    ray_ned /= np.linalg.norm(ray_ned, axis=1, keepdims=True)
    keep = ray_ned[:, 2] > 0.2
    offset = g.reach_offset(ray_ned, height, depth, N_WATER)
    point = np.column_stack([camera_ned[:, :2] + offset, depth])
    u, v = reference_pixel(sim_cam, R_sim, camera_ned, point, N_WATER)
    keep &= np.isfinite(u) & sim_cam.contains(u, v)
    assert keep.sum() > 0.6 * n

    # the localizer: its own rotation from the quaternion the simulator would send, in both yaw frames
    q_earth = g.quat_wxyz(g.rotation_zyx(roll, pitch, yaw))
    q_vehicle = g.quat_wxyz(g.rotation_zyx(roll, pitch, yaw_rel))
    for q, flags, ok in ((q_earth, 76, keep), (q_vehicle, 44, keep)):  # straight down included
        R_loc = latt.R_ned_from_cv(latt.R_ned_from_gimbal_device(q[ok], flags, vehicle_yaw[ok]))
        off, reaches = pixel_to_offset(loc_cam, R_loc, u[ok], v[ok], height[ok], depth[ok], N_WATER)
        assert reaches.all()
        err = np.hypot(*(off - offset[ok]).T)
        assert err.max() < 1e-3, (flags, err.max())
        assert err.max() < 1e-6  # in fact both are exact to far below a millimetre


def test_float32_quaternion_straight_down_is_the_localizers_rotation():
    """Pitch exactly -90 deg as the wire carries it (float32): the same matrix either way."""
    for yaw_rel_deg in (0.0, 52.3, -135.0, 179.9):
        q = g.quat_wxyz(g.rotation_zyx(0.0, -np.pi / 2, np.radians(yaw_rel_deg)))
        q32 = q.astype(np.float32).astype(float)
        R_loc = latt.quat_to_R(q32)
        assert np.abs(R_loc - g.matrix_zyx(0.0, -np.pi / 2, np.radians(yaw_rel_deg))).max() < 3e-7
        pitch = -np.arcsin(np.clip(R_loc[2, 0], -1, 1))
        assert abs(np.degrees(pitch) + 90.0) < 1e-4  # it decodes to straight down
    # the shape of ArduCopter's straight down in facts.md, q = [0.63373, 0.31367, -0.63373, 0.31367]: y = -w, z = x
    w, x, y, z = g.quat_wxyz(g.rotation_zyx(0.0, -np.pi / 2, np.radians(52.3)))
    assert w > 0 and abs(y + w) < 1e-15 and abs(z - x) < 1e-15 and np.isclose(w * w + x * x, 0.5)


def test_vehicle_frame_straight_down_composes_with_the_vehicle_yaw():
    rng = np.random.default_rng(3)
    for _ in range(20):
        yaw_rel, vehicle_yaw = np.radians(rng.uniform(-180, 180, 2))
        q32 = g.quat_wxyz(g.rotation_zyx(0.0, -np.pi / 2, yaw_rel)).astype(np.float32).astype(float)
        R_loc = latt.R_ned_from_gimbal_device(q32, 44, vehicle_yaw)
        assert np.abs(R_loc - g.matrix_zyx(0.0, -np.pi / 2, vehicle_yaw + yaw_rel)).max() < 1e-6


def test_euler_rotations_agree():
    rng = np.random.default_rng(5)
    rpy = rng.uniform(-np.pi, np.pi, (500, 3)) * [1, 0.5, 1]
    assert np.abs(g.matrix_zyx(*rpy.T) - latt.euler_to_R(*rpy.T)).max() < 1e-14
    assert (
        np.abs(latt.quat_to_R(g.quat_wxyz(g.rotation_zyx(*rpy.T))) - latt.euler_to_R(*rpy.T)).max()
        < 1e-14
    )
    assert np.array_equal(g.R_GIMBAL_FROM_CV, latt.R_GIMBAL_FROM_CV)


def test_geodesy_through_enu_matches_the_localizers_ned():
    rng = np.random.default_rng(6)
    ned = rng.uniform(-60, 60, (200, 3))
    a = g.ned_to_geodetic(ned, 63.44, 10.4, 0.4)
    b = l_ned_to_geodetic(ned[:, 0], ned[:, 1], ned[:, 2], 63.44, 10.4, 0.4)
    assert np.abs(np.array(a[:2]) - np.array(b[:2])).max() < 1e-11
    assert np.abs(a[2] - b[2]).max() < 1e-6
    # and north is north: 1 m north moves the latitude by ~1/111 km, not the longitude
    lat, lon, _ = g.ned_to_geodetic(np.array([1.0, 0.0, 0.0]), 63.44, 10.4, 0.0)
    assert 8.9e-6 < lat - 63.44 < 9.1e-6 and abs(lon - 10.4) < 1e-12


def test_undistortion_round_trip_on_the_scenario_cameras():
    for size in ((640, 360), (1280, 720), (1920, 1080)):
        cam = camera_of(
            scenario_from_dict({"name": "x", "camera": {"width": size[0], "height": size[1]}})
        )
        v, u = np.mgrid[-8 : cam.height + 8 : 7.3, -8 : cam.width + 8 : 6.1]
        rays = g.pixel_rays(cam, u, v)
        assert np.all(np.isfinite(rays))
        pu, pv = g.project(cam, np.eye(3), np.zeros(3), rays)
        assert max(np.abs(pu - u).max(), np.abs(pv - v).max()) < 1e-6

"""The fix's accuracy against Monte-Carlo: perturb each input by its sigma, measure (h_acc: half the radius
holding 95 % of the drawn fixes).

Also the terms beyond the calibration's sigmas: the UAV's own position error, extrapolated
attitude, and a time-alignment error that moves a rotating, travelling camera."""

import dataclasses
import itertools
import math

import cv2
import numpy as np
import pytest

from localizer.calibration import Sigmas
from localizer.camera import Camera
from localizer.ray import pixel_to_offset
from localizer.uncertainty import accuracy, h_acc_from_cov_m

CAM = Camera(1920, 1080, 1664.0, 1664.0, 959.5, 539.5, (-0.12, 0.08, 0.0004, -0.0002, -0.01))
N_WATER = 1.34
R_NADIR = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # cv x→E, y→S, z→D


def camera_R(tilt_from_nadir_deg, heading_deg):
    """Nadir camera tilted towards ``heading_deg`` by ``tilt_from_nadir_deg``."""
    tilt = cv2.Rodrigues(np.array([0.0, math.radians(tilt_from_nadir_deg), 0.0]))[0]  # Down → North
    turn = cv2.Rodrigues(np.array([0.0, 0.0, math.radians(heading_deg)]))[0]
    return turn @ tilt @ R_NADIR


def monte_carlo_spread(R, u, v, h, d, sigmas, n=3000, seed=1):
    """Half the radius holding 95 % of fixes from inputs drawn with the sigmas (pixel, tilt, heading, height,
    depth) about the undisturbed fix (what h_acc claims), and their mean's offset from it (m)."""
    rng = np.random.default_rng(seed)
    tilt, yaw = math.radians(sigmas.tilt_deg), math.radians(sigmas.yaw_deg)
    rvec = rng.normal(0.0, 1.0, (n, 3)) * [tilt, tilt, yaw]  # about North, East, Down
    Rs = np.stack([cv2.Rodrigues(r)[0] @ R for r in rvec])
    uu = u + rng.normal(0.0, sigmas.pixel_px, n)
    vv = v + rng.normal(0.0, sigmas.pixel_px, n)
    hh = h + rng.normal(0.0, sigmas.height_m, n)
    dd = d + rng.normal(0.0, sigmas.depth_m, n)
    true, _ = pixel_to_offset(CAM, R, u, v, h, d, N_WATER)
    off, reaches = pixel_to_offset(CAM, Rs, uu, vv, hh, dd, N_WATER)
    assert np.all(reaches)
    err = off - true
    radius = np.hypot(err[:, 0], err[:, 1])
    return float(np.quantile(radius, 0.95)) / 2.0, math.sqrt(np.sum(np.mean(err, axis=0) ** 2))


SCENES = {
    "nadir, centre": (camera_R(0, 0), CAM.cx, CAM.cy, 30.0, 2.0),
    "nadir, corner": (camera_R(0, 0), 40.0, 1040.0, 60.0, 1.0),
    "35° oblique": (camera_R(35, 70), 1500.0, 300.0, 25.0, 3.0),
    "45° oblique, far corner": (camera_R(45, -150), 1800.0, 100.0, 15.0, 4.0),
}
ONLY = {  # each input alone, at a size that makes it dominate
    "pixel_px": 8.0,
    "tilt_deg": 1.0,
    "yaw_deg": 3.0,
    "height_m": 1.0,
    "depth_m": 0.3,
}


@pytest.mark.parametrize("scene", sorted(SCENES))
def test_h_acc_matches_monte_carlo(scene):
    R, u, v, h, d = SCENES[scene]
    sig = Sigmas()
    h_acc = accuracy(CAM, R, u, v, h, d, N_WATER, sig)[0]
    half_r95, bias = monte_carlo_spread(R, u, v, h, d, sig)
    assert float(h_acc) == pytest.approx(half_r95, rel=0.15)
    assert bias < 0.2 * half_r95  # the linearization is fair: the spread is centred on the fix


@pytest.mark.parametrize("name", sorted(ONLY))
def test_each_input_enters_with_its_own_sigma(name):
    R, u, v, h, d = SCENES["35° oblique"]
    zero = dict.fromkeys(ONLY, 0.0)
    sig = dataclasses.replace(Sigmas(), **{**zero, name: ONLY[name]})
    h_acc = accuracy(CAM, R, u, v, h, d, N_WATER, sig)[0]
    half_r95, _ = monte_carlo_spread(R, u, v, h, d, sig, seed=2)
    assert half_r95 > 0.01
    assert float(h_acc) == pytest.approx(half_r95, rel=0.15)


def test_h_acc_grows_off_nadir_and_with_height():
    sig = Sigmas()
    tilts = [0, 10, 20, 30, 40, 50]
    by_tilt = [
        float(accuracy(CAM, camera_R(t, 30), CAM.cx, CAM.cy, 30.0, 2.0, N_WATER, sig)[0])
        for t in tilts
    ]
    assert all(b > a for a, b in itertools.pairwise(by_tilt)), by_tilt
    heights = [5.0, 10.0, 20.0, 40.0, 80.0]
    by_h = [
        float(accuracy(CAM, camera_R(20, 0), 300.0, 700.0, h, 2.0, N_WATER, sig)[0])
        for h in heights
    ]
    assert all(b > a for a, b in itertools.pairwise(by_h)), by_h


def test_uav_position_accuracy_adds_in_quadrature_and_vertical():
    """The UAV position's sigma (a receiver's DRMS) adds half its square to each axis; h_acc is the covariance's."""
    R, u, v, h, d = SCENES["35° oblique"]
    base = accuracy(CAM, R, u, v, h, d, N_WATER, Sigmas(depth_m=0.1))[2]
    more, v_acc, cov = accuracy(
        CAM, R, u, v, h, d, N_WATER, Sigmas(depth_m=0.1, surface_amsl_m=0.2), sigma_uav_m=1.5
    )
    np.testing.assert_allclose(cov - base, np.eye(2) * 1.5**2 / 2.0, atol=1e-12)
    assert float(v_acc) == pytest.approx(math.sqrt(0.1**2 + 0.2**2))
    assert float(more) == pytest.approx(float(h_acc_from_cov_m(cov)))


def test_extrapolated_attitude_adds_to_tilt_and_heading():
    """Extra tilt and heading sigmas from extrapolation act like larger calibration sigmas."""
    R, u, v, h, d = SCENES["35° oblique"]
    extra_tilt, extra_yaw = math.radians(0.4), math.radians(0.9)
    with_extra = accuracy(
        CAM, R, u, v, h, d, N_WATER, Sigmas(), sigma_tilt_rad=extra_tilt, sigma_yaw_rad=extra_yaw
    )[0]
    wider = Sigmas(tilt_deg=math.hypot(0.5, 0.4), yaw_deg=math.hypot(1.5, 0.9))
    assert float(with_extra) == pytest.approx(
        float(accuracy(CAM, R, u, v, h, d, N_WATER, wider)[0])
    )


@pytest.mark.parametrize("target", [None, (1.3, -0.9), (-0.7, 0.4)])
def test_time_alignment_error_against_monte_carlo(target):
    """A camera turning at ω and travelling at v, matched to telemetry δt ~ N(0, σ_t) off: the fix moves by
    the rotation ω·δt of the ray, v_h·δt, and the height change −v_d·δt. Checked by drawing δt. With the UUV's
    own velocity given (``target``), the fix is scored where the UUV is at the frame's stamp: its motion over δt
    comes off the camera's (one near the camera's horizontal velocity, one against it)."""
    R, u, v, h, d = SCENES["35° oblique"]
    omega = np.array([0.05, -0.12, 0.3])  # rad/s in NED
    vel = np.array([1.5, -0.8, 0.6])  # m/s
    quiet = Sigmas(pixel_px=0.0, tilt_deg=0.0, yaw_deg=0.0, height_m=0.0, depth_m=0.0, time_s=0.05)
    h_acc, _, cov = accuracy(
        CAM,
        R,
        u,
        v,
        h,
        d,
        N_WATER,
        quiet,
        omega_ned=omega,
        velocity_ned_mps=vel,
        target_velocity_ne_mps=target,
    )
    rng = np.random.default_rng(5)
    dt = rng.normal(0.0, quiet.time_s, 4000)
    Rs = np.stack([cv2.Rodrigues(omega * x)[0] @ R for x in dt])
    true, _ = pixel_to_offset(CAM, R, u, v, h, d, N_WATER)
    off, _ = pixel_to_offset(
        CAM, Rs, np.full(len(dt), u), np.full(len(dt), v), h - vel[2] * dt, d, N_WATER
    )
    uuv = np.zeros(2) if target is None else np.asarray(target)
    err = off + (vel[:2] - uuv) * dt[:, None] - true
    radius = np.hypot(err[:, 0], err[:, 1])
    assert float(h_acc) == pytest.approx(np.quantile(radius, 0.95) / 2.0, rel=0.05)
    assert cov[0, 1] == pytest.approx(np.mean(err[:, 0] * err[:, 1]), rel=0.15, abs=1e-5)


def test_batched_accuracy():
    R, u, v, h, d = SCENES["35° oblique"]
    Rs = np.stack([R, camera_R(0, 0)])
    h_acc, v_acc, cov = accuracy(
        CAM, Rs, [u, CAM.cx], [v, CAM.cy], [h, 30.0], [d, 2.0], N_WATER, Sigmas()
    )
    assert cov.shape == (2, 2, 2)
    assert h_acc.shape == v_acc.shape == (2,)
    assert h_acc[0] == pytest.approx(float(accuracy(CAM, R, u, v, h, d, N_WATER, Sigmas())[0]))


def test_the_trackers_own_pixel_sigma_per_frame_against_monte_carlo():
    """Each frame's pixel 1-sigma (the tracker's) replaces the calibration's: drawn pixel errors of 1 px at one
    frame and 6 px at another, all else exact, give the h_acc claimed for each (half their 95 % radius)."""
    R, u, v, h, d = SCENES["35° oblique"]
    quiet = Sigmas(pixel_px=3.0, tilt_deg=0.0, yaw_deg=0.0, height_m=0.0, depth_m=0.0, time_s=0.0)
    h_acc, _, _ = accuracy(
        CAM, np.stack([R, R]), [u, u], [v, v], h, d, N_WATER, quiet, sigma_pixel_px=[1.0, 6.0]
    )
    for claimed, sigma_px in zip(h_acc, (1.0, 6.0)):
        half_r95, _ = monte_carlo_spread(
            R, u, v, h, d, dataclasses.replace(quiet, pixel_px=sigma_px)
        )
        assert float(claimed) == pytest.approx(half_r95, rel=0.05)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_an_attitude_error_that_comes_with_the_heights_against_monte_carlo(sign):
    # a pose from the bottom's tilt moves with the height's error (reported − true, per metre reading high): the
    # camera turned back by that tilt at each drawn height; one sign takes back part of what the height moved the fix,
    # the other adds to it, and the claim follows either (the height's term alone would be 25-40 % off)
    R, u, v, h, d = SCENES["35° oblique"]
    sig = dataclasses.replace(Sigmas(), **{**dict.fromkeys(ONLY, 0.0), "height_m": 1.0})
    per_m = sign * np.radians([0.4, -0.6, 0.1])  # rad per metre, NED
    rng = np.random.default_rng(4)
    dh = rng.normal(0.0, sig.height_m, 3000)
    Rs = np.stack([cv2.Rodrigues(-per_m * x)[0] @ R for x in dh])
    true, _ = pixel_to_offset(CAM, R, u, v, h, d, N_WATER)
    off, _ = pixel_to_offset(CAM, Rs, u, v, h + dh, d, N_WATER)
    half_r95 = float(np.quantile(np.hypot(*(off - true).T), 0.95)) / 2.0
    h_acc = accuracy(CAM, R, u, v, h, d, N_WATER, sig, rotation_per_height_ned=per_m)[0]
    alone = accuracy(CAM, R, u, v, h, d, N_WATER, sig)[0]
    assert float(h_acc) == pytest.approx(half_r95, rel=0.1)
    assert abs(float(alone) / half_r95 - 1.0) > 0.25

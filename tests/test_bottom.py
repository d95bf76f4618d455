"""The pose biases from the static bottom (localizer.bottom) on floor features made with the simulator's geometry.

The features' pixels come from sim_fixtures.geometry (Fermat's crossing of the surface, cv2.projectPoints) seen
from the true camera; the estimator gets the attitude as a drone with a biased AHRS and a levelling error would
report it (scipy's rotations: reported = exp(error) · true, the convention of truth_errors.csv), and positions off
by a GNSS walk. Nothing of the localizer's geometry makes the data.
"""

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from groundstation.offline.bottom import (
    MIN_TILT_DEG,
    PoseCorrection,
    centred_wander_m,
    held_walk_error_m,
    kept_height_wander_m,
    track_velocity_ne_mps,
)
from localizer import bottom
from localizer.calibration import Sigmas
from localizer.camera import Camera
from localizer.geodesy import ned_to_geodetic
from sim_fixtures.geometry import R_GIMBAL_FROM_CV, SimCamera, matrix_zyx, project, surface_crossing

N_WATER = 1.34
FLOOR_M = 4.0
TILT_DEG = (
    0.30,
    -0.25,
)  # the camera's levelling error, about its own heading's forward and right axes
YAW_DEG = 2.0  # the compass reads high


def _camera() -> SimCamera:
    fx = 320 / np.tan(np.radians(31.0))
    return SimCamera(640, 360, fx, fx, 319.5, 179.5, (-0.12, 0.08, 0.0004, -0.0002, -0.01))


def _session(
    speed_mps: float,
    walk=None,
    seed: int = 3,
    duration_s: float = 12.0,
    rate_hz: float = 4.0,
    yaw_deg=None,
    white_m: float = 0.0,
    tilt_deg=None,
    pixel_noise_px: float = 0.3,
):
    """Floor features seen by a camera 10 m up at 72° down, flying along 60° at ``speed_mps`` (its gimbal's yaw held
    on the course, the airframe's heading swinging ±10° under it); ``walk(t)`` the reported position's slow error
    (N, E), ``white_m`` its white noise per axis; ``yaw_deg(t)`` the compass's error (default :data:`YAW_DEG`),
    ``tilt_deg(t)`` the levelling error (K, 2) (default :data:`TILT_DEG`); ``pixel_noise_px`` the features' pixels'
    white noise (1-sigma in u and v)."""
    rng = np.random.default_rng(seed)
    cam = _camera()
    t = np.arange(0.0, duration_s, 1.0 / rate_hz)
    course = np.radians(60.0)
    drift = 0.3 * np.column_stack([np.sin(0.3 * t), np.cos(0.23 * t)])
    ne = speed_mps * t[:, None] * [np.cos(course), np.sin(course)] + drift
    velocity = speed_mps * np.array([np.cos(course), np.sin(course)]) + 0.3 * np.column_stack(
        [0.3 * np.cos(0.3 * t), -0.23 * np.sin(0.23 * t)]
    )
    height = 10.0 + 0.3 * np.sin(0.1 * t)
    R_true = matrix_zyx(0.0, np.radians(-72.0), np.full(t.shape, course)) @ R_GIMBAL_FROM_CV
    tilt = np.radians(np.broadcast_to(TILT_DEG if tilt_deg is None else tilt_deg(t), (len(t), 2)))
    error = np.column_stack(
        [
            tilt[:, 0] * np.cos(course) - tilt[:, 1] * np.sin(course),
            tilt[:, 0] * np.sin(course) + tilt[:, 1] * np.cos(course),
            np.radians(np.full(t.shape, YAW_DEG) if yaw_deg is None else yaw_deg(t)),
        ]
    )
    R_reported = Rotation.from_rotvec(error).as_matrix() @ R_true
    cam_ned = np.column_stack([ne, -height])
    lo, hi = ne.min(axis=0) - 22.0, ne.max(axis=0) + 22.0
    n = 500
    points = np.column_stack(
        [rng.uniform(lo[0], hi[0], n), rng.uniform(lo[1], hi[1], n), np.full(n, FLOOR_M)]
    )
    frame, feature, us, vs = [], [], [], []
    for k in range(len(t)):
        u, v = project(
            cam,
            R_true[k],
            cam_ned[k],
            surface_crossing(np.broadcast_to(cam_ned[k], points.shape), points, N_WATER),
        )
        seen = np.flatnonzero(np.isfinite(u) & cam.contains(u, v, 4.0))
        frame += [k] * len(seen)
        feature += list(seen)
        us += list(u[seen] + rng.normal(0.0, pixel_noise_px, len(seen)))
        vs += list(v[seen] + rng.normal(0.0, pixel_noise_px, len(seen)))
    _, feature = np.unique(feature, return_inverse=True)
    error_ne = np.zeros_like(ne) if walk is None else walk(t)
    error_ne = error_ne + rng.normal(0.0, white_m, error_ne.shape)
    poses = bottom.FramePoses(
        t, R_reported, ne + error_ne, height, bottom.camera_heading_rad(R_reported), velocity
    )
    obs = bottom.Observations(np.array(frame), feature, np.array(us), np.array(vs))
    lens = Camera(
        width=cam.width,
        height=cam.height,
        fx=cam.fx,
        fy=cam.fy,
        cx=cam.cx,
        cy=cam.cy,
        distortion=cam.distortion,
    )
    return lens, poses, obs, error_ne


def test_moving_drone_recovers_the_biases_and_the_floor():
    lens, poses, obs, _ = _session(speed_mps=1.2)
    est = bottom.estimate(lens, N_WATER, poses, obs, bottom.Priors(walk_rate_m=0.003))
    assert est.estimated and est.tilt_estimated and est.yaw_estimated
    # a wrong sign (±0.5°, ±4°) or a tilt about the wrong axes (0.39° apart) fails these
    assert np.degrees(est.tilt_rad) == pytest.approx(TILT_DEG, abs=0.06)
    assert np.degrees(est.yaw_rad) == pytest.approx(YAW_DEG, abs=0.5)
    assert est.floor_depth_m == pytest.approx(FLOOR_M, abs=0.2)
    assert np.degrees(est.sigma_tilt_rad) < 0.06 and np.degrees(est.sigma_yaw_rad) < 0.5
    assert est.rms_px < 0.5
    # the correction turns the reported attitude back into the true one
    R_true = est.correction(poses.bias_heading_rad) @ poses.R_ned_from_cv
    residual = Rotation.from_matrix(R_true @ np.swapaxes(poses.R_ned_from_cv, 1, 2)).as_rotvec()
    assert np.degrees(np.abs(residual[:, 2])) == pytest.approx(YAW_DEG, abs=0.5)
    # the floor does not tell the height: reported 0.3 m high, the floor's depth takes most of it (about n times) and
    # the tilt the rest, by what the estimate says it moves per metre (measured 0.22° right, 5x its sigma)
    high = bottom.estimate(
        lens,
        N_WATER,
        dataclasses.replace(poses, height_m=poses.height_m + 0.3),
        obs,
        bottom.Priors(walk_rate_m=0.003),
    )
    assert est.floor_depth_m - high.floor_depth_m == pytest.approx(0.3 * N_WATER, rel=0.15)
    moved = np.array([*(high.tilt_rad - est.tilt_rad), high.yaw_rad - est.yaw_rad])
    assert np.degrees(np.abs(moved[1])) > 2 * np.degrees(est.sigma_tilt_rad)
    assert np.degrees(moved) == pytest.approx(np.degrees(0.3 * est.bias_per_height_rad), abs=0.02)
    assert "per metre the camera's height reads high they move tilt" in est.describe()


def test_plain_gnss_walk_is_found_about_its_mean():
    def walk(t):
        return np.column_stack([0.25 * np.sin(t / 5.0) + 0.02 * t, -0.15 * np.cos(t / 4.0)])

    lens, poses, obs, error_ne = _session(speed_mps=1.2, walk=walk)
    est = bottom.estimate(lens, N_WATER, poses, obs, bottom.Priors(walk_rate_m=0.02))
    # true = reported + w: w is minus the reported position's error, about its mean
    expected = -(error_ne - error_ne.mean(axis=0))
    found = est.walk_at(poses.t_s)
    assert np.max(np.abs(found - expected)) < 0.04 < np.max(np.abs(expected))
    assert np.degrees(est.yaw_rad) == pytest.approx(YAW_DEG, abs=0.5)
    # the line says how sure the walk is, and what each fix's h_acc takes for what was applied (at least the AHRS's
    # wander) and for what was not
    sigma_walk = np.max(np.hypot(*est.sigma_walk_ne_m.T))
    assert sigma_walk > 0
    assert (
        f"position walk up to {np.max(np.hypot(*est.walk_ne_m.T)):.2f} m ± {sigma_walk:.3f} m about"
        in est.describe()
    )
    correction = PoseCorrection(est, True, False, "camera")
    said = correction.describe()
    tilt_deg = max(MIN_TILT_DEG, np.degrees(est.sigma_tilt_rad))
    assert f"h_acc takes tilt ± {tilt_deg:.2f}° for them, not [uncertainty]'s" in said
    assert "heading ±" not in said.split("h_acc")[1] and "the camera's height" in said
    # the corrected position's sigma (a DRMS) in h_acc is the GNSS's and the walk's own error together
    frames = SimpleNamespace(t_unix=poses.t_s, sigma_uav_m=np.full(len(poses.t_s), 1.2))
    sigma_walk_m = np.hypot(*est.sigma_walk_at(poses.t_s).T)
    assert correction.sigma_position_m(frames) == pytest.approx(np.hypot(1.2, sigma_walk_m))
    # the heading held at 0 (not applied) while the compass reads 2° high: the walk fitted again takes up part of
    # it, which its own sigma does not hold (measured: its error 0.127/0.057 m against 0.011/0.020); widened by
    # what the free fit's walk moves per radian of heading times the heading's sigma as h_acc takes it (the
    # calibration's 2°) and the tilt's by its own (0.122/0.086 m, the error 1.05/0.66 of it), and then by how far
    # it is from the free fit's walk too
    held = bottom.estimate(
        lens, N_WATER, poses, obs, dataclasses.replace(est.priors, yaw_rad=1e-7, walk_rates_m=())
    )
    error_m = held.walk_at(poses.t_s) - expected
    ratio = np.sqrt(
        np.mean(error_m**2, axis=0) / np.mean(held.sigma_walk_at(poses.t_s) ** 2, axis=0)
    )
    assert np.max(ratio) > 3.0
    calibration = SimpleNamespace(tilt_deg=0.2, yaw_deg=YAW_DEG)
    moves = held_walk_error_m(est, held, calibration, True, False)
    for widened in (held.with_walk_error(moves[:, :3]), held.with_walk_error(moves)):
        sigma_m = widened.sigma_walk_at(poses.t_s)
        assert np.all(np.sqrt(np.mean(error_m**2, axis=0) / np.mean(sigma_m**2, axis=0)) < 1.5)


def test_the_tilts_sigma_is_what_the_residuals_say():
    # the pixels' noise (0.3 px, under the 0.7 px the fit weighs them by) sets the tilt's sigma: the estimate's
    # scatter over draws of the noise and the floor is what it claims (measured over seeds 0-7: 1.19 of its sigma, its
    # right component -0.016° off on average, a model error the fit does not see; a sigma floored at the 0.7 px prior
    # claimed 2.3 times the residuals' and its error came to 0.53 of it)
    z, sigma_deg, yaw_rad = [], {}, {}
    for seed in range(8):
        lens, poses, obs, _ = _session(speed_mps=1.2, seed=seed)
        est = bottom.estimate(lens, N_WATER, poses, obs, bottom.Priors(walk_rate_m=0.003))
        assert est.rms_px == pytest.approx(0.3, abs=0.02)
        sigma_deg[seed] = np.degrees(np.sqrt(np.diagonal(est.cov_bias)[:2]))
        yaw_rad[seed] = est.sigma_yaw_rad
        z.append((np.degrees(est.tilt_rad) - TILT_DEG) / sigma_deg[seed])
    assert 0.7 < np.sqrt(np.mean(np.square(z))) < 1.5
    # twice the noise, twice the tilt's sigma (seed 0's floor, its noise scaled; measured 2.13, 2.04; floored at the
    # 0.7 px prior both claimed the same, 1.07 apart). The heading, which the walk's prior (the velocity's) tells
    # here, keeps what the prior gives it (measured 1.06 apart; scaling the whole covariance, priors too, by the
    # residuals' variance would halve it at 0.3 px as well)
    lens, poses, obs, _ = _session(speed_mps=1.2, seed=0, pixel_noise_px=0.6)
    noisier = bottom.estimate(lens, N_WATER, poses, obs, bottom.Priors(walk_rate_m=0.003))
    ratio = np.degrees(np.sqrt(np.diagonal(noisier.cov_bias)[:2])) / sigma_deg[0]
    assert ratio == pytest.approx([2.0, 2.0], rel=0.15)
    assert noisier.sigma_yaw_rad / yaw_rad[0] < 1.2


def test_hovering_drone_does_not_claim_the_biases():
    lens, poses, obs, _ = _session(speed_mps=0.0)
    est = bottom.estimate(lens, N_WATER, poses, obs, bottom.Priors(walk_rate_m=0.003))
    assert est.slide_share < bottom.MIN_SLIDE_SHARE
    assert not est.estimated
    assert "not observable" in est.describe()


def test_white_position_noise_is_taken_frame_by_frame():
    # 3 cm of white noise on each axis of the reported position (a plain receiver's): 2-second knots cannot follow
    # it; taken as each frame's own offset it leaves the floor and the biases where they are
    lens, poses, obs, _ = _session(speed_mps=1.2, white_m=0.03)
    white = bottom.white_noise_m(poses)
    assert white == pytest.approx(0.03, rel=0.35)  # seen against the reported velocity
    rate = bottom.Priors(walk_rate_m=0.003)
    est = bottom.estimate(lens, N_WATER, poses, obs, dataclasses.replace(rate, white_m=white))
    assert est.floor_depth_m == pytest.approx(FLOOR_M, abs=0.2)
    assert np.degrees(est.tilt_rad) == pytest.approx(TILT_DEG, abs=0.08)
    assert np.degrees(est.yaw_rad) == pytest.approx(YAW_DEG, abs=0.5)
    assert est.rms_px < 0.5
    # without the frame offsets the same tracks misfit: the noise lands in the residuals
    blind = bottom.estimate(lens, N_WATER, poses, obs, rate)
    assert blind.rms_px > est.rms_px + 0.1


def test_parts_that_disagree_widen_the_sigmas(monkeypatch):
    lens, poses, obs, _ = steady = _session(speed_mps=1.2)
    est = bottom.estimate(lens, N_WATER, poses, obs, bottom.Priors(walk_rate_m=0.003), parts=3)
    assert est.parts.shape == (3, 4) and np.all(np.isfinite(est.parts))
    assert np.degrees(est.parts[:, 2]) == pytest.approx([YAW_DEG] * 3, abs=0.5)
    assert np.degrees(est.sigma_yaw_rad) < 0.5 and est.yaw_estimated

    # the compass's error steps by 3° in the last third: the whole's fit alone claims a tight heading; the parts
    # tell otherwise, and the sigma takes their spread
    def stepping(t):
        return np.where(t < 8.0, YAW_DEG, YAW_DEG + 3.0)

    lens, poses, obs, _ = _session(speed_mps=1.2, yaw_deg=stepping)
    whole = bottom.estimate(lens, N_WATER, poses, obs, bottom.Priors(walk_rate_m=0.003))
    split = bottom.estimate(lens, N_WATER, poses, obs, bottom.Priors(walk_rate_m=0.003), parts=3)
    spread = np.std(split.parts[:, 2], ddof=1)
    assert np.degrees(spread) > 1.0
    assert np.degrees(whole.sigma_yaw_rad) < 0.5 * np.degrees(spread)
    assert np.degrees(split.sigma_yaw_rad) > 2.0 * np.degrees(whole.sigma_yaw_rad)
    assert "parts' spread" in split.describe()
    # the step pulls the whole fit's tilt away from every part's (which agree on the truth): the claim covers it
    tilt_error_deg = np.degrees(split.tilt_rad) - TILT_DEG
    assert (
        np.abs(np.degrees(split.parts[:, :2]) - TILT_DEG).max() < 0.3 < np.abs(tilt_error_deg).max()
    )
    sigma_tilt_deg = np.degrees(np.sqrt(np.diagonal(split.cov_bias)[:2]))
    assert np.all(np.abs(tilt_error_deg) < 2.0 * sigma_tilt_deg), (tilt_error_deg, sigma_tilt_deg)

    # the whole recording's fit holds all the parts' data: its error beyond its own sigma is that of the parts'
    # mean, not one part's. Parts drawn about a truth with a scatter the fit's sigma does not hold (0.2° per part),
    # many times: what the parts add to the sigmas has the RMS of their mean's error (0.2°/sqrt(3)), one part's
    # scatter (0.2°) would claim sqrt(3) times too much
    lens, poses, obs, _ = steady
    rng = np.random.default_rng(5)
    truth, scatter = np.array([0.005, -0.004, 0.035, 4.0]), np.array([*np.radians([0.2] * 3), 0.3])
    drawn = []
    monkeypatch.setattr(
        bottom,
        "_part_values",
        lambda *_: drawn.append(truth + rng.normal(0.0, scatter)) or drawn[-1],
    )
    added, mean_error = [], []
    for _ in range(1500):
        split = bottom.with_parts(est, lens, N_WATER, poses, obs, 3)
        added.append(np.sqrt(np.diagonal(split.cov_bias - est.cov_bias)))
        mean_error.append(np.mean(drawn[-3:], axis=0)[:3] - truth[:3])
    ratio = np.sqrt(np.mean(np.square(added), axis=0) / np.mean(np.square(mean_error), axis=0))
    # and a few per cent more: on the draws whose three parts agree by chance (a standard error of 2 degrees of
    # freedom), the whole fit is more than WHOLE_APART of the sigmas from their mean and adds that distance (2-5 % of
    # the draws with the fit's own sigma as the residuals say it; measured 1.09/1.06/1.10)
    assert np.all((ratio > 0.9) & (ratio < 1.2)), ratio


def test_the_walk_rate_is_the_one_the_recording_likes_best():
    # the walk's prior about what the velocity says, its rate chosen per recording by the marginal likelihood: an
    # exact velocity wants the tightest rate on offer, one whose integral walks at 0.03 m/√s (white 0.06 m/s held
    # over each 0.25 s frame) about that (a fixed rate, or a floor under it, is right for one of them only)
    lens, poses, obs, _ = _session(speed_mps=1.2)
    noisy_velocity = poses.velocity_ne_mps + np.random.default_rng(8).normal(
        0.0, 0.06, poses.velocity_ne_mps.shape
    )
    noisy = dataclasses.replace(poses, velocity_ne_mps=noisy_velocity)
    rates = tuple(np.geomspace(0.001, 0.3, 12))
    priors = bottom.Priors(walk_rate_m=0.05, walk_rates_m=rates)
    exact = bottom.estimate(lens, N_WATER, poses, obs, priors)
    assert exact.priors.walk_rate_m == rates[0] and exact.priors.walk_rates_m == ()
    found = bottom.estimate(lens, N_WATER, noisy, obs, priors)
    assert found.priors.walk_rate_m == pytest.approx(0.03, rel=0.5)
    evidence = found.walk_rate_evidence
    assert np.array_equal(evidence[:, 0], rates)
    assert found.priors.walk_rate_m == evidence[np.argmax(evidence[:, 1]), 0]
    # the positions are exact (no walk): what the noisy velocity left in the walk is within its claimed sigmas
    assert np.sqrt(np.mean((found.walk_ne_m / found.sigma_walk_ne_m) ** 2)) < 2.0
    assert np.degrees(found.yaw_rad) == pytest.approx(YAW_DEG, abs=0.5)


def test_each_frames_white_noise_is_what_the_velocity_does_not_explain():
    _, poses, _, error_ne = _session(speed_mps=1.2, white_m=0.03)
    knots = bottom.knot_times(poses.t_s, 2.0)
    _, remainder = bottom.velocity_drift(poses.t_s, poses.velocity_ne_mps, poses.camera_ne_m, knots)
    # true = reported + walk + remainder: the remainder is minus the white error (its mean aside)
    expected = -(error_ne - error_ne.mean(axis=0))
    assert np.sqrt(np.mean((remainder - expected) ** 2)) < 0.01 < np.sqrt(np.mean(expected**2))
    # the fit's frames are some of the located ones: the walk follows the velocity's curve fitted on those; about that
    # curve, walk + remainder is minus the error on every frame, where a curve fitted again to all of them differs
    # from it by the white noise's share in the knots
    curve, _ = bottom.velocity_drift(
        poses.t_s[::3], poses.velocity_ne_mps[::3], poses.camera_ne_m[::3], knots
    )
    walk = bottom._interp_knots(knots, curve, poses.t_s)
    _, about = bottom.velocity_drift(
        poses.t_s, poses.velocity_ne_mps, poses.camera_ne_m, knots, curve
    )

    def rms_m(total):
        return np.sqrt(np.mean((total - total.mean(axis=0) - expected) ** 2))

    assert rms_m(walk + about) < 0.001 < rms_m(walk + remainder)


def test_a_plain_receivers_walk_told_by_the_velocity_is_where_the_fit_starts():
    # a plain receiver walks decimetres in seconds (0.6 m over 12 s here) while its velocity (the EKF's, from the
    # Doppler) is exact: the fit starts from the walk the velocity tells (a robust fit started from no walk, every
    # step of it many prior sigmas off, stopped short of it on the generated survey line), about its mean
    def walk(t):
        return np.column_stack([0.05 * t, -0.3 * np.sin(t / 6.0)])

    lens, poses, obs, error_ne = _session(speed_mps=1.2, walk=walk)
    problem = bottom._Problem(lens, N_WATER, poses, obs, bottom.Priors(walk_rate_m=0.003))
    _, start, _, _ = problem.unpack(problem.start())
    expected = -(error_ne - error_ne.mean(axis=0))
    found = bottom._interp_knots(problem.knots, start, poses.t_s)
    # its mean is held over the knots, the expected one's over the frames
    found = found - found.mean(axis=0)
    assert np.max(np.abs(expected)) > 0.25
    assert np.max(np.abs(found - expected)) < 0.005
    assert problem.depth0 == pytest.approx(FLOOR_M, rel=0.15)


def test_a_wandering_tilt_is_followed_within_its_prior():
    # the levelling error's forward tilt wanders 0.08° about its bias over the 12 s (an AHRS's slow wander): a
    # constant tilt leaves it in the floor's residuals; the wander's Gauss-Markov prior (1-sigma 0.1°, 60 s) lets the
    # tilt follow it, its mean still the bias. (A wander of the right tilt that grows through the recording is
    # nearly what a heading error does to the floor sliding through the image; the prior holds it.)
    def wandering(t):
        return np.column_stack([TILT_DEG[0] + 0.08 * np.sin(t / 4.0), np.full(len(t), TILT_DEG[1])])

    lens, poses, obs, _ = _session(speed_mps=1.2, tilt_deg=wandering)
    constant = bottom.Priors(walk_rate_m=0.003)
    wander = dataclasses.replace(constant, tilt_wander_rad=np.radians(0.1), tilt_wander_s=60.0)
    # the wander's Jacobian (the globals' tilt columns, forward-differenced, shared by its knots) against the
    # residuals' own central differences
    problem = bottom._Problem(lens, N_WATER, poses, obs, wander)
    x = problem.start()
    x[problem.first_wander : problem.first_feature] = np.radians(0.05)
    jac = problem.jacobian(x)
    for col in (problem.first_wander, problem.first_feature - 1):
        step = np.zeros_like(x)
        step[col] = 1e-6
        diff = (problem.residuals(x + step) - problem.residuals(x - step)) / 2e-6
        assert jac[:, col].toarray().ravel() == pytest.approx(diff, rel=1e-2, abs=1e-3)
    fixed = bottom.estimate(lens, N_WATER, poses, obs, constant)
    est = bottom.estimate(lens, N_WATER, poses, obs, wander)
    true = wandering(poses.t_s)
    err_fixed = np.degrees(fixed.tilt_at(poses.t_s)) - true
    err = np.degrees(est.tilt_at(poses.t_s)) - true
    assert np.sqrt(np.mean(err**2)) < 0.7 * np.sqrt(np.mean(err_fixed**2))
    assert np.degrees(est.tilt_rad) == pytest.approx(np.mean(true, axis=0), abs=0.03)
    assert np.degrees(est.yaw_rad) == pytest.approx(YAW_DEG, abs=0.5)
    assert est.rms_px < fixed.rms_px


def test_the_walk_sigma_takes_up_what_the_heights_wander_moves_it():
    # the reported heights wander 0.1 m back and forth over 20 s (a barometer's prop wash and gusts): the floor does
    # not tell the height, and the walk takes up part of its wander (measured: its error about its mean 0.97/1.49 of
    # its sigma north/east when the heights are taken as constant); given the wander's prior (the platform's
    # [uncertainty] baro_wander_m, baro_wander_s) the walk's sigma takes that part too, the fit itself the same
    lens, poses, obs, _ = _session(speed_mps=1.2)
    wander_m = 0.1 * np.sin(2 * np.pi * poses.t_s / 20.0 + 1.0)
    moved = dataclasses.replace(poses, height_m=poses.height_m + wander_m)
    priors = bottom.Priors(walk_rate_m=0.003, height_wander_m=0.1, height_wander_s=30.0)
    est = bottom.estimate(lens, N_WATER, moved, obs, priors)
    error_m = est.walk_at(poses.t_s)  # the positions are exact: the walk found is its error
    sigma_m = est.sigma_walk_at(poses.t_s)
    assert np.max(np.abs(error_m)) > 0.01  # the wander moved it
    assert np.all(np.sqrt(np.mean(error_m**2, axis=0) / np.mean(sigma_m**2, axis=0)) < 1.0)
    # its mean is a common error: the floor's depth and the tilt take it, not the walk (whose mean is held at 0)
    cov = bottom.height_wander_cov_m2(priors, est.knot_t_s)
    assert cov.sum(axis=0) == pytest.approx(np.zeros(len(est.knot_t_s)), abs=1e-12)
    assert np.sqrt(np.mean(np.diagonal(cov))) < 0.1


def test_the_uuvs_velocity_for_the_time_term_is_its_tracks():
    # a UUV turning on a 12 m circle at 1.5 m/s, located at 30 Hz with 3 cm of scatter per axis: the velocity per fix is
    # the track's (the derivative of its path, computed here on its own) to a few centimetres a second; a fix with
    # fewer than 3 neighbours within the window says 0 (the time term then takes the camera's whole motion)
    rng = np.random.default_rng(2)
    t = 1.7e9 + np.arange(0.0, 20.0, 1 / 30)
    angle = 1.5 / 12.0 * (t - t[0])
    ne = 12.0 * np.column_stack([np.sin(angle), 1.0 - np.cos(angle)])
    truth = 1.5 * np.column_stack([np.cos(angle), np.sin(angle)])
    lat, lon, _ = ned_to_geodetic(*(ne + rng.normal(0.0, 0.03, ne.shape)).T, 0.0, 43.5, 16.4, 0.0)
    status = np.full(len(t), "ok", dtype=object)
    status[300:400] = "lost"
    status[340] = "ok"  # alone among lost frames
    fixes = SimpleNamespace(t_unix=t, status=status, lat=np.asarray(lat), lon=np.asarray(lon))
    got = track_velocity_ne_mps(fixes)
    told = (status == "ok") & (np.arange(len(t)) != 340)
    assert np.sqrt(np.mean(np.sum((got[told] - truth[told]) ** 2, axis=1))) < 0.05
    assert np.all(got[~told] == 0.0)


def _gnss_session(alt_m, v_acc_m, t_s):
    """What :func:`kept_height_wander_m` takes of a session: the calibration's sigmas and GNSS altitudes (GPS_RAW_INT's
    columns h_acc, geoid, fix type, alt, v_acc, HDOP, VDOP) at ``t_s``, on the station's clock."""
    values = np.zeros((len(t_s), 7))
    values[:, 2], values[:, 3], values[:, 4] = 6, alt_m, v_acc_m
    gnss = SimpleNamespace(times=np.asarray(t_s, float), values=values)
    telemetry = SimpleNamespace(gnss=gnss, uav_time=lambda t: np.asarray(t, float))
    return SimpleNamespace(calibration=SimpleNamespace(sigmas=Sigmas()), telemetry=telemetry)


def test_the_heights_wander_the_walk_takes_is_what_they_move_against_the_gnss():
    # the barometer wanders 0.15 m (the default [uncertainty] baro_wander_m) over 30 s; heights that move with an RTK
    # altitude exactly (its 2 cm) keep none of it: the walk's prior is then the receiver's slow error's change,
    # centimetres; heights that wander against the GNSS altitudes by a 0.05 m sine get a prior whose change over the
    # knots is at least what they moved, binned as the walk's knots (computed here on its own); a plain receiver's
    # metres, or no GNSS altitude, leave the barometer's
    t = np.arange(0.0, 16.0, 0.2)
    poses = bottom.FramePoses(
        t, np.zeros((len(t), 3, 3)), np.zeros((len(t), 2)), 20.0 + np.zeros(len(t))
    )
    t_gnss = np.arange(0.0, 16.0, 0.1)
    baro = 0.15 * np.sin(2 * np.pi * t / 30.0)
    followed = kept_height_wander_m(
        _gnss_session(np.interp(t_gnss, t, baro), 0.02, t_gnss),
        dataclasses.replace(poses, height_m=20.0 + baro),
    )
    assert followed < 0.03
    moving = 0.05 * np.sin(2 * np.pi * t / 8.0)
    prior = kept_height_wander_m(
        _gnss_session(np.zeros(len(t_gnss)), 0.02, t_gnss),
        dataclasses.replace(poses, height_m=20.0 + moving),
    )
    knots = bottom.knot_times(t, 2.0)
    span = np.clip(np.searchsorted(knots, t, side="right") - 1, 0, len(knots) - 2)
    means = np.bincount(span, weights=moving) / np.bincount(span)
    assert centred_wander_m(prior, 30.0, knots) >= np.sqrt(np.mean((means - means.mean()) ** 2))
    assert followed < prior < Sigmas().baro_wander_m
    plain = _gnss_session(np.zeros(len(t_gnss)) + 1.5 * np.sin(t_gnss / 5.0), 3.0, t_gnss)
    assert kept_height_wander_m(plain, poses) == Sigmas().baro_wander_m
    none = _gnss_session(np.zeros(0), 0.02, np.zeros(0))
    assert kept_height_wander_m(none, poses) == Sigmas().baro_wander_m

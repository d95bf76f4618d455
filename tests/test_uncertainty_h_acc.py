"""h_acc is half the radius of the 95 % circle of the claimed 2-D normal error: checked against independent
computations (the 2-D normal's share within a circle integrated over directions, scipy's quantiles, Monte Carlo),
not the table it is interpolated from."""

import math

import numpy as np
import pytest
from scipy.stats import chi2, norm

from localizer.uncertainty import h_acc_from_cov_m, isotropic_sigma_m
from localizer.uuv_track import fix_covariance_m2

_ANGLES = np.linspace(0.0, 2.0 * np.pi, 4096, endpoint=False)


def share_within(radius_m, cov_m2) -> float:
    """P(|x| < radius_m) for x ~ N(0, cov_m2): in polar coordinates about the centre, along each direction θ the
    radius of a standard normal drawn in the covariance's axes is Rayleigh, so the share is the mean over θ of
    1 − exp(−R² / (2 (a cos² θ + b sin² θ))) with a, b the variances along the axes."""
    a, b = np.linalg.eigvalsh(cov_m2)
    along = a * np.cos(_ANGLES) ** 2 + b * np.sin(_ANGLES) ** 2
    return float(np.mean(1.0 - np.exp(-(radius_m**2) / (2.0 * along))))


def rotated(major_sigma_m, minor_sigma_m, angle_rad) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    turn = np.array([[c, -s], [s, c]])
    return turn @ np.diag([major_sigma_m**2, minor_sigma_m**2]) @ turn.T


def test_round_and_one_axis_against_scipy():
    """A round error of σ per axis: 2·h_acc = sqrt(χ²₂(0.95))·σ; all of it along one axis: 1.96·σ."""
    sigma = 0.37
    assert 2 * float(h_acc_from_cov_m(np.eye(2) * sigma**2)) == pytest.approx(
        math.sqrt(chi2.ppf(0.95, 2)) * sigma, rel=1e-4
    )
    assert 2 * float(h_acc_from_cov_m(rotated(sigma, 0.0, 0.7))) == pytest.approx(
        norm.ppf(0.975) * sigma, rel=1e-4
    )


def test_twice_h_acc_holds_95_percent_of_any_shape():
    """Random covariances (every axis ratio, any orientation, correlated north and east, scales over three
    decades): 2·h_acc holds 95 % of their normal error, by the integral over directions."""
    rng = np.random.default_rng(28)
    for _ in range(200):
        major = 10 ** rng.uniform(-2, 1)
        cov = rotated(major, major * rng.uniform(0, 1), rng.uniform(0, np.pi))
        assert share_within(2 * float(h_acc_from_cov_m(cov)), cov) == pytest.approx(0.95, abs=3e-4)


def test_batched_and_monte_carlo():
    """A batch gives each covariance its own h_acc; drawn errors of each fall within 2·h_acc 95 % of the time."""
    covs = np.stack([rotated(0.3, 0.3, 0.0), rotated(1.2, 0.4, 0.5), rotated(0.05, 0.001, 2.0)])
    h_acc = h_acc_from_cov_m(covs)
    assert h_acc.shape == (3,)
    rng = np.random.default_rng(5)
    for cov, h in zip(covs, h_acc):
        err = rng.multivariate_normal([0.0, 0.0], cov, 200_000)
        assert np.mean(np.hypot(*err.T) <= 2 * h) == pytest.approx(0.95, abs=0.002)


def test_isotropic_sigma_and_a_fix_without_its_covariance():
    """A claim of h_acc alone (another tool's positions.csv) is the round error whose h_acc it is."""
    sigma = float(isotropic_sigma_m(0.8))
    assert share_within(1.6, np.eye(2) * sigma**2) == pytest.approx(0.95, abs=3e-4)
    nan = float("nan")
    C = fix_covariance_m2(nan, nan, nan, 0.8)
    np.testing.assert_allclose(C, np.eye(2) * sigma**2)
    assert float(h_acc_from_cov_m(C)) == pytest.approx(0.8)


def test_degenerate_covariances():
    assert float(h_acc_from_cov_m(np.zeros((2, 2)))) == 0.0
    assert math.isnan(float(h_acc_from_cov_m(np.full((2, 2), np.nan))))

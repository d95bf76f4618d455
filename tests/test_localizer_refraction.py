"""The surface crossing of the refracted ray to a submerged point (Newton's method) against a bisection kept
here as the independent reference, over a grid of geometries up to grazing angles."""

import math

import numpy as np
import pytest

from localizer.refraction import offset_from_ray, ray_to_target, surface_distance

N_WATER = 1.34


def bisection(rho, h, d, n_water, iterations=64):
    """The crossing ``x`` of ``x + d·tan θ_w(x) = rho`` by bisection between the straight ray's crossing and
    ``rho`` (the localizer's method before Newton's)."""
    rho, h, d = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (rho, h, d)))
    lo, hi = rho * h / (h + d), rho.copy()
    for _ in range(iterations):
        x = 0.5 * (lo + hi)
        sin_w = x / np.hypot(x, h) / n_water
        f = x + d * sin_w / np.sqrt(1.0 - sin_w * sin_w) - rho
        lo, hi = np.where(f < 0, x, lo), np.where(f < 0, hi, x)
    return 0.5 * (lo + hi)


def grid():
    """(rho, h, d) over 0-300 m away, 0.05-150 m high, 0-30 m deep: off-nadir angles up to 89.99°."""
    rho = np.concatenate([[0.0, 1e-6, 0.01], np.geomspace(0.1, 300.0, 40)])
    h = np.geomspace(0.05, 150.0, 25)
    d = np.concatenate([[1e-4], np.geomspace(0.01, 30.0, 20)])
    return np.meshgrid(rho, h, d, indexing="ij")


@pytest.mark.parametrize("n_water", [1.33, N_WATER, 1.5])  # water, fresh to salt, and glass
def test_newton_matches_the_bisection_over_a_grid_to_grazing_angles(n_water):
    rho, h, d = grid()
    assert np.degrees(np.arctan2(rho, h)).max() > 89.99  # grazing rays are in the grid
    x = surface_distance(rho, h, d, n_water)
    np.testing.assert_allclose(x, bisection(rho, h, d, n_water), rtol=0, atol=1e-9)
    assert np.all((x >= rho * h / (h + d) - 1e-12) & (x <= rho + 1e-12))


def test_scalars_take_the_same_steps_as_arrays():
    rho, h, d = (a.ravel()[::7] for a in grid())
    x = surface_distance(rho, h, d, N_WATER)
    one = [
        surface_distance(float(r), float(hh), float(dd), N_WATER) for r, hh, dd in zip(rho, h, d)
    ]
    assert all(isinstance(v, float) for v in one)
    np.testing.assert_allclose(one, x, rtol=0, atol=1e-12)


def test_the_crossing_ends_where_the_ray_reaches_the_point():
    """Traced forward from the crossing by :func:`offset_from_ray` (Snell's law applied the other way), the ray
    lands on the point: a check independent of both solvers."""
    rng = np.random.default_rng(5)
    ne = rng.uniform(-80.0, 80.0, (500, 2))
    h, d = rng.uniform(0.3, 120.0, 500), rng.uniform(0.0, 15.0, 500)
    ray = ray_to_target(ne, h, d, N_WATER)
    landed, reaches = offset_from_ray(ray, h, d, N_WATER)
    assert reaches.all()
    np.testing.assert_allclose(landed, ne, rtol=0, atol=1e-9)


def test_above_the_water_and_without_refraction_the_ray_is_straight():
    rho, h = np.array([0.0, 3.0, 40.0]), np.array([10.0, 2.0, 0.5])
    for d in (0.0, -0.3):
        np.testing.assert_allclose(
            surface_distance(rho, h, d, N_WATER), rho * h / (h + d), rtol=0, atol=1e-15
        )
        assert surface_distance(40.0, 0.5, d, N_WATER) == pytest.approx(40.0 * 0.5 / (0.5 + d))
    np.testing.assert_allclose(surface_distance(rho, h, 2.0, None), rho * h / (h + 2.0))


def test_nan_in_nan_out():
    x = surface_distance(np.array([math.nan, 5.0]), 10.0, 1.0, N_WATER)
    assert math.isnan(x[0]) and x[1] == pytest.approx(float(bisection(5.0, 10.0, 1.0, N_WATER)))
    assert math.isnan(surface_distance(math.nan, 10.0, 1.0, N_WATER))

"""Wind waves on the water surface: a wind-sea spectrum realised as a sum of random-phase linear waves.

The spectrum is Elfouhaily et al.'s unified directional spectrum ("A unified directional spectrum for
long and short wind-driven waves", JGR 1997): a fetch-limited JONSWAP peak (wave age from the fetch)
and a gravity-capillary tail around k_m = 370 rad/m (λ 1.7 cm), as a curvature (saturation)
spectrum B(k); the elevation spectrum is S(k) = B(k)/k³ and the slope spectrum k²·S(k) = B(k)/k, so
the mean-square slope is ∫ B d(ln k). That total, from a quarter of the peak's wavenumber to 10·k_m,
is scaled to Cox & Munk's clean-surface law, mss = 0.003 + 0.00512·U with U the wind at 12.5 m (from
the 10 m wind by the log profile of the spectrum's own roughness length); the scale is 0.74–1.14 for
2–10 m/s and 1–10 km of fetch, Elfouhaily's own calibration against Cox & Munk.

The realisation keeps only waves the renderer can resolve: wavenumbers up to 2π/λ_min, λ_min a few
pixels of the image at the surface (``[waves] shortest_wavelength_m``). Nothing is rescaled: the
resolved mean-square slope is Cox & Munk's total minus the unresolved part's (42–79 % of it resolved
in the waves scenarios, λ_min 8–18 cm; :attr:`WaveField.resolved_mss`). The unresolved slopes widen the sun's glint
instead (:attr:`WaveField.unresolved_mss`). Directions follow a cos^2s((θ − θ_wind)/2) spreading
whose s gives Cox & Munk's ratio of crosswind to upwind slope variance (at most 1).

Each of ``components`` log-spaced wavenumber bands becomes one wave: a wavenumber drawn in the band,
a direction drawn from the spreading (stratified), a uniform random phase, and the amplitude that
gives the band's slope variance: a²·k²/2 = ∫_band B d(ln k). Frequencies by the dispersion of
gravity-capillary waves over the seafloor's depth h: ω² = g·k·(1 + (k/k_m)²)·tanh(k·h).

Frames: NED north/east metres, time in seconds since the first frame; η is the height of the
surface above its mean (up positive), so the surface is the set down = −η(north, east, t).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property
from itertools import pairwise

import cv2
import numpy as np
from scipy.special import j1

from .scenario import Scenario
from .texture import sample

G_MPS2 = 9.81
KAPPA = 0.41  # von Kármán's constant
K_M = 370.0  # rad/m: the gravity-capillary waves' slowest wavenumber (Elfouhaily's k_m)
C_M = 0.23  # m/s: their phase speed there
K_TOTAL_MAX = 10 * K_M  # Cox & Munk's total counts slopes up to here (the spectrum is ~0 beyond)
RESOLVE_PX = 4.0  # the shortest wave resolved, in the floor's pixels at the surface, straight down
# the floor's surface grids: points per shortest wavelength (interpolated bicubically)
GRID_PER_WAVELENGTH = 5
MAX_GRID_POINTS = 1_500_000  # ... and at most this many points a grid
MARGIN = 2  # points a coarser octave's grid reaches past the finer one's on every side
CHUNK = 1 << 21  # (points × waves) evaluated at once by the exact sums
SEED_STREAM = 505  # the realisation's random numbers: np.random.default_rng([seed, SEED_STREAM])


def cox_munk_mss(u12_5_mps) -> float:
    """Cox & Munk's (1954) clean-surface mean-square slope for the wind ``u12_5_mps`` at 12.5 m."""
    return 0.003 + 0.00512 * u12_5_mps


def cox_munk_crosswind_ratio(u12_5_mps) -> float:
    """Cox & Munk's crosswind over upwind slope variance, (0.003 + 0.00192·U) / (0.00316·U), at most 1."""
    return min(1.0, (0.003 + 0.00192 * u12_5_mps) / (0.00316 * u12_5_mps))


def spreading_s(ratio: float) -> float:
    """The s of a cos^2s(θ/2) spreading whose crosswind/upwind slope variance is ``ratio`` (≤ 1).

    Its second Fourier coefficient is A2 = s(s − 1)/((s + 1)(s + 2)); the slope variances along and
    across the mean direction are (1 ± A2)/2 of the total, so A2 = (1 − r)/(1 + r); solved for s ≥ 1.
    """
    a2 = (1.0 - ratio) / (1.0 + ratio)
    b = 1.0 + 3.0 * a2
    return (b + np.sqrt(b * b + 8.0 * a2 * (1.0 - a2))) / (2.0 * (1.0 - a2))


def phase_speed(k, depth_m=np.inf):
    """Phase speed (m/s) of gravity-capillary waves of wavenumber ``k`` (rad/m) over ``depth_m``."""
    return np.sqrt(G_MPS2 / k * (1.0 + (k / K_M) ** 2) * np.tanh(k * depth_m))


@dataclass(frozen=True)
class Spectrum:
    """Elfouhaily's omnidirectional spectrum for a 10 m wind and a fetch, scaled to Cox & Munk."""

    u10_mps: float
    fetch_m: float

    @property
    def inverse_wave_age(self) -> float:
        """Ω = U10 / c_p from the fetch (0.84 fully developed)."""
        x = G_MPS2 * self.fetch_m / self.u10_mps**2
        return max(0.84, 0.84 * np.tanh((x / 2.2e4) ** 0.4) ** -0.75)

    @property
    def k_peak(self) -> float:
        """Wavenumber (rad/m) of the spectral peak."""
        return G_MPS2 * self.inverse_wave_age**2 / self.u10_mps**2

    @property
    def roughness_m(self) -> float:
        """The sea's aerodynamic roughness length, 3.7e-5·U10²/g·Ω^0.9 (Donelan's, as Elfouhaily)."""
        return 3.7e-5 * self.u10_mps**2 / G_MPS2 * self.inverse_wave_age**0.9

    @property
    def u12_5_mps(self) -> float:
        """The wind at 12.5 m (Cox & Munk's anemometer) by the log profile."""
        z0 = self.roughness_m
        return self.u10_mps * np.log(12.5 / z0) / np.log(10.0 / z0)

    def raw_saturation(self, k):
        """Elfouhaily's curvature spectrum B(k) = k³·S(k), dimensionless, unscaled."""
        k = np.asarray(k, dtype=float)
        om, kp = self.inverse_wave_age, self.k_peak
        c, cp = phase_speed(k), phase_speed(kp)
        sigma = 0.08 * (1.0 + 4.0 * om**-3)
        gamma = 1.7 if om < 1.0 else 1.7 + 6.0 * np.log(om)
        peak = gamma ** np.exp(-((np.sqrt(k / kp) - 1.0) ** 2) / (2.0 * sigma**2))
        l_pm = np.exp(-1.25 * (kp / k) ** 2)
        long = (
            0.5
            * 6e-3
            * om**0.55
            * cp
            / c
            * l_pm
            * peak
            * np.exp(-om / np.sqrt(10.0) * (np.sqrt(k / kp) - 1.0))
        )
        u_star = KAPPA * self.u10_mps / np.log(10.0 / self.roughness_m)
        ratio = np.log(u_star / C_M)
        alpha_m = max(0.0, 1e-2 * (1.0 + (ratio if u_star <= C_M else 3.0 * ratio)))
        short = 0.5 * alpha_m * C_M / c * l_pm * peak * np.exp(-0.25 * (k / K_M - 1.0) ** 2)
        return long + short

    def _mss_raw(self, k_lo, k_hi, n: int = 4001) -> float:
        lk = np.linspace(np.log(k_lo), np.log(k_hi), n)
        return float(np.trapezoid(self.raw_saturation(np.exp(lk)), lk))

    @property
    def k_low(self) -> float:
        """The longest waves counted: a quarter of the peak's wavenumber (the spectrum is ~1e-5 of its peak there)."""
        return self.k_peak / 4.0

    @cached_property
    def scale(self) -> float:
        """Cox & Munk's mean-square slope over the raw spectrum's, from :attr:`k_low` to ``K_TOTAL_MAX``."""
        return cox_munk_mss(self.u12_5_mps) / self._mss_raw(self.k_low, K_TOTAL_MAX)

    def saturation(self, k):
        """The curvature spectrum B(k) scaled to Cox & Munk: ∫ B d(ln k) over all k is their mss."""
        return self.scale * self.raw_saturation(k)

    def mss(self, k_lo: float, k_hi: float, n: int = 4001) -> float:
        """Mean-square slope (both axes together) of the waves between wavenumbers ``k_lo`` and ``k_hi`` (the
        trapezoidal rule on ``n`` points in ln k)."""
        return self.scale * self._mss_raw(k_lo, k_hi, n)


@dataclass(frozen=True)
class WaveField:
    """One realisation: ``len(amplitude_m)`` linear waves (arrays over the waves)."""

    # (M, 2) wave vectors, north and east (rad/m), pointing where each wave travels
    k_ne: np.ndarray
    amplitude_m: np.ndarray  # (M,)
    omega: np.ndarray  # (M,) rad/s
    phase: np.ndarray  # (M,) rad
    resolved_mss: float  # the spectrum's mean-square slope of the realised band (analytic)
    unresolved_mss: float  # Cox & Munk's total minus that: the slopes too short to render
    shortest_wavelength_m: float

    @property
    def height_sigma_m(self) -> float:
        """Standard deviation of η."""
        return float(np.sqrt(0.5 * np.sum(self.amplitude_m**2)))

    def _sum(self, north_m, east_m, t_s, weights, trig):
        """Σ_m weights[:, m]·trig(k_m·x − ω_m·t + φ_m) at points and times (broadcast together), (len(weights), ...).

        In float32 (the speed of its vector sin and cos) about the points' mean place and time: the phases there are
        reduced to [0, 2π) in float64, the rest spans at most a few hundred radians (1e-5 rad in float32)."""
        n, e, t = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (north_m, east_m, t_s)))
        x = np.column_stack([n.ravel(), e.ravel(), t.ravel()])
        out = np.empty((len(weights), len(x)))
        if len(x) == 0:
            return out.reshape((len(weights),) + n.shape)
        x0 = x.mean(axis=0)
        per = np.stack([self.k_ne[:, 0], self.k_ne[:, 1], -self.omega])
        at_x0 = ((x0 @ per + self.phase) % (2 * np.pi)).astype(np.float32)
        per, w = per.astype(np.float32), np.ascontiguousarray(weights.T, dtype=np.float32)
        rel = (x - x0).astype(np.float32)
        step = max(1, CHUNK // len(self.omega))
        for i in range(0, len(x), step):
            ph = rel[i : i + step] @ per
            ph += at_x0
            out[:, i : i + step] = (trig(ph, out=ph) @ w).T
        return out.reshape((len(weights),) + n.shape)

    def height(self, north_m, east_m, t_s):
        """η (m, up) at points and times (broadcast together)."""
        return self._sum(north_m, east_m, t_s, self.amplitude_m[None], np.cos)[0]

    def gradient(self, north_m, east_m, t_s):
        """(∂η/∂north, ∂η/∂east) at points and times, stacked on the last axis (..., 2)."""
        w = -(self.amplitude_m * self.k_ne.T)  # d/dx a·cos(k·x + ...) = −a·k·sin(...)
        return np.moveaxis(self._sum(north_m, east_m, t_s, w, np.sin), 0, -1)

    def averaged(self, radius_m: float) -> WaveField:
        """The field averaged over disks of ``radius_m``: each wave's amplitude times the disk's transfer function
        2·J1(k·r)/(k·r) (an average of linear waves is the sum of their averages)."""
        kr = np.hypot(self.k_ne[:, 0], self.k_ne[:, 1]) * radius_m
        return replace(self, amplitude_m=self.amplitude_m * 2.0 * j1(kr) / kr)

    def at(self, t_s):
        """The surface at time(s) ``t_s`` (a scalar, or an array broadcast with the points asked)."""
        return ExactSurface(self, np.asarray(t_s, dtype=float))

    def gridded(self, lo_ne, hi_ne, t_s: float) -> GriddedSurface:
        """η and its gradient at time ``t_s`` on a grid over the box from ``lo_ne`` to ``hi_ne`` (north, east) with
        ``GRID_PER_WAVELENGTH`` points per shortest wavelength (at most ``MAX_GRID_POINTS``: coarser over a wide view).

        Each octave of wavenumbers is computed on a grid of its own resolution (:meth:`_grid`), from the longest
        waves': each grid is doubled (bicubic) onto the next finer one's points and added to it."""
        lo, hi = np.asarray(lo_ne, dtype=float), np.asarray(hi_ne, dtype=float)
        k = np.hypot(self.k_ne[:, 0], self.k_ne[:, 1])
        octave = np.floor(np.log2(k.max() / k)).astype(int)  # 0: the shortest waves
        step = max(
            2 * np.pi / k.max() / GRID_PER_WAVELENGTH, np.sqrt(np.prod(hi - lo) / MAX_GRID_POINTS)
        )
        origin = lo - step
        shape = np.ceil((hi - origin) / step).astype(int) + 2
        grids = []  # (origin, step, shape) of each octave's grid, the finest first
        for _ in range(octave.max() + 1):
            grids.append((origin, step, shape))
            # a grid twice as coarse whose doubling (cv2.resize: fine point i at coarse i/2 - 1/4) lands on these
            # points, with MARGIN coarse points beyond them on every side
            origin, step, shape = (
                origin + step / 2 - MARGIN * 2 * step,
                2 * step,
                -(-shape // 2) + 2 * MARGIN,
            )
        fields = None
        for b in range(octave.max(), -1, -1):
            origin, step, shape = grids[b]
            if fields is not None:
                doubled = [
                    cv2.resize(f, (2 * f.shape[1], 2 * f.shape[0]), interpolation=cv2.INTER_CUBIC)
                    for f in fields
                ]
                m = 2 * MARGIN
                fields = [f[m : m + shape[0], m : m + shape[1]] for f in doubled]
            waves = np.flatnonzero(octave == b)
            if len(waves):
                own = self._grid(waves, origin, step, *shape, t_s)
                fields = own if fields is None else [f + g for f, g in zip(fields, own)]
            elif fields is None:
                fields = [np.zeros(shape, np.float32)] * 3
        origin, step, _ = grids[0]
        return GriddedSurface(float(origin[0]), float(origin[1]), step, tuple(fields))

    def _grid(
        self, waves, origin_ne, step_m: float, rows: int, cols: int, t_s: float
    ) -> list[np.ndarray]:
        """η, ∂η/∂north and ∂η/∂east (float32 (rows, cols) each) of the waves ``waves`` (indices) on a grid, by one
        complex matrix product: each wave is separable, exp(i·(k_n·n + k_e·e)) = exp(i·k_n·n)·exp(i·k_e·e)."""
        kn, ke = self.k_ne[waves, 0], self.k_ne[waves, 1]
        x = np.exp(1j * np.outer(origin_ne[0] + step_m * np.arange(rows), kn)).astype(np.complex64)
        y = np.exp(1j * np.outer(origin_ne[1] + step_m * np.arange(cols), ke)).T
        c = self.amplitude_m[waves] * np.exp(1j * (self.phase[waves] - self.omega[waves] * t_s))
        right = np.concatenate(
            [c[:, None] * y, (1j * kn * c)[:, None] * y, (1j * ke * c)[:, None] * y], axis=1
        )
        fields = (x @ right.astype(np.complex64)).real
        return [np.ascontiguousarray(fields[:, i * cols : (i + 1) * cols]) for i in range(3)]

    @property
    def grid_reach_m(self) -> float:
        """How far (m) the floor's grids reach past the rays' flat crossings, per unit of tan(incidence): 5 σ of η."""
        return 5.0 * self.height_sigma_m


@dataclass(frozen=True)
class ExactSurface:
    """The wave field at a time, summed wave by wave at each point asked."""

    field: WaveField
    t_s: np.ndarray

    def height(self, ne):
        """η (N,) at points ``ne`` (N, 2)."""
        return self.field.height(ne[:, 0], ne[:, 1], self.t_s)

    def gradient(self, ne):
        """(∂η/∂north, ∂η/∂east) (N, 2) at points ``ne`` (N, 2)."""
        return self.field.gradient(ne[:, 0], ne[:, 1], self.t_s)


@dataclass(frozen=True)
class GriddedSurface:
    """The wave field at a time sampled on a grid (rows along north, columns along east) and interpolated bicubically
    (the floor's many rays): :meth:`WaveField.gridded`."""

    north0_m: float
    east0_m: float
    step_m: float
    fields: tuple  # η, ∂η/∂north, ∂η/∂east: float32 (rows, cols) each

    def _sample(self, ne, which) -> np.ndarray:
        """Fields ``which`` (indices) at points ``ne`` (N, 2): (N, len(which))."""
        x, y = (ne[:, 1] - self.east0_m) / self.step_m, (ne[:, 0] - self.north0_m) / self.step_m
        return np.stack(
            [sample(self.fields[i], x, y, cv2.INTER_CUBIC, cv2.BORDER_REPLICATE) for i in which],
            axis=-1,
        )

    def height(self, ne):
        return self._sample(ne, (0,))[:, 0]

    def gradient(self, ne):
        return self._sample(ne, (1, 2))


def downwind_rad(sc: Scenario) -> float:
    """Where the wind blows to (radians from North): the waves' mean direction of travel."""
    w = sc.waves
    return float(
        np.radians(sc.uav.wind_from_deg if w.direction_from_deg is None else w.direction_from_deg)
        + np.pi
    )


def shortest_wavelength_m(sc: Scenario, fx_px: float) -> float:
    """``[waves] shortest_wavelength_m``, or by default ``RESOLVE_PX`` pixels at the surface seen straight down from
    the UAV's mean height."""
    given = sc.waves.shortest_wavelength_m
    return given if given is not None else RESOLVE_PX * sc.uav.height_m / fx_px


def wave_field(sc: Scenario, fx_px: float) -> WaveField | None:
    """The scenario's wave field (None for a flat surface, ``[waves] wind_mps = 0``); ``fx_px`` the focal length in
    the floor's pixels (the camera's over the renderer's ``floor_div``), for the default shortest wavelength."""
    w = sc.waves
    if w.wind_mps <= 0:
        return None
    spec = Spectrum(w.wind_mps, w.fetch_m)
    lam = shortest_wavelength_m(sc, fx_px)
    k_lo, k_hi, m = spec.k_low, 2 * np.pi / lam, w.components
    rng = np.random.default_rng([sc.seed, SEED_STREAM])
    if not k_hi > 2 * k_lo:
        raise ValueError(
            f"scenario {sc.name}: waves.shortest_wavelength_m = {lam:g}: the spectrum's longest waves are "
            f"{2 * np.pi / k_lo:.3g} m, resolve at least half as long"
        )
    edges = np.geomspace(k_lo, k_hi, m + 1)
    k = np.exp(rng.uniform(np.log(edges[:-1]), np.log(edges[1:])))
    band_mss = np.array([spec.mss(a, b, 65) for a, b in pairwise(edges)])
    amplitude = np.sqrt(2.0 * band_mss) / k
    ratio = cox_munk_crosswind_ratio(spec.u12_5_mps)
    s = spreading_s(ratio)
    theta = np.linspace(-np.pi, np.pi, 4001)
    cdf = np.cumsum(np.cos(theta / 2) ** (2 * s))
    cdf = (cdf - cdf[0]) / (cdf[-1] - cdf[0])
    quantiles = (rng.permutation(m) + rng.uniform(0.0, 1.0, m)) / m
    heading = downwind_rad(sc) + np.interp(quantiles, cdf, theta)
    k_ne = k[:, None] * np.column_stack([np.cos(heading), np.sin(heading)])
    omega = k * phase_speed(k, sc.site.floor_depth_m)
    resolved = spec.mss(k_lo, k_hi)
    return WaveField(
        k_ne,
        amplitude,
        omega,
        rng.uniform(0.0, 2 * np.pi, m),
        resolved,
        cox_munk_mss(spec.u12_5_mps) - resolved,
        lam,
    )

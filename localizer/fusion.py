"""Several drones' fixes of one UUV as one: aligned in time, checked against each other, weighed by their covariances,
their shared errors kept whole, each claim floored by what its fixes show, the result gated against its own track.

Each source (one drone's skyfix) fixes the same UUV at its own frames' times, with its own errors: its
attitude and gimbal, its pixel, its GNSS receiver's noise. Some errors are every drone's
(:data:`SHARED_TERMS`, :func:`shared_effects`): the UUV's one depth sensor, the weather's pressure trend in
every barometer (the height, unless a rangefinder or the UUV's size measures it), the GNSS error of
receivers that see the same sky (or use one RTK base), a clock all the stations share. No number of drones
averages those away. A source's claimed covariance ``C`` is split into its shared part ``G Gᵀ`` (``G``:
2 × :data:`SHARED_TERMS`, the horizontal effect of each shared error at 1-sigma through that drone's own
geometry) and its independent part ``W = C − G Gᵀ`` (a shared part larger than :data:`SHARED_MAX` of the
claim is scaled down to it: :func:`fit_shared`).

- **In time** (:class:`SourceTrack`): a source's position at time ``t`` is its newest fix moved on by
  the velocity fitted (least squares) over its fixes of the last :data:`VELOCITY_S`; its covariance
  grows by that velocity's own uncertainty and by the UUV's acceleration bound over the step, both
  times the step. A source whose newest fix is more than :data:`MAX_STEP_S` from ``t`` is not used.
- **Against each other** (:func:`choose`): two sources agree when their difference lies within
  :data:`AGREE_SIGMAS` (Mahalanobis) of the sum of their covariances — the whole claims, shared parts
  included, though those cancel in the difference: the shared sigmas are partly a configured guess;
  counting them as independent never refuses two drones that agree. The largest set of sources that agree pairwise is fused; the sources outside it are rejected. When two such sets are
  equally large (two sources that disagree, with no third to side with one), the previous fused position
  decides: the set that agrees with it, if exactly one does; otherwise nothing is fused (no fix,
  never a guess).
- **Floored by what they show** (:class:`Floors`): over the last :data:`FLOOR_WINDOW_S` each pair's
  differences are compared with the sum of their claimed covariances; what the differences show beyond
  it is an error at least one of the two has and did not claim. Each source's independent part is raised
  by the smallest such excess over its partners (a source sitting off every other one takes it; two that
  agree with each other keep their claims). The caller adds what a source's own fixes show from frame to
  frame (:attr:`localizer.uuv_track.Scatter.ratio` above 1).
- **Weighed** (:func:`fuse`): generalised least squares over all sources' fixes at once, their joint
  covariance the independent parts on the diagonal blocks plus ``G Gᵀ`` across: ``P = (Hᵀ Σ⁻¹ H)⁻¹``,
  ``x = P Hᵀ Σ⁻¹ z``. Without shared errors this is ``P = (Σ Wᵢ⁻¹)⁻¹``; N drones with one shared
  error ``S`` alike give ``P = W/N + S``, never below ``S``; a shared error that moves two drones' fixes in
  opposite directions (the depth, seen from opposite sides) cancels. The vertical is not combined that way:
  the depth is the same sensor in every source, so the fused altitude is the mean weighted by ``1/v_accᵢ²``
  and its accuracy the best source's, not smaller.
- **Gated against its own track** (:class:`OutputGate`): the fused fixes' own track
  (:class:`~localizer.uuv_track.UuvTrack`); a fused position beyond where the UUV can be from it (more
  than :data:`~localizer.fix_gate.GATE_SIGMAS` over both fused claims, the old and the new: a source joining
  or leaving moves the fused position by at most their difference) is not taken. Where it can be grows with
  the time since the track's last fix at the UUV's top speed, but never beyond ``max_reach_m`` (the live
  gate's :data:`~localizer.fix_gate.MAX_REACH_M`): fused positions held off the track by a fake, or by the
  real drones' absence, do not become valid by waiting. Only the caller restarts the track elsewhere
  (:meth:`OutputGate.restart`: the fuser, once most of its configured drones agree there). The fuser also
  holds a fusion of fewer than half its drones within the reach of where most of them last agreed
  (:meth:`OutputGate.check`'s ``hold``, :func:`beyond_reach_sigmas`): a lone source walking slowly away, each step within the UUV's dynamics,
  cannot drag the fused fix further than ``max_reach_m``.

Pure computation: positions in metres north and east of a reference the caller chooses, times in seconds
of one time base (GNSS time where the sources have it).
"""

from __future__ import annotations

import itertools
import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from .fix import Fix
from .fix_gate import GATE_SIGMAS, MAX_REACH_M
from .refraction import surface_distance
from .uuv_track import UuvTrack

#: A source's velocity is fitted over its fixes of the last this many seconds ...
VELOCITY_S = 0.5
#: ... from at least this many fixes (fewer: the source is used only at its own fixes' times, step ≤ one frame).
VELOCITY_MIN_FIXES = 4
#: A source's newest fix further than this from the fusion time (s) is not used.
MAX_STEP_S = 0.25
#: Two sources agree when their difference is within this many sigmas (Mahalanobis, over their difference's covariance).
AGREE_SIGMAS = 4.0
#: The errors every drone shares, in the columns of ``G`` (:func:`shared_effects`).
SHARED_TERMS = ("depth", "height", "gnss_n", "gnss_e", "clock")
#: At most this share of a claimed covariance is taken as shared (:func:`fit_shared`).
SHARED_MAX = 0.75
#: :class:`Floors` compares each pair of sources over this many seconds.
FLOOR_WINDOW_S = 10.0


def _no_shared() -> np.ndarray:
    return np.zeros((2, len(SHARED_TERMS)))


@dataclass(frozen=True)
class SharedSigmas:
    """1-sigma of the errors every drone shares: ``gnss_m`` (per axis, horizontal: the GNSS error of receivers under
    one sky, or an RTK base's; None: each fix's own ``sigma_uav_m`` taken as shared whole, per axis its DRMS / √2),
    ``height_m`` (the barometers' common trend: at most each fix's own ``sigma_height_m``), ``clock_s`` (the
    stations' common clock error, times the UUV's velocity). The depth's is each fix's own ``sigma_depth_m``."""

    gnss_m: float | None = None
    height_m: float = 0.0
    clock_s: float = 0.0


@dataclass(frozen=True)
class Sample:
    """One source's fix in the fuser's frame: time (s), north-east (m) and covariance (m²), altitude (m AMSL)
    and its 1-sigma (m); ``G`` (m per 1-sigma) the horizontal effect of each of :data:`SHARED_TERMS`."""

    t: float
    z: np.ndarray
    C: np.ndarray
    alt_m: float
    v_acc_m: float
    G: np.ndarray = field(default_factory=_no_shared)


@dataclass(frozen=True)
class Estimate:
    """A source's (or the fusion's) position at one time: north-east (m), covariance (m²), altitude and its
    1-sigma (m); ``G`` as :class:`Sample`'s (``C − G Gᵀ`` is the part independent of the other sources)."""

    z: np.ndarray
    C: np.ndarray
    alt_m: float
    v_acc_m: float
    G: np.ndarray = field(default_factory=_no_shared)

    @property
    def W(self) -> np.ndarray:
        """The independent part of :attr:`C` (m²)."""
        return self.C - self.G @ self.G.T

    def floored(self, F: np.ndarray) -> Estimate:
        """The same with ``F`` (m², an error the source did not claim) added to its independent part."""
        return Estimate(self.z, self.C + F, self.alt_m, self.v_acc_m, self.G)


def positive_part(M: np.ndarray, floor: float = 0.0) -> np.ndarray:
    """A symmetric matrix with its eigenvalues below ``floor`` raised to it."""
    w, V = np.linalg.eigh(0.5 * (M + M.T))
    return (V * np.maximum(w, floor)) @ V.T


def fit_shared(C: np.ndarray, G: np.ndarray) -> np.ndarray:
    """The shared effects ``G`` held within the claim ``C`` (m²): scaled down, where they exceed it, to
    :data:`SHARED_MAX` of it in its every direction (the rest of a claim is the drone's own: its pixel, its
    attitude). A claim is never raised by configured shared sigmas: what its fixes show does that."""
    if not G.any():
        return G
    worst = float(np.max(np.real(np.linalg.eigvals(np.linalg.solve(C, G @ G.T)))))
    return G * math.sqrt(min(1.0, SHARED_MAX / worst))


def shared_effects(
    fix: Fix, sigmas: SharedSigmas, velocity_ne_mps: np.ndarray | None = None
) -> np.ndarray:
    """``G`` (2 × :data:`SHARED_TERMS`, m): how each shared error at 1-sigma moves this fix north and east.

    The depth and the height move it along the line from the UAV to the UUV (``north_m``, ``east_m``) by the
    refracted ray's slope in water and in air (Snell, :func:`~localizer.refraction.surface_distance`) times the
    fix's ``sigma_depth_m`` and the shared height sigma (none when a rangefinder or the UUV's size measured the
    height: then it is the drone's own); the GNSS error moves it as it moves the UAV (:func:`shared_gnss_m`); the
    clock by the UUV's velocity ``velocity_ne_mps`` (m/s) times ``clock_s``. A term whose inputs the fix lacks is 0.
    """
    G = _no_shared()
    rho = math.hypot(fix.north_m, fix.east_m)
    h, d = fix.height_m, fix.depth_m
    if (
        math.isfinite(rho)
        and rho > 0
        and math.isfinite(h)
        and h > 0
        and math.isfinite(d)
        and d >= 0
    ):
        x = float(surface_distance(rho, h, d))
        sin_w = x / math.hypot(x, h) / 1.34
        tan_air, tan_water = x / h, sin_w / math.sqrt(1.0 - sin_w * sin_w)
        along = np.array([fix.north_m, fix.east_m]) / rho
        sigma_depth = fix.sigma_depth_m if math.isfinite(fix.sigma_depth_m) else 0.0
        own_height = any(w in fix.height_source for w in ("rangefinder", "size"))
        sigma_height = (
            0.0
            if own_height
            else min(
                sigmas.height_m,
                fix.sigma_height_m if math.isfinite(fix.sigma_height_m) else sigmas.height_m,
            )
        )
        G[:, 0] = along * tan_water * sigma_depth
        G[:, 1] = along * tan_air * sigma_height
    G[0, 2] = G[1, 3] = shared_gnss_m(fix, sigmas)
    if velocity_ne_mps is not None:
        G[:, 4] = velocity_ne_mps * sigmas.clock_s
    return G


def shared_gnss_m(fix: Fix, sigmas: SharedSigmas) -> float:
    """The per-axis 1-sigma (m) of the GNSS error this fix shares with the other drones': the configured
    ``gnss_m``, else the fix's own UAV position sigma (``sigma_uav_m``, a DRMS: / √2 per axis) whole (receivers under
    one sky share most of theirs; an RTK base's error is every rover's); 0 when the fix does not carry it."""
    if sigmas.gnss_m is not None:
        return sigmas.gnss_m
    return fix.sigma_uav_m / math.sqrt(2.0) if math.isfinite(fix.sigma_uav_m) else 0.0


class SourceTrack:
    """One source's recent fixes and its position at nearby times (see the module doc)."""

    def __init__(self, max_accel_mps2: float):
        self.max_accel_mps2 = max_accel_mps2
        self.samples: deque[Sample] = deque()

    def add(self, s: Sample) -> None:
        """A new fix; one not after the newest is ignored (the caller's gate refuses those)."""
        if self.samples and s.t <= self.samples[-1].t:
            return
        self.samples.append(s)
        while self.samples[0].t < s.t - VELOCITY_S:
            self.samples.popleft()

    def clear(self) -> None:
        """The source lost the UUV: its old fixes say nothing about where it is now."""
        self.samples.clear()

    @property
    def newest_t(self) -> float:
        return self.samples[-1].t if self.samples else -math.inf

    def velocity(self) -> tuple[np.ndarray, np.ndarray] | None:
        """Velocity (m/s, north-east) fitted over the kept fixes and its covariance ((m/s)²); None from too few."""
        if len(self.samples) < VELOCITY_MIN_FIXES:
            return None
        t = np.array([s.t for s in self.samples])
        z = np.array([s.z for s in self.samples])
        dt = t - t.mean()
        sxx = float(dt @ dt)
        if sxx <= 0.0:
            return None
        v = dt @ (z - z.mean(axis=0)) / sxx
        resid = z - z.mean(axis=0) - np.outer(dt, v)
        noise_m2 = (resid**2).sum(axis=0) / max(1, len(t) - 2)
        return v, np.diag(noise_m2 / sxx)

    def at(self, t: float) -> Estimate | None:
        """The source's position at ``t``, or None when its newest fix is more than :data:`MAX_STEP_S` away
        (or, without a velocity, is not the fix of ``t`` itself)."""
        if not self.samples or abs(t - self.newest_t) > MAX_STEP_S:
            return None
        last = self.samples[-1]
        step = t - last.t
        if step == 0.0:
            return Estimate(last.z, last.C, last.alt_m, last.v_acc_m, last.G)
        fitted = self.velocity()
        if fitted is None:
            return None
        v, V = fitted
        grow = V * step**2 + np.eye(2) * (0.5 * self.max_accel_mps2 * step**2) ** 2
        return Estimate(last.z + v * step, last.C + grow, last.alt_m, last.v_acc_m, last.G)


def distance(a: Estimate, b: Estimate) -> float:
    """Mahalanobis distance of two estimates' difference over the sum of their covariances."""
    d = a.z - b.z
    return float(math.sqrt(max(0.0, d @ np.linalg.solve(a.C + b.C, d))))


def choose(estimates: dict[str, Estimate], prior: Estimate | None) -> tuple[str, ...]:
    """The sources to fuse (see the module doc): the largest pairwise-agreeing set, the prior deciding a tie;
    () when nothing can be chosen."""
    names = sorted(estimates)
    agree = {
        (a, b): distance(estimates[a], estimates[b]) <= AGREE_SIGMAS
        for a, b in itertools.combinations(names, 2)
    }
    for size in range(len(names), 0, -1):
        sets = [
            s
            for s in itertools.combinations(names, size)
            if all(agree[p] for p in itertools.combinations(s, 2))
        ]
        if len(sets) == 1:
            return sets[0]
        if sets:
            if prior is None:
                return ()
            with_prior = [
                s for s in sets if distance(fuse([estimates[n] for n in s]), prior) <= AGREE_SIGMAS
            ]
            return with_prior[0] if len(with_prior) == 1 else ()
    return ()


def fuse(estimates: list[Estimate]) -> Estimate:
    """The generalised least-squares combination of the estimates, their shared errors correlating them (module
    doc); the altitude weighted by ``1/v_acc²`` with the best source's accuracy (the depth they share is not
    averaged away). The result carries no ``G``: its covariance holds the shared part whole."""
    n = len(estimates)
    H = np.tile(np.eye(2), (n, 1))
    G = np.vstack([e.G for e in estimates])
    Sigma = G @ G.T
    for i, e in enumerate(estimates):
        Sigma[2 * i : 2 * i + 2, 2 * i : 2 * i + 2] += e.W
    SiH = np.linalg.solve(Sigma, H)
    P = np.linalg.inv(H.T @ SiH)
    z = P @ (SiH.T @ np.concatenate([e.z for e in estimates]))
    v = [
        e
        for e in estimates
        if math.isfinite(e.v_acc_m) and e.v_acc_m > 0 and math.isfinite(e.alt_m)
    ]
    if v:
        w = np.array([1.0 / e.v_acc_m**2 for e in v])
        alt = float(np.dot(w, [e.alt_m for e in v]) / w.sum())
        v_acc = min(e.v_acc_m for e in v)
    else:
        alt = float(np.mean([e.alt_m for e in estimates]))
        v_acc = math.nan
    return Estimate(z, 0.5 * (P + P.T), alt, v_acc)


class Floors:
    """What the sources' differences show beyond their claims, pair by pair, over :data:`FLOOR_WINDOW_S` (module
    doc): :meth:`add` at each fusion time, :meth:`excess_m2` the floor of one source."""

    def __init__(self):
        self._pairs: dict[tuple[str, str], deque[tuple[float, np.ndarray]]] = {}

    def add(self, t: float, estimates: dict[str, Estimate]) -> None:
        """Every pair's difference at ``t`` against the sum of their (unfloored) claimed covariances."""
        for a, b in itertools.combinations(sorted(estimates), 2):
            ea, eb = estimates[a], estimates[b]
            d = ea.z - eb.z
            q = self._pairs.setdefault((a, b), deque())
            q.append((t, np.outer(d, d) - ea.C - eb.C))
            while q[0][0] < t - FLOOR_WINDOW_S:
                q.popleft()

    def excess_m2(self, name: str, t: float) -> np.ndarray:
        """The smallest excess (m², by its trace) of the pairs ``name`` was in within the window before ``t``: the
        mean of ``d dᵀ −`` their claimed covariances, its negative part dropped; zero without a partner. From the
        first comparison on: a source that sits off its partners is floored at once (an honest pair's few first
        comparisons may floor them a little, on the safe side)."""
        best = None
        for pair, q in self._pairs.items():
            kept = [M for s, M in q if s >= t - FLOOR_WINDOW_S]
            if name not in pair or not kept:
                continue
            E = positive_part(sum(kept) / len(kept))
            if best is None or np.trace(E) < np.trace(best):
                best = E
        return np.zeros((2, 2)) if best is None else best


def beyond_reach_sigmas(
    z: np.ndarray, C: np.ndarray, anchor_z: np.ndarray, anchor_C: np.ndarray, reach_m: float
) -> float:
    """How many sigmas a position ``z`` (covariance ``C``, m²) lies beyond ``reach_m`` of ``anchor_z`` (covariance
    ``anchor_C``): the distance beyond the reach over the 1-sigma of both along the line between them; 0 within."""
    d = z - anchor_z
    dist = float(np.hypot(*d))
    if dist <= reach_m:
        return 0.0
    u = d / dist
    return (dist - reach_m) / math.sqrt(float(u @ (C + anchor_C) @ u))


class OutputGate:
    """The fused fixes' own track (module doc): :meth:`check` says whether a fused position can be the UUV."""

    def __init__(
        self, max_speed_mps: float, max_accel_mps2: float, max_reach_m: float = MAX_REACH_M
    ):
        self.max_speed_mps = max_speed_mps
        self.max_accel_mps2 = max_accel_mps2
        self.max_reach_m = max_reach_m
        self.track: UuvTrack | None = None
        self.refused = 0
        self.restarts = 0

    def check(
        self, t: float, z: np.ndarray, C: np.ndarray, hold: Estimate | None = None
    ) -> float | None:
        """None when the fused position ``z`` (covariance ``C``, m²) at ``t`` lies where the UUV can be by the track
        (which then takes it; the first starts it), else how many sigmas beyond (the track unchanged: what it
        allows grows with the time since its last fix, at the UUV's top speed, up to ``max_reach_m``). ``hold``:
        a position it must also lie within ``max_reach_m`` of (:func:`beyond_reach_sigmas`)."""
        if hold is not None:
            d = beyond_reach_sigmas(z, C, hold.z, hold.C, self.max_reach_m)
            if d > GATE_SIGMAS:
                self.refused += 1
                return d
        if self.track is None:
            self._start(t, z, C)
            return None
        d = self.track.distance(t, z, C + self.track.C, 1.0)[0]
        if d > GATE_SIGMAS:
            self.refused += 1
            return d
        self.track.update(t, z, C, 1.0)
        return None

    def restart(self, t: float, z: np.ndarray, C: np.ndarray) -> None:
        """Start the track again at ``z`` (the caller has reason to trust it there; counted in ``restarts``)."""
        self.restarts += self.track is not None
        self._start(t, z, C)

    def _start(self, t: float, z: np.ndarray, C: np.ndarray) -> None:
        self.track = UuvTrack(
            self.max_speed_mps, self.max_accel_mps2, t, z, C, 1.0, max_reach_m=self.max_reach_m
        )

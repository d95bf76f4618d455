"""Several drones' fixes of one UUV as one: aligned in time, checked against each other, weighed by their covariances.

Each source (one drone's skyfix) fixes the same UUV at its own frames' times, with its own errors: its
GNSS, its attitude and gimbal, its height over the water, its pixel. Those errors are independent from
one drone to the next; only the UUV's depth (one pressure sensor) is shared, and it enters the vertical.

- **In time** (:class:`SourceTrack`): a source's position at time ``t`` is its newest fix moved on by
  the velocity fitted (least squares) over its fixes of the last :data:`VELOCITY_S`; its covariance
  grows by that velocity's own uncertainty and by the UUV's acceleration bound over the step, both
  times the step. A source whose newest fix is more than :data:`MAX_STEP_S` from ``t`` is not used.
- **Against each other** (:func:`choose`): two sources agree when their difference lies within
  :data:`AGREE_SIGMAS` (Mahalanobis) of the sum of their covariances — the whole claimed covariance,
  common part included, since the drones' common errors are independent. The largest set of sources
  that agree pairwise is fused; the sources outside it are rejected. When two such sets are equally
  large (two sources that disagree, with no third to side with one), the previous fused position
  decides: the set that agrees with it, if exactly one does; otherwise nothing is fused (no fix,
  never a guess).
- **Weighed** (:func:`fuse`): ``P = (Σ Cᵢ⁻¹)⁻¹``, ``x = P Σ Cᵢ⁻¹ zᵢ`` — the minimum-variance combination
  of independent estimates. The vertical is not combined that way: the depth is the same sensor in
  every source, so the fused altitude is the mean weighted by ``1/v_accᵢ²`` and its accuracy the best
  source's, not smaller.

Pure computation: positions in metres north and east of a reference the caller chooses, times in seconds
of one time base (GNSS time where the sources have it).
"""

from __future__ import annotations

import itertools
import math
from collections import deque
from dataclasses import dataclass

import numpy as np

#: A source's velocity is fitted over its fixes of the last this many seconds ...
VELOCITY_S = 0.5
#: ... from at least this many fixes (fewer: the source is used only at its own fixes' times, step ≤ one frame).
VELOCITY_MIN_FIXES = 4
#: A source's newest fix further than this from the fusion time (s) is not used.
MAX_STEP_S = 0.25
#: Two sources agree when their difference is within this many sigmas (Mahalanobis, over C_i + C_j).
AGREE_SIGMAS = 4.0


@dataclass(frozen=True)
class Sample:
    """One source's fix in the fuser's frame: time (s), north-east (m) and covariance (m²), altitude (m AMSL)
    and its 1-sigma (m)."""

    t: float
    z: np.ndarray
    C: np.ndarray
    alt_m: float
    v_acc_m: float


@dataclass(frozen=True)
class Estimate:
    """A source's (or the fusion's) position at one time: north-east (m), covariance (m²), altitude and its
    1-sigma (m)."""

    z: np.ndarray
    C: np.ndarray
    alt_m: float
    v_acc_m: float


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
            return Estimate(last.z, last.C, last.alt_m, last.v_acc_m)
        fitted = self.velocity()
        if fitted is None:
            return None
        v, V = fitted
        grow = V * step**2 + np.eye(2) * (0.5 * self.max_accel_mps2 * step**2) ** 2
        return Estimate(last.z + v * step, last.C + grow, last.alt_m, last.v_acc_m)


def distance(a: Estimate, b: Estimate) -> float:
    """Mahalanobis distance of two independent estimates' difference over the sum of their covariances."""
    d = a.z - b.z
    return float(math.sqrt(max(0.0, d @ np.linalg.solve(a.C + b.C, d))))


def choose(estimates: dict[str, Estimate], prior: Estimate | None) -> tuple[str, ...]:
    """The sources to fuse (see the module doc): the largest pairwise-agreeing set, the prior deciding a tie;
    () when nothing can be chosen."""
    names = sorted(estimates)
    agree = {(a, b): distance(estimates[a], estimates[b]) <= AGREE_SIGMAS for a, b in itertools.combinations(names, 2)}
    for size in range(len(names), 0, -1):
        sets = [s for s in itertools.combinations(names, size) if all(agree[p] for p in itertools.combinations(s, 2))]
        if len(sets) == 1:
            return sets[0]
        if sets:
            if prior is None:
                return ()
            with_prior = [s for s in sets if distance(fuse([estimates[n] for n in s]), prior) <= AGREE_SIGMAS]
            return with_prior[0] if len(with_prior) == 1 else ()
    return ()


def fuse(estimates: list[Estimate]) -> Estimate:
    """The covariance-weighted combination of independent estimates; the altitude weighted by ``1/v_acc²`` with
    the best source's accuracy (the depth they share is not averaged away)."""
    info = sum(np.linalg.inv(e.C) for e in estimates)
    P = np.linalg.inv(info)
    z = P @ sum(np.linalg.solve(e.C, e.z) for e in estimates)
    v = [e for e in estimates if math.isfinite(e.v_acc_m) and e.v_acc_m > 0 and math.isfinite(e.alt_m)]
    if v:
        w = np.array([1.0 / e.v_acc_m**2 for e in v])
        alt = float(np.dot(w, [e.alt_m for e in v]) / w.sum())
        v_acc = min(e.v_acc_m for e in v)
    else:
        alt = float(np.mean([e.alt_m for e in estimates]))
        v_acc = math.nan
    return Estimate(z, 0.5 * (P + P.T), alt, v_acc)

"""The fuser's decisions, fix by fix: only the configured drones, each through its own gates, then fused
(:mod:`localizer.fusion`), the result gated against its own track.

A source is one drone's skyfix, named by the key its fixes come on. Only the sources the fuser
was given (``sources``) are taken: a fix from any other key is counted (``unconfigured``) and
goes no further. A fix stamped ahead of the fuser's clock by more than ``clock_tolerance_s``
(its station time ``t``, or its GNSS time against the source's usual offset from its
station time, the median of its recent fixes') is refused as ``future`` and counted: it goes
into no track, so it cannot hold back the fixes after it. Each fix is then judged on its own
(:class:`~localizer.fix_gate.FixGate`, one per source: accuracy, age, order, and the source's
own track of the UUV — a drone whose tracker jumps to a look-alike is refused there, and a
drone that joins or comes back is taken only after a second of consistent fixes); a source
reporting the UUV lost, released or awaited drops its fixes at once. Then, at the time of the
fix that just came, every source with a recent fix is moved to that time, its claim floored
by what its fixes show — from frame to frame (its gate's
:attr:`~localizer.uuv_track.Scatter.ratio`, when above 1: the fixes scatter beyond their whole
claim) and against the other sources (:class:`~localizer.fusion.Floors`) — its shared errors
(:func:`~localizer.fusion.shared_effects`, ``shared``) split from its own, and the ones that
agree are fused (:func:`~localizer.fusion.choose`, :func:`~localizer.fusion.fuse`).
The fused fixes decide between two sources that disagree once they have gone on for a
second (:data:`~localizer.fix_gate.CONFIRM_S`) without a disagreement: an incumbent drone that
has been fused for a second outweighs a newcomer that disagrees with it; two that appear
together and disagree get no fix until a third sides with one. A fused position beyond where
the UUV can be by the fused fixes' own track (:class:`~localizer.fusion.OutputGate`, its reach capped at
``max_reach_m`` however long since) is an ``off_track`` fix: no position, GPS_INPUT says no fix. The track
starts again at the fused position only once more than half of the configured drones have agreed on it for
:data:`~localizer.fix_gate.CONFIRM_S` and no source with a current fix disagrees (the UUV moved on while they
had lost it); while one does, the fused fix stays off_track: no fix rather than a guess. A fusion of half the configured
drones or fewer is ``off_track`` too beyond ``max_reach_m`` of the last fused position most of them agreed on
(:meth:`~localizer.fusion.OutputGate.check`'s ``hold``; none yet: the sources' own gates judge): one drone faking fixes,
or a minority, can neither drag the fused fix further nor restart it where they say (the price: one drone left
alone of two follows the UUV only that far).

Time base: a fix's GNSS time (``t_gnss``, the drone's station clock corrected by its
autopilot's SYSTEM_TIME) where it has one, else its station time ``t`` — then the drones'
laptops must keep their clocks together (NTP, chrony): an offset between them moves the
sources apart by the UUV's speed times it, and shows in each source's ``delay_s`` (arrival on
the fuser's clock minus the fix's time). The fused fix carries the newest source fix's ``t``
and ``t_gnss``; at most ``max_hz`` fused fixes a second go out (two drones at 30 fps would
otherwise make 60).

A fused fix: ``ok``, its position and 2×2 covariance the fusion's, ``h_acc_m`` half that covariance's 95 % circle's radius
(:func:`~localizer.uncertainty.h_acc_from_cov_m`, as every fix's),
``v_acc_m`` the best source's (the depth is shared), ``depth_m`` and the word fields the
newest source fix's; no pixel (``u``, ``v``) and no offset from a UAV (``north_m``, ``east_m``).
When sources disagree and nothing decides between them: a ``disagree`` fix (no position), and
GPS_INPUT says no fix at once.

Pure computation (no I/O): :meth:`Fuser.on_fix` is called with each received fix and the
fuser's clock.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Collection
from dataclasses import dataclass, field

import numpy as np

from groundstation.runtime.gps_input import LOSS_STATUSES
from localizer.clock import Median
from localizer.fix import Fix
from localizer.fix_gate import CONFIRM_S, MAX_REACH_M, MAX_SPEED_MPS, FixGate
from localizer.fusion import (
    Estimate,
    Floors,
    OutputGate,
    Sample,
    SharedSigmas,
    SourceTrack,
    choose,
    fit_shared,
    fuse,
    shared_effects,
)
from localizer.geodesy import geodetic_to_ned, ned_to_geodetic
from localizer.uncertainty import h_acc_from_cov_m
from localizer.uuv_track import fix_covariance_m2

#: Fused fixes go out at most this often per second by default.
MAX_HZ = 30.0
#: A fix stamped this far (s) ahead of the fuser's clock is refused as ``future`` by default: the drones' and the
#: fuser's clocks must agree this well (their fixes' age is judged on them too).
CLOCK_TOLERANCE_S = 0.25
#: Fixes from names not configured are counted by name for this many names, the rest together.
UNCONFIGURED_NAMES = 32


def aligned_t(fix: Fix) -> float:
    """The fix's time in the fuser's time base: GNSS time when the source knows it, else its station time."""
    return fix.t_gnss if math.isfinite(fix.t_gnss) else fix.t_unix


@dataclass
class Source:
    """One drone's fixes as the fuser sees them."""

    gate: FixGate
    track: SourceTrack
    received: int = 0
    refused: Counter = field(default_factory=Counter)
    used: int = 0  # fusions it took part in
    rejected: int = 0  # fusions it was left out of, disagreeing
    in_use: bool = False  # it took part in the last fusion
    last_status: str | None = None
    last_recv: float | None = None
    delay_s: float | None = None  # arrival (fuser's clock) minus the fix's time
    time_base: str | None = None  # "gnss" or "station"
    h_acc_m: float | None = None
    # its claim as the last fusion weighed it (as an h_acc): shared part, floors
    h_acc_used_m: float | None = None
    # the DRMS of what the floors added to its claim at the last fusion
    floor_m: float | None = None
    offset: Median = field(default_factory=Median)  # its fixes' aligned time minus station time (s)

    def status(self, now: float) -> dict:
        def num(x, digits=3):
            return None if x is None or not math.isfinite(x) else round(float(x), digits)

        return {
            "received": self.received,
            "used": self.used,
            "rejected": self.rejected,
            "in_use": self.in_use,
            "refused": dict(self.refused),
            "gate_state": self.gate.state,
            "last_status": self.last_status,
            "age_s": None if self.last_recv is None else num(max(0.0, now - self.last_recv)),
            "delay_s": num(self.delay_s),
            "time_base": self.time_base,
            "h_acc_m": num(self.h_acc_m),
            "h_acc_used_m": num(self.h_acc_used_m),
            "floor_m": num(self.floor_m),
        }


class Fuser:
    """Per-source gates and the fusion (see the module doc); ``new_gate()`` makes a source's gate, ``sources`` are
    the names (fix keys) whose fixes may be fused."""

    def __init__(
        self,
        new_gate: Callable[[], FixGate],
        max_accel_mps2: float,
        max_hz: float = MAX_HZ,
        *,
        sources: Collection[str],
        max_speed_mps: float = MAX_SPEED_MPS["bluerov2"],
        clock_tolerance_s: float = CLOCK_TOLERANCE_S,
        shared: SharedSigmas | None = None,
        max_reach_m: float = MAX_REACH_M,
    ):
        self.new_gate = new_gate
        self.configured = frozenset(sources)
        self.max_accel_mps2 = max_accel_mps2
        self.clock_tolerance_s = clock_tolerance_s
        self.shared = shared or SharedSigmas()
        # a little under the period: sources' frames do not tick exactly
        self.min_step_s = 0.9 / max_hz
        self.sources: dict[str, Source] = {}
        self.unconfigured: Counter[str] = Counter()  # fixes from names not configured, by name
        # the fused fixes: what decides between disagreeing sources
        self.fused = SourceTrack(max_accel_mps2)
        self.output = OutputGate(max_speed_mps, max_accel_mps2, max_reach_m)
        self.floors = Floors()
        self.published = 0
        self.disagreements = 0
        self.last_t = -math.inf
        self.last_sources: tuple[str, ...] = ()
        self._ref: tuple[float, float] | None = None
        self._fused_since: float | None = None  # the first fusion since the last disagreement
        # the first of a run of fusions off the output's track with most configured sources in it, none opposed;
        # the last fused position most configured sources agreed on
        self._off_since: float | None = None
        self._anchor: Estimate | None = None

    def on_fix(self, name: str, fix: Fix, now: float) -> Fix | None:
        """Take one source's fix received at ``now`` (the fuser's clock); the fused fix to publish, or None."""
        if name not in self.configured:
            self.unconfigured[
                name
                if name in self.unconfigured or len(self.unconfigured) < UNCONFIGURED_NAMES
                else "(others)"
            ] += 1
            return None
        src = self.sources.get(name)
        if src is None:
            src = self.sources[name] = Source(self.new_gate(), SourceTrack(self.max_accel_mps2))
        src.received += 1
        src.last_status, src.last_recv, src.delay_s = fix.status, now, now - fix.t_unix
        if not fix.ok:
            if fix.status in LOSS_STATUSES:
                src.gate.target_lost()
                src.track.clear()
            return None
        t = aligned_t(fix)
        usual = src.offset.value
        src.offset.add(t - fix.t_unix)
        if fix.t_unix - now > self.clock_tolerance_s or (
            usual is not None and t - fix.t_unix - usual > self.clock_tolerance_s
        ):
            src.refused["future"] += 1
            return None
        why = src.gate.check(fix, now)
        if why is not None:
            src.refused[why] += 1
            return None
        src.time_base = "gnss" if math.isfinite(fix.t_gnss) else "station"
        src.delay_s, src.h_acc_m = now - t, fix.h_acc_m
        z, C = self._local(fix)
        fitted = self.fused.velocity()
        G = fit_shared(C, shared_effects(fix, self.shared, None if fitted is None else fitted[0]))
        src.track.add(Sample(t, z, C, fix.alt_amsl_m, fix.v_acc_m, G))
        if t < self.last_t + self.min_step_s:
            return None  # behind the fused stream, or too soon after it: used in the next fusion
        return self._fuse(t, fix)

    def _scatter_m2(self, name: str, e: Estimate) -> np.ndarray:
        """What a source's fixes show from frame to frame beyond its whole claim (m²)."""
        ratio = self.sources[name].gate.scatter.ratio
        return (ratio - 1.0) * e.C if ratio is not None and ratio > 1.0 else np.zeros((2, 2))

    def _fuse(self, t: float, newest: Fix) -> Fix:
        claimed: dict[str, Estimate] = {}
        for name, src in self.sources.items():
            e = src.track.at(t)
            if e is not None:
                claimed[name] = e
        self.floors.add(t, claimed)
        # which agree: by their claims and their own scatter (a source's bias seen by the others does not make it
        # agree); how much each weighs: the floors from the others too
        scattered = {name: e.floored(self._scatter_m2(name, e)) for name, e in claimed.items()}
        estimates = {}
        for name, e in scattered.items():
            estimates[name] = e.floored(self.floors.excess_m2(name, t))
            src = self.sources[name]
            src.floor_m = math.sqrt(max(0.0, np.trace(estimates[name].C - claimed[name].C)))
            src.h_acc_used_m = float(h_acc_from_cov_m(estimates[name].C))
        settled = self._fused_since is not None and t - self._fused_since >= CONFIRM_S
        chosen = choose(scattered, self.fused.at(t) if settled else None)
        for name, src in self.sources.items():
            src.in_use = name in chosen
            src.used += src.in_use
            src.rejected += name in estimates and not src.in_use
        self.last_t, self.last_sources = t, chosen
        self.published += 1
        if not chosen:
            self.disagreements += 1
            self.fused.clear()
            self._fused_since = self._off_since = None
            return Fix(
                t_unix=newest.t_unix, status="disagree", t_gnss=newest.t_gnss, frame=self.published
            )
        est = fuse([estimates[n] for n in chosen])
        majority = 2 * len(chosen) > len(self.configured)
        if self.output.check(t, est.z, est.C, None if majority else self._anchor) is not None:
            # most configured sources, none with a current fix left out, off the track: for a second, a restart
            unopposed = majority and len(chosen) == len(estimates)
            if not unopposed:
                self._off_since = None
            elif self._off_since is None:
                self._off_since = t
            if unopposed and t - self._off_since >= CONFIRM_S:
                self.output.restart(t, est.z, est.C)
            else:
                return Fix(
                    t_unix=newest.t_unix,
                    status="off_track",
                    t_gnss=newest.t_gnss,
                    frame=self.published,
                )
        self._off_since = None
        if majority:
            self._anchor = est
        self.fused.add(Sample(t, est.z, est.C, est.alt_m, est.v_acc_m))
        if self._fused_since is None:
            self._fused_since = t
        lat, lon, _ = ned_to_geodetic(est.z[0], est.z[1], 0.0, *self._ref, 0.0)
        # NaN without the source's ellipsoid height
        geoid_m = newest.alt_ellipsoid_m - newest.alt_amsl_m
        return Fix(
            t_unix=newest.t_unix,
            status="ok",
            lat=float(lat),
            lon=float(lon),
            alt_amsl_m=est.alt_m,
            alt_ellipsoid_m=est.alt_m + geoid_m,
            depth_m=newest.depth_m,
            h_acc_m=float(h_acc_from_cov_m(est.C)),
            v_acc_m=est.v_acc_m,
            sigma_n_m=math.sqrt(est.C[0, 0]),
            sigma_e_m=math.sqrt(est.C[1, 1]),
            cov_ne_m2=float(est.C[0, 1]),
            t_gnss=newest.t_gnss,
            sigma_depth_m=newest.sigma_depth_m,
            height_source=newest.height_source,
            depth_source=newest.depth_source,
            time_source=newest.time_source,
            frame=self.published,
        )

    def _local(self, fix: Fix) -> tuple[np.ndarray, np.ndarray]:
        """The fix in metres north and east of the first fix the fuser took, with its covariance."""
        if self._ref is None:
            self._ref = (fix.lat, fix.lon)
        n, e, _ = geodetic_to_ned(fix.lat, fix.lon, 0.0, *self._ref, 0.0)
        return np.array([float(n), float(e)]), fix_covariance_m2(
            fix.sigma_n_m, fix.sigma_e_m, fix.cov_ne_m2, fix.h_acc_m
        )

    def status(self, now: float) -> dict:
        return {
            "published": self.published,
            "disagreements": self.disagreements,
            "off_track": self.output.refused,
            "output_restarts": self.output.restarts,
            "last_sources": list(self.last_sources),
            "configured": sorted(self.configured),
            "unconfigured": dict(self.unconfigured),
            "sources": {name: src.status(now) for name, src in sorted(self.sources.items())},
        }

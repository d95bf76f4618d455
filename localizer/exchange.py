"""Several UUVs in one video: when a UUV's target may be another UUV's, and the evidence that says whose it is.

Two trackers in one video can exchange their targets where the vehicles pass near or over each other: a tracker that
loses its UUV under the other locks onto the other, or both follow the wrong vehicle after they part. Each UUV's
gate (:class:`~localizer.fix_gate.FixGate`) joins one :class:`Fleet` and shares its newest target (the tracker's
fix, valid or not, with the UUV's pressure depth) and its trusted track; then, for each UUV:

- **An encounter** begins when its target comes within :data:`NEAR_M` of another UUV's newest target, or of where
  that UUV's trusted track is now (boxes that overlap or come near; a jump toward the other vehicle's track). Both
  trusted tracks as they were then, its own and the other's, are kept (:class:`Encounter`).
- **While they are near**: with the other UUV at least :data:`DEPTH_APART_M` deeper, this one is on top and what its
  tracker sees there is this one (the other is hidden under it): its fixes are judged as ever. Otherwise (the other on
  top, or both at about one depth) no fix (``exchanged``): which is which cannot be told.
- **Once they have parted** (beyond :data:`NEAR_M`): the lock's fixes since the encounter began are weighed as two
  hypotheses — the target is this UUV (its kept track moved on, the fix at its own depth) or the other (the other's
  kept track moved on, the fix's ray taken down to the other's pressure depth: :func:`depth_shift`) — by the
  log-likelihood of each one's innovations (a constant-velocity filter from the kept track, the vehicles holding
  their course within :data:`COURSE_ACCEL_MPS2`; while the other's own fixes are valid, the other is where its
  current track says). The encounter ends, and the fixes are judged as ever, only when the
  UUV's own hypothesis is :data:`EVIDENCE` nats likelier; until then ``exchanged``, with the evidence in the status.
  A tracker's lock follows one object: a new lock (after a loss, a selection) weighs its own fixes from the kept
  tracks again, and so does a fix the own hypothesis cannot explain (beyond :data:`~localizer.fix_gate.GATE_SIGMAS`:
  the tracker moved to another object without saying so). The operator's confirmation ends the encounter too.

A target that another UUV's gate has found to be this UUV (its encounter with this one's evidence at −EVIDENCE or
less) does not keep this one near; and this one's target on the same spot (within :data:`SAME_SPOT_M`, taken to
this one's depth) is this UUV: two trackers on it. Pure computation: times are the gates' (UNIX s),
positions metres north and east in each gate's own local frame, moved between frames by :meth:`Fleet.shift_m`.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field

import numpy as np

from .geodesy import geodetic_to_ned
from .refraction import surface_distance
from .uuv_track import UuvTrack

#: Targets closer than this (m, horizontally) may be exchanged: two BlueROV2 lengths (0.46 m), the trackers' boxes'
#: margin included.
NEAR_M = 1.0
#: Of two UUVs that overlap, one at least this much (m) shallower hides the other: a BlueROV2's height (0.25 m) and
#: the depths' errors.
DEPTH_APART_M = 0.3
#: Two targets closer than this (m), taken to one depth, are one vehicle: half a BlueROV2's length.
SAME_SPOT_M = 0.25
#: The hypotheses' filters: the vehicles hold their course within this white acceleration (m/s², 1-sigma).
COURSE_ACCEL_MPS2 = 0.3
#: The log-likelihood ratio (nats) by which the UUV's own hypothesis must beat the other's.
EVIDENCE = 20.0
#: Another UUV's target or trusted track is taken as where it is for this long (s).
RECENT_S = 0.5
#: The water's refractive index the fix's ray is taken down with (the fix does not carry the calibration's).
N_WATER = 1.34


def depth_shift(north_m: float, east_m: float, height_m: float, depth_m: float) -> np.ndarray:
    """How far (m north, east) a fix moves per metre deeper along its own ray: the refracted ray's horizontal
    direction times the tangent of its angle in the water, for a fix ``north_m``, ``east_m`` from the UAV, the camera
    ``height_m`` over the water and the UUV ``depth_m`` under it (zero when any is missing or it is at the nadir)."""
    rho = math.hypot(north_m, east_m)
    if not (math.isfinite(rho) and rho > 0 and height_m > 0 and depth_m >= 0):
        return np.zeros(2)
    x = float(surface_distance(rho, height_m, depth_m, N_WATER))
    sin_w = x / math.hypot(x, height_m) / N_WATER
    return np.array([north_m, east_m]) / rho * (sin_w / math.sqrt(1.0 - sin_w * sin_w))


@dataclass
class Sighting:
    """A UUV's newest target as its gate took it: time (the gate's), north-east (m, the gate's frame), the UUV's
    pressure depth (m) and :func:`depth_shift`."""

    t: float
    z: np.ndarray
    depth_m: float
    shift: np.ndarray


@dataclass
class Other:
    """Another UUV as one gate sees it now, in that gate's frame: its recent target and where its trusted track is
    (None: not recent), its depth (m), its trusted track (a copy) and whether its gate passed its last fixes."""

    uuv_id: str
    target: np.ndarray | None
    at: np.ndarray | None
    depth_m: float
    track: UuvTrack | None
    valid: bool = False  # its own fixes are valid now: its track says where it is
    # its recent target, which its gate found to be the viewer's UUV
    on_viewer: np.ndarray | None = None

    def near(self, z: np.ndarray) -> float | None:
        """The distance (m) from ``z`` to its target or track's position, whichever is nearer, when under
        :data:`NEAR_M`; else None."""
        d = [float(np.hypot(*(z - p))) for p in (self.target, self.at) if p is not None]
        return min(d) if d and min(d) < NEAR_M else None


def _log_likelihood(
    track: UuvTrack, t: float, z: np.ndarray, R: np.ndarray, take: bool = True
) -> tuple[float, float]:
    """Log-likelihood of ``z`` (covariance ``R``) at ``t`` under ``track`` moved on, and its Mahalanobis distance;
    with ``take`` the track then takes it."""
    x, P = track.predict(t, COURSE_ACCEL_MPS2)
    S = P[:2, :2] + R
    nu = z - x[:2]
    q = float(nu @ np.linalg.solve(S, nu))
    if take:
        track.update(t, z, R, 1.0, COURSE_ACCEL_MPS2)
    return -0.5 * (q + math.log(np.linalg.det(2.0 * math.pi * S))), math.sqrt(q)


@dataclass
class Encounter:
    """A UUV's target near another UUV's: both trusted tracks as they were (None: that UUV had none), and the
    evidence of the fixes of the lock weighed since (``llr``: nats for its own UUV over the other)."""

    other_id: str
    own: UuvTrack | None
    other: UuvTrack | None
    since_t: float
    llr: float = 0.0
    fixes: int = 0
    _filters: tuple | None = field(default=None, repr=False)

    def restart(self) -> None:
        """A new lock (or a fix its own hypothesis cannot explain): weigh from the kept tracks again."""
        self.llr, self.fixes, self._filters = 0.0, 0, None

    def weigh(
        self,
        t: float,
        z: np.ndarray,
        R: np.ndarray,
        toward_other_m: np.ndarray,
        limit: float,
        other_now: UuvTrack | None = None,
    ) -> None:
        """One fix of the lock (``R``: its frame-to-frame covariance, m²): at ``z`` if it is this UUV, at
        ``z + toward_other_m`` (its ray at the other's depth) if it is the other — where the other's kept track moved
        on says, or, while the other's own fixes are valid, where its current track ``other_now`` says. A fix further
        than ``limit`` sigma from its own hypothesis restarts the weighing with it."""
        if self.own is None or self.other is None:
            return
        if self._filters is None:
            self._filters = (copy.deepcopy(self.own), copy.deepcopy(self.other))
        own, own_q = _log_likelihood(self._filters[0], t, z, R)
        if own_q > limit and self.fixes:
            self.restart()
            return self.weigh(t, z, R, toward_other_m, limit, other_now)
        other, _ = _log_likelihood(self._filters[1], t, z + toward_other_m, R)
        if other_now is not None:
            other, _ = _log_likelihood(other_now, t, z + toward_other_m, R, take=False)
        self.llr += own - other
        self.fixes += 1

    def status(self) -> dict:
        return {
            "other": self.other_id,
            "since_t": round(self.since_t, 3),
            "fixes": self.fixes,
            "evidence": round(self.llr, 1),
            "needed": EVIDENCE,
        }


class Fleet:
    """The gates of the UUVs in one video, by UUV id (each joins with :meth:`join`)."""

    def __init__(self):
        self.gates: dict = {}

    def join(self, uuv_id: str, gate) -> None:
        self.gates[uuv_id] = gate

    def others(self, uuv_id: str, gate, t: float) -> list[Other]:
        """The other UUVs as ``gate`` (``uuv_id``'s) sees them at ``t``."""
        return [self._other(i, g, uuv_id, gate, t) for i, g in self.gates.items() if i != uuv_id]

    @staticmethod
    def shift_m(gate, to) -> np.ndarray:
        """What to add to a position in ``gate``'s frame to have it in ``to``'s (m north, east)."""
        if gate.ref is None or to.ref is None or gate.ref == to.ref:
            return np.zeros(2)
        n, e, _ = geodetic_to_ned(*gate.ref, 0.0, *to.ref, 0.0)
        return np.array([float(n), float(e)])

    def _other(self, uuv_id: str, gate, viewer_id: str, viewer, t: float) -> Other:
        shift = self.shift_m(gate, viewer)
        seen = gate.sighting
        enc = gate.encounter
        mine = enc is not None and enc.other_id == viewer_id and enc.llr <= -EVIDENCE
        target = seen.z + shift if seen and abs(t - seen.t) <= RECENT_S else None
        if (
            mine and target is not None and viewer.sighting is not None
        ):  # the same ray at the viewer's depth
            target = target + (viewer.sighting.depth_m - seen.depth_m) * seen.shift
        track = copy.deepcopy(gate.track) if gate.track is not None else None
        at = None
        valid = gate.state == "tracking" and abs(t - gate.valid_t) <= RECENT_S
        if track is not None:
            track.x[:2] += shift
            if gate.state == "tracking" and abs(t - track.t) <= RECENT_S:
                at = track.predict(t)[0][:2]
        depth_m = seen.depth_m if seen else math.nan
        if mine:
            return Other(uuv_id, None, at, depth_m, track, valid, target)
        return Other(uuv_id, target, at, depth_m, track, valid)

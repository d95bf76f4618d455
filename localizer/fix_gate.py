"""Safety gates: which ``ok`` fixes may be sent to a vehicle as a valid position, judged against a track.

A fix that reaches a UUV's autopilot moves its EKF; a wrong one (the tracker on a
glint, on the UUV's shadow, on another vehicle) is worse than none. :class:`FixGate`
keeps a track of the UUV (:class:`~localizer.uuv_track.UuvTrack`: its fixes filtered
with constant velocity, the vehicle's top speed and acceleration) and lets a fix through
only when every test passes; otherwise it names the first that failed:

- ``h_acc``: its horizontal accuracy ``h_acc_m`` is not finite or above ``max_h_acc_m``
  (default 2.5 m, EKF3's own alignment limit hdop ≤ 2.5 with skyfix's 1 m per unit of hdop);
- ``age``: it is older than ``max_age_s`` when offered (``now − t_unix``);
- ``out_of_order``: its exposure is not after the last fix the gate took;
- ``clock``: the frame's exposure and its arrival disagree by more than :data:`CLOCK_TOL_S` with what they were
  (a clock mapped onto the station's stepped: see *Time* below);
- ``prediction``: its pixel lies outside the window where the telemetry's prediction had
  the tracker look (the frame's ``window``; a tracker that ignores the prediction, such as
  OpenCV's, can report a match anywhere);
- ``innovation``: while tracking, it lies more than :data:`GATE_SIGMAS` beyond where the
  track's UUV can be (:meth:`~localizer.uuv_track.UuvTrack.distance`: within its top speed
  of the track's position and within its acceleration bound of that position moved on with
  the velocity; what lies beyond, over a covariance that is the track's own plus the
  *white* part of the fix's — the part that changes from frame to frame, measured on the
  fixes (:class:`~localizer.uuv_track.Scatter`) — not the whole claimed accuracy, most of
  which is an error every frame shares: see :mod:`localizer.uuv_track`). After frames
  without a fix (telemetry or depth missing, the video stopped) while the tracker kept the
  target, the same test holds with the bounds grown by the gap;
- ``diverged``: the fixes left the track — refused for longer than :data:`HOLD_S` — or the
  tracker found a target again where the UUV cannot be (the first fix after a loss out of
  reach, below): the tracker follows something else. Every fix is refused for
  :data:`DIVERGED_S`, or until the tracker reports the target lost (a release, a new
  acquisition), then the gate acquires again;
- ``reach``: while acquiring, the same test against the last good track: the UUV can have
  gone the top speed times the time since — at most ``max_reach_m`` (default
  :data:`MAX_REACH_M`), however long since: waiting does not make a far target the UUV — and
  the fixes' shared error can have changed too. The gate does not forget where the UUV was:
  a new lock — a target found again after a loss, an operator's selection, the lock after
  two trackers were on one vehicle (``same_vehicle``), the first after a restart with the
  track kept on disk (:meth:`FixGate.memory`, :meth:`FixGate.remember`) — whose first fix is
  out of reach is another object (``diverged``: none of that lock's fixes goes out, however
  long, until the tracker reports the target lost or the operator confirms it,
  :meth:`FixGate.confirm`); a later fix out of reach starts the confirmation over;
- ``unconfirmed``: while acquiring (the first target, after the tracker lost it or it was
  released, after ``diverged``): a fix of a candidate chain not yet :data:`CONFIRM_S` (and
  :data:`CONFIRM_FIXES` fixes) long. Each chain fix must agree with the chain's own track
  (innovation) and lie within reach; one that does not is left out, and after
  :data:`CHAIN_MISSES` such in a row the next starts a new chain. When the chain is long
  enough it is checked once more with the white share measured over it, and becomes the
  track;
- ``exchanged`` (several UUVs in one video, each gate joined to one
  :class:`~localizer.exchange.Fleet`): the target came near another UUV's, and which vehicle it is has not been told
  yet — the other is on top or at about its depth while they are near, or, once they have parted, the fixes since do
  not follow this UUV's own track, at its own depth, by enough evidence over the other's at the other's depth (see
  :mod:`localizer.exchange`). The operator's confirmation ends it.

The acceleration bound is the vehicle's (``max_accel_mps2``) unless a second source says it
is not pushing: with ``thrusters`` (:class:`~localizer.thrusters.Thrusters`, the UUV's
autopilot's outputs) idle from the track's last fix until now, the bound over that step is
what the water and the drag can do (:func:`~localizer.thrusters.idle_accel_mps2`, with
``water_accel_mps2``, default :data:`WATER_ACCEL_MPS2`), for the track's speed plus two sigma.

What the fixes alone cannot tell, measured (``bench/gate_streams.py``): a UUV starting to move
from a tracker starting to drift, unless the start is faster than the UUV can make it. A
ramp starting abruptly at 0.35 m/s (the issue's: 0.7 m in 2 s) is 2 cm ahead of a BlueROV2
starting at its acceleration bound (3 m/s²), and a motion within the bound follows it to
4 mm: without the thrusters' word it passes, as the real start must. An abrupt start at top
speed (7 cm from any motion within the bound) is refused from its third frame until the
track's UUV could have caught up with it (about 0.5 s). With the thrusters idle the same
ramp, and any drift faster than the water moves the UUV, is refused within a few frames and
the gate is ``diverged`` half a second later. A look-alike found after a loss where the UUV
could be by then, and consistent for a second, is taken. Drifts and look-alikes are also
the tracker's to catch (its match against the UUV's first appearance).

Time: offered with the arrival of its frame (:class:`Arrival`: its station-clock and monotonic
times, and the monotonic time now), a fix's time on the gate's own base is its monotonic arrival
less the exposure-to-arrival gap measured on the station clock; its age is the monotonic time
since that. A step of the station clock (the station-clock minus monotonic offset changing by
more than :data:`CLOCK_STEP_S` from one frame to the next) is counted and changes nothing: the
time between fixes, which the bounds grow with, is monotonic, so a step never widens a gate. A
frame whose exposure-to-arrival gap jumps by more than :data:`CLOCK_TOL_S` (its exposure comes
from a clock mapping that did not step with the station's) is refused (``clock``), and starts a
new lock. Without an arrival (offline, the fuser) the exposure times are the base.

Pure computation; times are station-clock UNIX seconds (the gate's base: the station clock as it was
at the first fix); the local frame is metres north and east of the first fix the gate saw.
"""

from __future__ import annotations

import copy
import math
from collections import Counter
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .exchange import DEPTH_APART_M, EVIDENCE, SAME_SPOT_M, Encounter, Fleet, Sighting, depth_shift
from .fix import Fix, Fixes
from .geodesy import geodetic_to_ned, ned_to_geodetic
from .thrusters import STALE_S, Thrusters, idle_accel_mps2
from .uuv_track import Scatter, UuvTrack, fix_covariance_m2

#: A fix further than this many sigmas from the track (innovation, reach) is refused.
GATE_SIGMAS = 5.0
#: Fixes refused by the track (innovation, prediction) for longer than this (s): the gate is ``diverged``.
HOLD_S = 0.5
#: A new or re-acquired target is valid after a chain of consistent fixes at least this long (s) ...
CONFIRM_S = 1.0
#: ... of at least this many fixes.
CONFIRM_FIXES = 10
#: A chain goes on past this many fixes in a row that disagree with it (refused); one more starts a new chain.
CHAIN_MISSES = 2
#: ``diverged`` (fixes that left the track, a target found again out of reach) lasts this long (s) unless the
#: tracker reports the target lost.
DIVERGED_S = 5.0
#: Top speeds (m/s) of vehicle classes, for ``--uuv-max-speed-mps``'s default.
MAX_SPEED_MPS = {"bluerov2": 1.5}
#: Horizontal accelerations (m/s²) vehicle classes can reach, for ``--uuv-max-accel-mps2``'s default. A
#: BlueROV2: the thrust that holds its top speed, 4.03·1.5 + 18.18·1.5² = 47 N by the surge damping Wu
#: (2018) identified, over its mass with the added mass, 11.5 + 5.5 kg: 2.8 m/s² from rest (sway: 58 N
#: over 24 kg, 2.4 m/s²). ArduSub's position modes ask for less: POSHOLD PILOT_ACCEL_Z (1 m/s²),
#: AUTO and GUIDED WPNAV_ACCEL (2.5 m/s²).
MAX_ACCEL_MPS2 = {"bluerov2": 3.0}
#: What the water can do to a UUV whose thrusters are idle (m/s²): sheltered shallow water, a slack tether — a current
#: that changes by 0.5 m/s within 10 s (a current itself is a velocity, which the track follows). Waves move a vehicle
#: near the surface by their orbital acceleration (ω·u: 0.3–0.5 m/s² for 0.2 m waves of 3–4 s over 2 m of water): set
#: ``--uuv-water-accel-mps2`` to it there, or a UUV rocked by the waves is refused (no fix, never a wrong one).
WATER_ACCEL_MPS2 = 0.05
#: However long since the last trusted fix, a new lock's first fix further than this (m) from the track (and its
#: shared error's change) is not the UUV: a BlueROV2's second at top speed. ``--uuv-max-reach-m``.
MAX_REACH_M = 1.5
#: A change of the station clock against the monotonic clock larger than this (s) from one frame to the next is a step
#: (NTP slews at most 0.5 ms/s).
CLOCK_STEP_S = 0.05
#: A frame whose exposure-to-arrival gap (station clock) differs from the previous frame's by more than this (s) is
#: refused (``clock``): network and reader delays vary by less.
CLOCK_TOL_S = 1.0
REASONS = (
    "h_acc",
    "age",
    "out_of_order",
    "clock",
    "prediction",
    "innovation",
    "diverged",
    "reach",
    "unconfirmed",
    "exchanged",
)
STATES = ("acquiring", "tracking", "diverged")


class Arrival(NamedTuple):
    """When a fix's frame arrived, on the station clock (``t_recv_unix``, UNIX s) and on the monotonic clock
    (``t_recv_mono``, s), and the monotonic time the fix is offered at (``now_mono``)."""

    t_recv_unix: float
    t_recv_mono: float
    now_mono: float


@dataclass(frozen=True)
class _Seen:
    """A fix in the gate's local frame."""

    t: float
    z: np.ndarray  # north, east (m)
    C: np.ndarray  # its covariance (m²)


def gate_offline(fixes: Fixes, lost: np.ndarray, gate: FixGate) -> np.ndarray:
    """The gate over a whole recording, where no vehicle waits: what it says of each frame's fix, with the fixes
    that the frames after them confirmed taken (an object array: None for a fix taken, the reason for one
    refused, "" for a frame without a fix).

    The fixes go through ``gate`` in time order, each offered at its own exposure (no age); ``lost``: the frames
    whose tracker lost the target (a re-acquisition follows). Live, a new or re-acquired target's fixes are
    ``unconfirmed`` until its chain is :data:`CONFIRM_S` long; offline the chain that the confirmation makes the
    track is taken whole, its first fixes included. Fixes left out of a chain (they disagreed with it), and every
    other refusal, stay refused.
    """
    word = np.full(len(fixes), "", dtype=object)
    at = {}
    order = np.argsort(fixes.t_unix, kind="stable")
    ok = order[fixes.status[order] == "ok"]
    each = dict(zip(ok.tolist(), fixes.each(ok)))
    ne_m = None  # every frame's north and east of the gate's origin, once it has one (m)
    for i in order.tolist():
        if lost[i]:
            gate.target_lost()
        if i not in each:
            continue
        t = each[i].t_unix
        at[t] = i
        word[i] = gate.check(each[i], t, ne_m=None if ne_m is None else ne_m[i])
        if ne_m is None and gate.ref is not None:
            n, e, _ = geodetic_to_ned(fixes.lat, fixes.lon, 0.0, *gate.ref, 0.0)
            ne_m = np.column_stack([n, e])
        if gate.confirmed_t:
            word[[at[t] for t in gate.confirmed_t]] = None
            gate.confirmed_t = ()
    return word


def gate_together(
    fixes: dict[str, Fixes], lost: dict[str, np.ndarray], gates: dict[str, FixGate]
) -> dict[str, np.ndarray]:
    """Several UUVs' fixes of one recording, by UUV id, through their gates (joined to one
    :class:`~localizer.exchange.Fleet`), frame by frame in time order as live: per UUV what its gate says of each
    frame's fix when offered (None taken, the reason refused, "" no fix; no confirmation taken back, unlike
    :func:`gate_offline`). ``lost``: each UUV's frames whose tracker lost the target."""
    words = {k: np.full(len(f), "", dtype=object) for k, f in fixes.items()}
    order = sorted(
        (float(f.t_unix[i]), n, k, i)
        for n, (k, f) in enumerate(fixes.items())
        for i in range(len(f))
    )
    for t, _, k, i in order:
        if lost[k][i]:
            gates[k].target_lost()
        if fixes[k].status[i] == "ok":
            words[k][i] = gates[k].check(fixes[k][i], t)
    return words


def in_window(fix: Fix, window) -> bool:
    """Whether the fix's pixel lies in ``window`` (x, y, w, h; None: no prediction, nothing to check)."""
    if window is None:
        return True
    x, y, w, h = window
    return x <= fix.u <= x + w and y <= fix.v <= y + h


class FixGate:
    """The gates of the module doc; :attr:`rejected` counts refusals by reason, :attr:`accepted` the rest.

    ``judge_track=False``: only ``h_acc``, ``age`` and ``out_of_order`` — for fixes whose every input was judged
    against its own track already (``skyfix fuse``'s, :mod:`groundstation.fuse`).
    """

    def __init__(
        self,
        max_speed_mps: float = MAX_SPEED_MPS["bluerov2"],
        max_accel_mps2: float = MAX_ACCEL_MPS2["bluerov2"],
        max_h_acc_m: float = 2.5,
        max_age_s: float = 0.5,
        confirm_s: float = CONFIRM_S,
        confirm_fixes: int = CONFIRM_FIXES,
        thrusters: Thrusters | None = None,
        water_accel_mps2: float = WATER_ACCEL_MPS2,
        judge_track: bool = True,
        max_reach_m: float = MAX_REACH_M,
        fleet: Fleet | None = None,
        uuv_id: str = "",
    ):
        self.judge_track = judge_track
        self.fleet, self.uuv_id = fleet, uuv_id
        self.sighting: Sighting | None = None  # the newest target (:mod:`localizer.exchange`)
        # the target came near another UUV's: not told apart yet
        self.encounter: Encounter | None = None
        self.valid_t = -math.inf  # the last valid fix (the gate's base)
        if fleet is not None:
            fleet.join(uuv_id, self)
        self.max_reach_m = max_reach_m
        self.max_speed_mps = max_speed_mps
        self.max_accel_mps2 = max_accel_mps2
        self.max_h_acc_m = max_h_acc_m
        self.max_age_s = max_age_s
        self.confirm_s = confirm_s
        self.confirm_fixes = confirm_fixes
        self.thrusters = thrusters
        self.water_accel_mps2 = water_accel_mps2
        self.accel_bound_mps2: float | None = None  # the bound of the last step judged
        self._now = -math.inf
        self.state = "acquiring"
        self.state_since_t: float | None = None
        # the last confirmed track: while acquiring, where the UUV was
        self.track: UuvTrack | None = None
        self.scatter = Scatter()
        self._ref: tuple[float, float] | None = None  # lat, lon of the local frame's origin
        self._chain: list[_Seen] = []
        self._chain_track: UuvTrack | None = None
        self._chain_misses = 0  # fixes in a row that disagreed with the chain
        # tracking: the first refused fix since the last accepted
        self._refusing_since: float | None = None
        self._diverged_until = -math.inf
        self._last_t = -math.inf
        self._new_lock = True  # the next ok fix is the first of the tracker's lock (after a loss)
        self._foreign = False  # this lock began where the UUV cannot be: none of its fixes goes out
        self._operator_lock = False  # the operator confirmed this lock: no reach test until it ends
        self._shift = 0.0  # the station clock's steps since the first arrival (s): a fix's time is t_unix − this
        self._base: float | None = None  # station minus monotonic clock (s) at the first arrival
        self._offset: float | None = None  # ... and at the last
        # the last frame's exposure-to-arrival gap on the station clock (s)
        self._gap: float | None = None
        self.clock_steps = 0
        self.last_clock_step_s: float | None = None
        self.confirmed_t: tuple[
            float, ...
        ] = ()  # the exposures of the chain the last confirmation made the track
        self.accepted = 0
        self.rejected: Counter[str] = Counter()
        self.last_refusal: str | None = None

    # -- the interface -------------------------------------------------------------------------
    @property
    def ref(self) -> tuple[float, float] | None:
        """The local frame's origin (lat, lon; None before the first fix)."""
        return self._ref

    def check(
        self,
        fix: Fix,
        now: float,
        window=None,
        arrival: Arrival | None = None,
        ne_m: np.ndarray | None = None,
    ) -> str | None:
        """None if ``fix`` (status ok) may go out as valid, else the reason; counts either way.

        ``now``: the station clock (UNIX s) when offered; ``window``: (x, y, w, h) pixels where the telemetry's
        prediction had the tracker look for this frame, or None; ``arrival``: when its frame arrived (the gate's
        time base, see the module doc), or None; ``ne_m``: the fix's north and east of the gate's :attr:`ref` (m),
        when the caller computed them (offline, for every fix at once), or None.
        """
        reason = self._reason(fix, now, window, arrival, ne_m)
        if reason is None:
            self.accepted += 1
            self.valid_t = self._last_t
        else:
            self.rejected[reason] += 1
        return reason

    def target_lost(self) -> None:
        """The tracker lost the target (or it was released, or the operator selected one, or two trackers were on one
        vehicle): the next fixes are a re-acquisition, a new lock, judged against the last trusted track."""
        self._enter("acquiring", self._last_t if math.isfinite(self._last_t) else None)
        self._new_lock = True
        self._foreign = self._operator_lock = False
        if self.encounter is not None:
            self.encounter.restart()

    def confirm(self) -> dict:
        """The operator says the target tracked now is the UUV: this lock's fixes are confirmed as a first target's
        are (a second of consistent fixes) without the reach test, and then replace the track. Ends with the lock
        (a loss, a release, a selection); and that it is this UUV, whichever other came near. What it did, JSON-ready."""
        if self.encounter is not None:
            self.encounter, self._operator_lock = None, True
            if self.state == "tracking":
                return {
                    "confirmed": True,
                    "why": "the target is this UUV, whichever other UUV came near",
                }
        if self.state == "tracking":
            return {"confirmed": False, "why": "the gates track the target already"}
        self._operator_lock, self._foreign = True, False
        if self.state == "diverged":
            self._enter("acquiring", self._last_t if math.isfinite(self._last_t) else None)
        self._new_lock = False
        self.last_refusal = (
            "unconfirmed: the operator confirmed the target; its fixes are being confirmed"
        )
        return {
            "confirmed": True,
            "why": f"the target's fixes are valid after {self.confirm_s:g} s of consistent "
            "fixes, whatever the last trusted track",
        }

    def memory(self, now: float) -> dict | None:
        """The last trusted track, JSON-ready, for :meth:`remember` after a restart (None before the first): its
        position (lat, lon), velocity, covariances (the track's own ``P``, the newest fix's ``C`` and its shared
        part ``common``), time ``t`` (the gate's base, UNIX s) and age at ``now`` (station clock, UNIX s)."""
        tr = self.track
        if tr is None:
            return None
        lat, lon, _ = ned_to_geodetic(tr.x[0], tr.x[1], 0.0, *self._ref, 0.0)
        return {
            "t": float(tr.t),
            "lat": float(lat),
            "lon": float(lon),
            "vn_mps": float(tr.x[2]),
            "ve_mps": float(tr.x[3]),
            "P": tr.P.tolist(),
            "C": tr.C.tolist(),
            "common": tr.common.tolist(),
            "age_s": max(0.0, float(now - self._shift - tr.t)),
        }

    def remember(self, memory: dict, t: float) -> None:
        """Start from a track kept by :meth:`memory` (a restart): ``t`` is its time on this gate's base (the station
        clock now less its age). The gate acquires: the first lock must be within reach of it."""
        self._ref = (float(memory["lat"]), float(memory["lon"]))
        C = np.array(memory["C"], dtype=float)
        track = UuvTrack(
            self.max_speed_mps, self.max_accel_mps2, t, np.zeros(2), C, 1.0, self.max_reach_m
        )
        track.x = np.array([0.0, 0.0, float(memory["vn_mps"]), float(memory["ve_mps"])])
        track.P = np.array(memory["P"], dtype=float)
        track.common = np.array(memory["common"], dtype=float)
        self.track = track
        self.target_lost()

    # -- the tests -----------------------------------------------------------------------------
    def _reason(
        self, fix: Fix, now: float, window, arrival: Arrival | None, ne_m: np.ndarray | None
    ) -> str | None:
        t, age, stepped = self._time(fix, now, arrival)
        self._now = now
        if not (math.isfinite(fix.h_acc_m) and fix.h_acc_m <= self.max_h_acc_m):
            return self._refuse(
                t, "h_acc", f"h_acc {fix.h_acc_m:.2f} m above {self.max_h_acc_m:g} m"
            )
        if stepped:
            self.target_lost()
            self.last_refusal = f"clock: {stepped}"
            return "clock"
        if not age <= self.max_age_s:
            return self._refuse(t, "age", f"{age:.2f} s old when offered")
        if t <= self._last_t:
            return "out_of_order"
        if not self.judge_track:
            self._last_t = t
            return None
        if not in_window(fix, window):
            return self._refuse(
                t,
                "prediction",
                f"pixel ({fix.u:.0f}, {fix.v:.0f}) outside the window the telemetry predicted",
                leaves_track=True,
            )
        seen = self._local(fix, t, ne_m)
        if self.fleet is not None and (why := self._exchange(fix, seen)):
            return self._refuse(seen.t, "exchanged", why)
        if self.state == "diverged":
            if seen.t < self._diverged_until:
                return "diverged"
            self._enter("acquiring", seen.t)
        if self.state == "tracking":
            return self._track_step(seen)
        return self._chain_step(seen)

    def _time(
        self, fix: Fix, now: float, arrival: Arrival | None
    ) -> tuple[float, float, str | None]:
        """The fix's time on the gate's base, its age when offered (s), and what stepped (None: nothing).

        With its frame's ``arrival``: the exposure less the station clock's change against the monotonic clock
        since the first arrival (slews and steps: the exposure is stamped on the station clock), or, when the
        exposure-to-arrival gap jumped (the exposure's clock did not step with the station's), as the previous one
        moved on with the monotonic arrivals; the age is monotonic."""
        if arrival is None:
            return fix.t_unix, now - fix.t_unix, None
        offset = arrival.t_recv_unix - arrival.t_recv_mono
        gap = arrival.t_recv_unix - fix.t_unix
        stepped = None
        if self._base is None:
            self._base = self._offset = offset
        else:
            d_offset, d_gap = offset - self._offset, gap - self._gap
            if (
                abs(d_gap) > CLOCK_TOL_S
            ):  # the exposure did not move with the arrival: its clock kept its course
                self._shift += d_offset - d_gap
                stepped = (
                    f"the frame's exposure moved {d_offset - d_gap:+.2f} s against its arrival's "
                    f"{d_offset:+.2f} s on the station clock (the gates keep to the monotonic clock)"
                )
            else:
                self._shift += d_offset
            if abs(d_offset) > CLOCK_STEP_S:
                self.clock_steps += 1
                self.last_clock_step_s = d_offset
                stepped = (
                    f"the station clock stepped {d_offset:+.2f} s (the gates keep to the monotonic clock); "
                    "the target is confirmed again"
                )
        self._offset, self._gap = offset, gap
        t = fix.t_unix - self._shift
        return t, arrival.now_mono + self._base - t, stepped

    def _refuse(self, t: float, reason: str, why: str, leaves_track: bool = False) -> str:
        """A refusal that breaks a chain; ``leaves_track``: the fix is not where the track is — tracking, once such
        refusals have gone on for longer than :data:`HOLD_S`, the gate is ``diverged``."""
        self.last_refusal = f"{reason}: {why}"
        self._chain.clear()
        if not (leaves_track and self.state == "tracking"):
            return reason
        if self._refusing_since is None:
            self._refusing_since = t
        elif t - self._refusing_since > HOLD_S:
            left = self._refusing_since
            self._diverged_until = left + DIVERGED_S
            self._enter("diverged", t)
            self.last_refusal = (
                f"diverged: the fixes left the track {t - left:.1f} s ago ({why}); refused until "
                f"{DIVERGED_S:g} s after that, or until the target is lost or released"
            )
            return "diverged"
        return reason

    def _exchange(self, fix: Fix, f: _Seen) -> str | None:
        """Why ``fix`` may be another UUV's target (:mod:`localizer.exchange`), or None."""
        shift = depth_shift(fix.north_m, fix.east_m, fix.height_m, fix.depth_m)
        self.sighting = Sighting(f.t, f.z, fix.depth_m, shift)
        others = {o.uuv_id: o for o in self.fleet.others(self.uuv_id, self, f.t)}
        if any(
            o.on_viewer is not None and np.hypot(*(o.on_viewer - f.z)) < SAME_SPOT_M
            for o in others.values()
        ):
            # another UUV's tracker on this one, as its gate found: this is this UUV
            self.encounter = None
            return None
        enc = self.encounter
        if enc is None:
            near = [(d, o) for o in others.values() if (d := o.near(f.z)) is not None]
            if not near or self._operator_lock:
                return None
            o = min(near, key=lambda p: p[0])[1]
            track = copy.deepcopy(self.track)
            enc = self.encounter = Encounter(o.uuv_id, track, o.track, f.t)
        other = others[enc.other_id]
        below_m = other.depth_m - fix.depth_m
        toward = below_m * shift if math.isfinite(below_m) else np.zeros(2)
        R = UuvTrack.white_m2(f.C, self.scatter.share)
        enc.weigh(f.t, f.z, R, toward, GATE_SIGMAS, other.track if other.valid else None)
        apart = other.near(f.z)
        if apart is not None:
            if below_m >= DEPTH_APART_M:
                return None  # on top: the other is hidden under it
            return (
                f"{apart:.2f} m from {other.uuv_id}'s target at {fix.depth_m:.2f} m to its {other.depth_m:.2f} m "
                f"deep: which is which is not known while they are this near"
            )
        if enc.llr >= EVIDENCE:
            self.encounter = None
            return None
        return (
            f"since {other.uuv_id} came near, the target's {enc.fixes} fixes say {enc.llr:+.1f} nats that it is "
            f"{self.uuv_id or 'this UUV'}, not {other.uuv_id} ({EVIDENCE:g} needed, or the operator's confirmation)"
        )

    def _track_step(self, f: _Seen) -> str | None:
        share = self.scatter.share
        a = self._accel(self.track)
        d = self.track.sigmas(f.t, f.z, f.C, share, a)
        if d > GATE_SIGMAS:
            idle = f", its thrusters idle: {a:.2f} m/s²" if a < self.max_accel_mps2 else ""
            return self._refuse(
                f.t,
                "innovation",
                f"{d:.1f} sigma beyond where the UUV can be "
                f"{f.t - self.track.t:.2f} s after the track's last fix (gate {GATE_SIGMAS:g}{idle})",
                leaves_track=True,
            )
        self.track.update(f.t, f.z, f.C, share, a)
        self.scatter.add(f.t, f.z, f.C)
        self._refusing_since = None
        self._last_t = f.t
        return None

    def _chain_step(self, f: _Seen) -> str | None:
        share = self.scatter.share
        why = self._out_of_reach(f, share)
        first_of_lock, self._new_lock = self._new_lock, False
        if (
            why and first_of_lock
        ):  # the tracker locked onto something where the UUV cannot be: not the UUV
            self._diverged_until = math.inf
            self._foreign = True
            self._enter("diverged", f.t)
            self.last_refusal = (
                f"diverged: the target found is not the UUV: {why}; refused until the target is "
                "lost or released, or the operator confirms it"
            )
            return "diverged"
        if why:
            self.last_refusal = f"reach: {why}"
            self._chain.clear()
            self.scatter.restart()
            return "reach"
        self._last_t = f.t
        a = self._accel(self._chain_track) if self._chain else None
        if self._chain and self._chain_track.sigmas(f.t, f.z, f.C, share, a) <= GATE_SIGMAS:
            self._chain.append(f)
            self._chain_track.update(f.t, f.z, f.C, share, a)
            self._chain_misses = 0
        elif (
            self._chain and self._chain_misses < CHAIN_MISSES
        ):  # one stray fix does not start the chain over
            self._chain_misses += 1
            return "unconfirmed"
        else:
            self._chain = [f]
            self._chain_track = self._new_track(f, share)
            self._chain_misses = 0
            self.scatter.restart()
        self.scatter.add(f.t, f.z, f.C)
        if f.t - self._chain[0].t >= self.confirm_s and len(self._chain) >= self.confirm_fixes:
            track, failed = self._replay(self._chain, self.scatter.share)
            if failed is None:
                self.track = track
                self.confirmed_t = tuple(s.t for s in self._chain)
                self._enter("tracking", f.t)
                return None
            self._chain = self._chain[failed:]
            self._chain_track = self._replay(self._chain, self.scatter.share, check=False)[0]
        return "unconfirmed"

    def _replay(
        self, chain: list[_Seen], share: float, check: bool = True
    ) -> tuple[UuvTrack, int | None]:
        """The chain's track, and the index of the first fix that fails (reach, innovation) with ``share``."""
        track = self._new_track(chain[0], share)
        for i, f in enumerate(chain):
            a = self._accel(track)
            if check and (
                self._out_of_reach(f, share)
                or (i and track.sigmas(f.t, f.z, f.C, share, a) > GATE_SIGMAS)
            ):
                return track, max(i, 1)
            if i:
                track.update(f.t, f.z, f.C, share, a)
        return track, None

    def _out_of_reach(self, f: _Seen, share: float) -> str | None:
        """Why the UUV cannot be at ``f`` given the last good track (None: it can, or there is none, or the operator
        confirmed this lock)."""
        if self.track is None or self._operator_lock:
            return None
        d, radius, margin = self.track.distance(f.t, f.z, f.C, share, self._accel(self.track))
        if d <= GATE_SIGMAS:
            return None
        return (
            f"{d:.1f} sigma beyond where the UUV can be {f.t - self.track.t:.1f} s after the last good fix "
            f"(it can have moved {radius:.2f} m; 1 sigma {margin:.2f} m)"
        )

    def _accel(self, track: UuvTrack) -> float:
        """The acceleration bound (m/s²) from ``track``'s last fix until now: the water's and the drag's while the
        thrusters were idle all along, else the vehicle's. A track filtered with the idle bound whose thrusters
        push now is widened by :data:`~localizer.thrusters.STALE_S` of the vehicle's: the push can have begun that
        long before its first output arrived."""
        a = self.max_accel_mps2
        idle = self.thrusters is not None and self.thrusters.idle_since(
            track.t + self._shift, self._now
        )
        if idle:
            speed = math.hypot(track.x[2], track.x[3]) + 2.0 * math.sqrt(
                max(track.P[2, 2], track.P[3, 3])
            )
            a = min(a, idle_accel_mps2(speed, self.water_accel_mps2))
        elif track.tight:
            track.widen(STALE_S)
        track.tight = idle
        self.accel_bound_mps2 = a
        return a

    def _new_track(self, f: _Seen, share: float) -> UuvTrack:
        return UuvTrack(
            self.max_speed_mps, self.max_accel_mps2, f.t, f.z, f.C, share, self.max_reach_m
        )

    def _local(self, fix: Fix, t: float, ne_m: np.ndarray | None) -> _Seen:
        """The fix in the local frame at ``t`` (the gate's base); ``ne_m``: its north and east (m), if known."""
        if self._ref is None:
            self._ref = (fix.lat, fix.lon)
        n, e = geodetic_to_ned(fix.lat, fix.lon, 0.0, *self._ref, 0.0)[:2] if ne_m is None else ne_m
        C = fix_covariance_m2(fix.sigma_n_m, fix.sigma_e_m, fix.cov_ne_m2, fix.h_acc_m)
        return _Seen(t, np.array([float(n), float(e)]), C)

    def _enter(self, state: str, t: float | None) -> None:
        self._chain.clear()
        self._refusing_since = None
        if state != "tracking":
            self.scatter.restart()
        self.state, self.state_since_t = state, t

    # -- the status ----------------------------------------------------------------------------
    def status(self, now: float) -> dict:
        """JSON-ready: the limits, the state, refusals by reason, the chain being confirmed and the track."""

        def num(x, digits=3):
            return round(float(x), digits) if x is not None and math.isfinite(x) else None

        out = {
            "max_speed_mps": self.max_speed_mps,
            "max_accel_mps2": self.max_accel_mps2,
            "max_h_acc_m": self.max_h_acc_m,
            "max_age_s": self.max_age_s,
            "state": self.state,
            "state_since_t": num(self.state_since_t),
            "accepted": self.accepted,
            "rejected": {r: self.rejected[r] for r in REASONS},
            "last_refusal": self.last_refusal,
            "white_share": num(self.scatter.share, 4) if self.scatter.samples else None,
            "diverged_until_t": num(self._diverged_until) if self.state == "diverged" else None,
            "chain": None,
            "track": None,
            "reach_m": None,
            "thrusters": self.thrusters.state(now) if self.thrusters is not None else None,
            "accel_bound_mps2": num(self.accel_bound_mps2),
            "max_reach_m": num(self.max_reach_m),
            "operator_confirmed": self._operator_lock,
            "clock_steps": self.clock_steps,
            "last_clock_step_s": num(self.last_clock_step_s),
            "exchange": self.encounter.status() if self.encounter is not None else None,
        }
        if self._chain:
            out["chain"] = {
                "fixes": len(self._chain),
                "span_s": num(self._chain[-1].t - self._chain[0].t),
                "needed_s": self.confirm_s,
            }
        tr = self.track
        if tr is None:
            return out
        lat, lon, _ = ned_to_geodetic(tr.x[0], tr.x[1], 0.0, *self._ref, 0.0)
        A = tr.absolute_m2()
        now = now - self._shift  # on the gate's base
        out["track"] = {
            "t": num(tr.t),
            "age_s": num(now - tr.t),
            "lat": num(lat, 8),
            "lon": num(lon, 8),
            "vn_mps": num(tr.x[2]),
            "ve_mps": num(tr.x[3]),
            "sigma_n_m": num(math.sqrt(A[0, 0])),
            "sigma_e_m": num(math.sqrt(A[1, 1])),
            "cov_ne_m2": num(A[0, 1], 5),
            "sigma_own_m": num(math.sqrt(tr.P[0, 0] + tr.P[1, 1])),
            "sigma_vn_mps": num(math.sqrt(tr.P[2, 2])),
            "sigma_ve_mps": num(math.sqrt(tr.P[3, 3])),
        }
        if self.state != "tracking":
            out["reach_m"] = num(tr.reach_m(now))
        return out

"""Safety gates: which ``ok`` fixes may be sent to a vehicle as a valid position.

A fix that reaches a UUV's autopilot moves its EKF; a wrong one (the tracker on a
glint, a telemetry glitch) is worse than none. :class:`FixGate` lets a fix through
only when every test passes, and otherwise names the first that failed:

- ``h_acc``: its horizontal accuracy ``h_acc_m`` is not finite or above ``max_h_acc_m``
  (default 2.5 m, EKF3's own alignment limit hdop ≤ 2.5 with skyfix's 1 m per unit of hdop);
- ``age``: it is older than ``max_age_s`` when offered (``now − t_unix``; the same limit
  after which the sender stops repeating it);
- ``out_of_order``: its exposure is not after the last accepted fix's;
- ``jump``: it is further from the last accepted fix than the UUV can have moved:
  ``max_speed_mps · Δt + K_SIGMA · √(h_acc₁² + h_acc₂²)`` (each fix's own 1-sigma
  error, :data:`K_SIGMA` of them; default speed 1.5 m/s, a BlueROV2's top speed);
- ``unconfirmed``: there is no reference to compare with — the first fix, the first
  after a loss of the track (:meth:`FixGate.reset`), or the first after
  ``reference_s`` without an accepted fix (past a second the speed bound is too loose
  to tell a wrong fix from a move). Such a fix starts a candidate chain and is held
  back; once :data:`CONFIRM` consecutive fixes each pass the jump test against the
  one before, the last is accepted and becomes the reference. One stray fix (a single
  false match) is then never sent, at the cost of two frames' delay (~70 ms at 30 fps)
  after a loss; a fix rejected by another test breaks the chain.

A fix failing ``jump`` against an established reference also starts a candidate
chain: if the vehicle really is there (the reference was the wrong one), the chain
confirms it and the gate follows after :data:`CONFIRM` fixes, instead of rejecting
every fix for ever. Pure computation; times are station-clock UNIX seconds.
"""

from __future__ import annotations

import math
from collections import Counter

from .fix import Fix

K_SIGMA = 3.0
CONFIRM = 3
#: Top speeds (m/s) of vehicle classes, for ``--uuv-max-speed-mps``'s default.
MAX_SPEED_MPS = {"bluerov2": 1.5}
_M_PER_DEG = math.pi / 180.0 * 6_371_000.0
REASONS = ("h_acc", "age", "out_of_order", "jump", "unconfirmed")


def distance_m(a: Fix, b: Fix) -> float:
    """Horizontal distance (m) between two fixes a few metres apart (equirectangular)."""
    dn = (a.lat - b.lat) * _M_PER_DEG
    de = (a.lon - b.lon) * _M_PER_DEG * math.cos(math.radians((a.lat + b.lat) / 2.0))
    return math.hypot(dn, de)


class FixGate:
    """The gates of the module doc; :attr:`rejected` counts rejections by reason, :attr:`accepted` the rest."""

    def __init__(self, max_speed_mps: float = MAX_SPEED_MPS["bluerov2"], max_h_acc_m: float = 2.5,
                 max_age_s: float = 0.5, reference_s: float = 1.0):
        self.max_speed_mps = max_speed_mps
        self.max_h_acc_m = max_h_acc_m
        self.max_age_s = max_age_s
        self.reference_s = reference_s
        self.reference: Fix | None = None
        self._chain: list[Fix] = []
        self.accepted = 0
        self.rejected: Counter[str] = Counter()

    def reset(self) -> None:
        """The track was lost: the next fix needs confirming."""
        self.reference = None
        self._chain.clear()

    def consistent(self, a: Fix, b: Fix) -> bool:
        """Whether ``b`` is within reach of ``a`` (the jump test)."""
        dt = max(0.0, b.t_unix - a.t_unix)
        return distance_m(a, b) <= self.max_speed_mps * dt + K_SIGMA * math.hypot(a.h_acc_m, b.h_acc_m)

    def check(self, fix: Fix, now: float) -> str | None:
        """None if ``fix`` (status ok) may go out as valid, else the reason; counts either way."""
        reason = self._reason(fix, now)
        if reason is None:
            self.accepted += 1
        else:
            self.rejected[reason] += 1
        return reason

    def _reason(self, fix: Fix, now: float) -> str | None:
        if not (math.isfinite(fix.h_acc_m) and fix.h_acc_m <= self.max_h_acc_m):
            self._chain.clear()
            return "h_acc"
        if not now - fix.t_unix <= self.max_age_s:
            self._chain.clear()
            return "age"
        ref = self.reference
        if ref is not None and fix.t_unix <= ref.t_unix:
            return "out_of_order"
        if ref is not None and fix.t_unix - ref.t_unix > self.reference_s:
            self.reference = ref = None
        if ref is not None and self.consistent(ref, fix):
            self.reference = fix
            self._chain.clear()
            return None
        if self._chain and (fix.t_unix <= self._chain[-1].t_unix or not self.consistent(self._chain[-1], fix)):
            self._chain.clear()
        self._chain.append(fix)
        if len(self._chain) >= CONFIRM:
            self.reference = fix
            self._chain.clear()
            return None
        return "jump" if ref is not None else "unconfirmed"

    def status(self) -> dict:
        return {"max_speed_mps": self.max_speed_mps, "max_h_acc_m": self.max_h_acc_m, "max_age_s": self.max_age_s,
                "accepted": self.accepted, "rejected": {r: self.rejected[r] for r in REASONS}}

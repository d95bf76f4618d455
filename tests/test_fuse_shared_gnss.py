"""Two drones sharing their GNSS error (one sky, one RTK base): each fix message carries the drone's GNSS sigma
(``sigma_uav_m``), and ``skyfix fuse``'s fuser keeps that error whole instead of averaging it away by √2.

Each trial draws one GNSS error both drones' positions carry (per axis 1/√2 of their sigma_uav_m, as the
localizer's accuracy adds it) and a little noise of each drone's own; the fixes go through the fix message (JSON)
into the :class:`~groundstation.fuse.fuser.Fuser`. The fused claim stays near one drone's (above 0.85 of it, where
independent errors would give 0.71) and covers the errors it makes (within 2 h_acc); the control, the GNSS error
taken as independent (``SharedSigmas(gnss_m=0)``, what the fuser did while the message lacked sigma_uav_m),
claims 1/√2 of a drone's and its errors exceed the claim."""

from __future__ import annotations

import math

import numpy as np
from test_fusion import fix, north_east

from groundstation.fuse.fuser import Fuser
from groundstation.messages import FixMessage
from localizer.fix_gate import FixGate
from localizer.fusion import SharedSigmas
from localizer.uncertainty import isotropic_sigma_m

SIGMA_UAV_M = 1.0  # each drone's GNSS sigma (DRMS), all of it shared
OWN_M = 0.05  # each drone's own error per axis
TRIALS = 40
SECONDS = 2.0


def _carried(f):
    """The fix as the fuser receives it: through the fix message's JSON."""
    return FixMessage.model_validate_json(FixMessage.of(f).model_dump_json(by_alias=True)).to_fix()


def _trial(rng, shared: SharedSigmas | None) -> tuple[float, float, float]:
    """(fused error, fused h_acc, one drone's h_acc), m, at the end of one trial."""
    fuser = Fuser(lambda: FixGate(max_age_s=0.5), 3.0, sources=("a", "b"), shared=shared)
    bias = rng.normal(0.0, SIGMA_UAV_M / math.sqrt(2.0), 2)
    sigma = math.hypot(OWN_M, SIGMA_UAV_M / math.sqrt(2.0))  # per axis, as claimed
    last, one = None, None
    for k in range(round(SECONDS * 30)):
        for i, name in enumerate("ab"):
            t = 1000.0 + k / 30.0 + 0.004 * i
            n, e = bias + rng.normal(0.0, OWN_M, 2)
            f = fix(t, 0.3 * (t - 1000.0) + n, e, sigma)
            f.sigma_uav_m = SIGMA_UAV_M
            got = _carried(f)
            assert got.sigma_uav_m == SIGMA_UAV_M
            one = got.h_acc_m
            fused = fuser.on_fix(name, got, t + 0.08)
            if fused is not None and fused.ok:
                last = fused
    assert last is not None, fuser.status(2000.0)
    return math.hypot(*north_east(last)), last.h_acc_m, one


def _trials(shared: SharedSigmas | None) -> np.ndarray:
    rng = np.random.default_rng(29)
    return np.array([_trial(rng, shared) for _ in range(TRIALS)])


def _ratio(err, h_acc) -> float:
    """RMS error / RMS of the claims' DRMS (round claims: √2 times their per-axis sigma): 1 when calibrated."""
    return math.sqrt(np.mean(err**2) / np.mean(2.0 * isotropic_sigma_m(h_acc) ** 2))


def test_two_drones_sharing_their_gnss_error_do_not_claim_it_averaged_away():
    err, h_acc, one = _trials(None).T
    within = np.mean(err <= 2 * h_acc)
    print(
        f"shared kept: fused h_acc / one drone's {np.median(h_acc / one):.3f}, within 2 h_acc {within:.2f}, "
        f"RMS err / RMS claimed DRMS {_ratio(err, h_acc):.2f}"
    )
    assert np.all(h_acc >= 0.85 * one)
    assert within >= 0.9


def test_the_control_taken_as_independent_claims_too_little():
    err, h_acc, one = _trials(SharedSigmas(gnss_m=0.0)).T
    ratio = _ratio(err, h_acc)
    print(
        f"independent: fused h_acc / one drone's {np.median(h_acc / one):.3f}, "
        f"RMS err / RMS claimed DRMS {ratio:.2f}"
    )
    assert np.all(h_acc < 0.75 * one)  # averaged away by √2
    assert ratio > 1.2  # and the errors exceed that claim

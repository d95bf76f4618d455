"""``positions_smoothed.csv``: the offline track, written beside ``positions.csv`` by ``process`` and ``evaluate``.

``positions.csv`` is what a live run would have sent, frame by frame (causal). Offline the
whole recording is there: the fixes go through the safety gates
(:func:`localizer.fix_gate.gate_offline`: a fix off the UUV's track or a target never
confirmed is left out; a re-acquired target's first second is confirmed by the fixes after
it; the gates' white share never below the jitter the whole recording shows over a wave's
period, :class:`FlooredScatter`), and the ones taken are smoothed forward and backward
(:func:`localizer.smooth.smooth_fixes`), gaps bridged while the smoothed position's own
1-sigma stays within :data:`localizer.smooth.BRIDGE_SIGMA_M`.

Columns: ``positions.csv``'s first six (``t,lat,lon,depth_m,h_acc_m,status``), so
``report`` and ``export`` read it as they read positions.csv, then ``sigma_n_m,
sigma_e_m,cov_ne_m2`` (against the truth: the smoothed part plus the error the fixes
share), ``sigma_shared_m`` (that shared part's DRMS: the floor no smoothing goes below),
``vn_mps,ve_mps`` (the smoothed velocity) and ``gap_s`` (0 at a frame with its own fix;
the time between the fixes around a bridged frame) and ``traced_back`` (1: the frame's fix
is not in positions.csv: the UUV's pixel there was found by tracing a re-acquisition back
through the frames the causal pass had lost it in, as ``process`` and ``evaluate`` track
the video, :func:`groundstation.offline.track.track_session` ``both_ways``; else 0).
``status``: ``ok`` where there is a smoothed position; else the frame's own word (from
positions.csv, or ``ok`` for a fix traced back), or ``refused`` for a fix the gates
refused that no fixes around it bridge.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from groundstation.runtime.gps_input import LOSS_STATUSES
from groundstation.session.positions import write_table
from localizer.fix import Fixes
from localizer.fix_gate import FixGate, gate_offline
from localizer.smooth import Smoothed, recording_fits, recording_jitter_share, smooth_fixes
from localizer.uuv_track import Scatter

NAME = "positions_smoothed.csv"
COLUMNS = (
    "t",
    "lat",
    "lon",
    "depth_m",
    "h_acc_m",
    "status",
    "sigma_n_m",
    "sigma_e_m",
    "cov_ne_m2",
    "sigma_shared_m",
    "vn_mps",
    "ve_mps",
    "gap_s",
    "traced_back",
)


def offline_track(
    fixes: Fixes, max_speed_mps: float, max_accel_mps2: float
) -> tuple[Smoothed, np.ndarray]:
    """The smoothed track of a recording's fixes and its status word per frame (see the module doc)."""
    gate = FixGate(max_speed_mps, max_accel_mps2, max_h_acc_m=math.inf, max_age_s=math.inf)
    recorded = recording_fits(fixes, fixes.status == "ok")
    gate.scatter = FlooredScatter(recording_jitter_share(recorded))
    words = gate_offline(fixes, np.isin(fixes.status, LOSS_STATUSES), gate)
    taken = np.array([w is None for w in words], dtype=bool)
    # the fixes' local fits computed once: the same fixes where the gates take every ok fix
    smoothed = smooth_fixes(fixes, taken, max_speed_mps, max_accel_mps2, recorded=recorded)
    status = np.where(
        smoothed.ok, "ok", np.where(fixes.status == "ok", "refused", fixes.status)
    ).astype(object)
    return smoothed, status


class FlooredScatter(Scatter):
    """The gate's white share (:class:`~localizer.uuv_track.Scatter`) never below ``floor``: offline, the jitter the
    whole recording shows over a wave's period (:func:`localizer.smooth.recording_jitter_share`, a median: a wrong
    target's jumps do not raise it). Waves move a fix by 5-10 cm over a second; the frame-to-frame share measured
    on the fixes gated so far can be a tenth of that in a calm stretch (a fresh breeze's true pixel: 0.001 against
    0.03), and the true UUV's next swell was refused as ``innovation``, then ``diverged``, for seconds."""

    def __init__(self, floor: float):
        super().__init__()
        self.floor = floor if math.isfinite(floor) else 0.0

    @property
    def share(self) -> float:
        return max(self.floor, super().share)


def traced_back(causal: Fixes, offline: Fixes) -> np.ndarray:
    """Per frame (bool): ``offline`` (the smoothed track's fixes) has a fix there that ``causal`` (positions.csv's,
    the same frames) has not: a frame traced back from a re-acquisition."""
    return (offline.status == "ok") & (causal.status != "ok")


def write_smoothed_csv(
    path: Path,
    fixes: Fixes,
    smoothed: Smoothed,
    status: np.ndarray,
    traced: np.ndarray | None = None,
) -> None:
    """The table of the module doc, one row per frame of ``fixes``; ``traced``: :func:`traced_back` (None: none)."""
    traced = np.zeros(len(fixes), dtype=bool) if traced is None else traced
    cov, shared = smoothed.cov_m2, smoothed.cov_shared_m2
    columns = (
        fixes.t_unix,
        smoothed.lat,
        smoothed.lon,
        fixes.depth_m,
        smoothed.h_acc_m,
        status,
        np.sqrt(cov[:, 0, 0]),
        np.sqrt(cov[:, 1, 1]),
        cov[:, 0, 1],
        np.sqrt(shared[:, 0, 0] + shared[:, 1, 1]),
        smoothed.vn_mps,
        smoothed.ve_mps,
        smoothed.gap_s,
        traced.astype(int).astype(str),
    )
    digits = (6, 9, 9, 4, 4, None, 4, 4, 6, 4, 4, 4, 3, None)
    write_table(
        path, COLUMNS, ([_cell(v, d) for v, d in zip(row, digits)] for row in zip(*columns))
    )


def _cell(value, digits: int | None) -> str:
    if digits is None:
        return str(value)
    return f"{value:.{digits}f}" if math.isfinite(value) else ""


def summary(status: np.ndarray, smoothed: Smoothed, traced: np.ndarray | None = None) -> str:
    """One line: how many frames have a smoothed position, how many of them bridged (and with ``traced``,
    :func:`traced_back`, how many traced back), the noise's share of the fixes' covariance (frame to frame, or over
    a wave's period) and the acceleration bound (median over the frames)."""
    bridged = int(np.sum(smoothed.ok & (smoothed.gap_s > 0)))
    back = "" if traced is None else f", {int(np.sum(traced & smoothed.ok))} traced back"
    return (
        f"smoothed: {int(smoothed.ok.sum())} of {len(status)} frames ({bridged} bridged{back}), "
        f"{int(np.sum(status == 'refused'))} fixes refused; noise's share of the fixes' covariance "
        f"{smoothed.white_share:.3f} (over a wave's period {smoothed.wave_share:.3f}), acceleration bound "
        f"{float(np.median(smoothed.accel_mps2[smoothed.ok])) if smoothed.ok.any() else float('nan'):.2f} m/s²"
    )

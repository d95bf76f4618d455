"""The safety gates on the issue's fix streams, before (the previous-fix gate) and after (the track).

    .venv/bin/python bench/gate_streams.py [--before COMMIT] [--out bench/results/gate_streams.txt]

Feeds the streams of ``groundstation/testing/gate_streams.py`` (30 Hz, white error 3 mm per axis, h_acc 0.4 m and
0.05 m) to the gate of ``localizer/fix_gate.py`` at ``--before`` (read with ``git show``; default
805dfec, the gate that compared each fix with the previous accepted one) and to today's. For each:
how many fixes that are not the UUV went out as valid (of how many), the largest error of a valid
fix, and how many fixes of the real UUV were refused more than a second after its (re)acquisition.
A third column: today's gate told by the UUV's autopilot whether its thrusters push
(``localizer/thrusters.py``; ArduSub's outputs at 10 Hz): idle while the UUV is at rest, pushing
throughout where it really moves.
Then, for an abrupt start: how well a motion within the acceleration bound can explain it (the
smallest largest-residual of a bounded-acceleration fit), the reason a slow one cannot be told from
a real start. Last, what a check costs (the GPS_INPUT sink runs it on the event loop for every fix).
"""

from __future__ import annotations

import argparse
import importlib.util
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from emit import emit

from groundstation.testing import gate_streams as gs
from localizer.fix_gate import MAX_ACCEL_MPS2, MAX_SPEED_MPS, FixGate

ROOT = Path(__file__).resolve().parents[1]

V, A = MAX_SPEED_MPS["bluerov2"], MAX_ACCEL_MPS2["bluerov2"]


def old_gate_class(commit: str, work: Path):
    """``FixGate`` of ``localizer/fix_gate.py`` at ``commit`` (written into ``work``), a module of the localizer
    package."""
    src = subprocess.run(
        ["git", "-C", str(ROOT), "show", f"{commit}:localizer/fix_gate.py"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    path = work / f"fix_gate_{commit}.py"
    path.write_text(src)
    spec = importlib.util.spec_from_file_location("localizer.fix_gate_before", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.FixGate


def streams(h_acc_m: float) -> list:
    return [
        gs.ramp(h_acc_m),
        gs.ramp(h_acc_m, 1.5, 1.0),
        gs.step(h_acc_m, 0.8),
        gs.step(h_acc_m, 10.0),
        gs.lookalike(h_acc_m, 3.0),
        gs.lookalike(h_acc_m, 1.0),
        gs.crossing(h_acc_m),
        gs.accelerate(h_acc_m, A, V),
        gs.turn(h_acc_m, V, A),
    ]


def score(stream, valid: np.ndarray) -> tuple[str, str, str]:
    ok = np.array([f.ok for f in stream.fixes])
    seen = np.array([[f.lat, f.lon] for f in stream.fixes])
    err = np.full(len(ok), np.nan)
    err[ok] = np.hypot(
        (seen[ok, 0] - gs.LAT0) * gs.M_PER_DEG - stream.truth_ne[ok, 0],
        (seen[ok, 1] - gs.LON0) * gs.M_PER_DEG * np.cos(np.radians(gs.LAT0))
        - stream.truth_ne[ok, 1],
    )
    wrong = f"{(valid & stream.wrong).sum()}/{stream.wrong.sum()}" if stream.wrong.any() else "—"
    worst = f"{np.nanmax(np.where(valid, err, np.nan)):.3f}" if valid.any() else "—"
    right_refused = (~valid & stream.real_after(1.0)).sum()
    return wrong, worst, str(right_refused)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--before", default="805dfec", help="commit of the gate to compare with")
    p.add_argument("--out", type=Path, help="also write the table here")
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as work:
        Before = old_gate_class(args.before, Path(work))
    lines = [
        (
            f"gates on 30 Hz fix streams (white error {gs.NOISE_M * 1000:g} mm per axis); before = {args.before}, "
            f"after = today's (top speed {V:g} m/s, acceleration {A:g} m/s²)"
        ),
        (
            "wrong valid: fixes not of the UUV sent as valid / such fixes; worst: largest error of a valid fix (m); "
            "real refused: fixes of the UUV refused more than 1 s after its (re)acquisition"
        ),
        "",
    ]
    head = (
        f"{'stream':44} {'h_acc':>5}  {'before: wrong valid':>19} {'worst':>6} {'real refused':>12}  "
        f"{'after: wrong valid':>18} {'worst':>6} {'real refused':>12}  "
        f"{'thrusters: wrong valid':>22} {'worst':>6} {'real refused':>12}"
    )
    lines += [head, "-" * len(head)]
    for h_acc in (0.4, 0.05):
        for s in streams(h_acc):
            old, new = Before(), FixGate()
            before = score(s, gs.offer(old, s, old.reset))
            after = score(s, gs.offer(new, s, new.target_lost))
            told = FixGate(thrusters=gs.vectored_thrusters())
            moves = bool(np.ptp(s.truth_ne) > 0)
            thr = score(
                s, gs.offer(told, s, told.target_lost, told.thrusters, lambda t, m=moves: m)
            )
            lines.append(
                f"{s.name:44} {h_acc:5.2f}  {before[0]:>19} {before[1]:>6} {before[2]:>12}  "
                f"{after[0]:>18} {after[1]:>6} {after[2]:>12}  {thr[0]:>22} {thr[1]:>6} {thr[2]:>12}"
            )
    lines += [
        "",
        "an abrupt start at v against the best motion within the acceleration bound a (noise-free):",
    ]
    for v in (0.35, 0.7, 1.5):
        fits = ", ".join(
            f"{gs.bounded_fit_residual_m(v, a) * 1000:.1f} mm at a = {a:g} m/s²"
            for a in (1.0, 2.5, A)
        )
        lines.append(f"  v = {v:.2f} m/s: largest residual {fits}")
    stream = gs.turn(0.4, V, A, seconds=20.0)
    gate, cost_us = FixGate(), []
    for f in stream.fixes:
        t0 = time.perf_counter()
        gate.check(f, f.t_unix + 0.05)
        cost_us.append((time.perf_counter() - t0) * 1e6)
    lines.append(
        f"\ncost of a check (tracking, {len(cost_us)} fixes): median {np.median(cost_us):.0f} µs, "
        f"p99 {np.percentile(cost_us, 99):.0f} µs, max {max(cost_us):.0f} µs"
    )
    emit(lines, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())

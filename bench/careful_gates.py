"""Benchmark: the safety gates come back careful — restarts, selections, clock steps (the issue's measurements).

    .venv/bin/python bench/careful_gates.py [--out bench/results/careful_gates.txt]

30 Hz fix streams with their truth (``groundstation/testing/gate_streams.py``, ``tests/test_careful_gates.py``'s streams), through
:class:`~localizer.fix_gate.FixGate`:

- a restart: the UUV tracked, its track kept by the real file (``groundstation/live/track_memory.py``), a new gate
  started from it 3 s later; a consistent look-alike 50 m away for 10 s: valid fixes (and, for comparison, a fresh
  gate without the kept track: when the look-alike became valid); the UUV where it was: when valid again;
- a selection of a look-alike 2, 5, 10 m away while tracking: valid fixes within 15 s; the gate as it was (the
  selection unseen by the gates, the reach growing with time): when it became valid; confirmed by the operator:
  when valid;
- ±10 s steps of the station clock, the tracker jumping 8 m (h_acc 0.4 m) or 1.2 m (h_acc 0.05 m) at that moment:
  valid fixes more than 3 h_acc off the truth; the gate as it was: the exposure times alone, the reach uncapped.
"""

from __future__ import annotations

import argparse
import math
import tempfile
from pathlib import Path

from emit import emit

from groundstation.testing.careful_gates import kept_gate, off_valid, still, tracked
from groundstation.testing.gate_streams import HZ, T0
from localizer.fix_gate import FixGate


def first_valid_s(valid: list[bool]) -> float | None:
    return valid.index(True) / HZ if True in valid else None


def restart() -> tuple[list[str], dict]:
    lines, data = ["restart (track kept 3 s before), look-alike 50 m away for 10 s:"], {}
    for h in (0.4, 0.05):
        with tempfile.TemporaryDirectory() as d:
            gate, t = kept_gate(Path(d), h)
            lookalike = sum(still(gate, t, 10.0, north_m=50.0, h_acc_m=h))
            gate, t = kept_gate(Path(d), h)
            back = first_valid_s(still(gate, t, 3.0, h_acc_m=h))
        fresh = first_valid_s(still(FixGate(), T0, 3.0, north_m=50.0, h_acc_m=h))
        data[f"h_acc_{h}"] = {
            "lookalike_valid": lookalike,
            "fresh_gate_lookalike_valid_after_s": fresh,
            "uuv_valid_after_s": back,
        }
        lines.append(
            f"  h_acc {h:.2f} m: look-alike valid fixes {lookalike} (a fresh gate: valid after {fresh:.2f} s);"
            f" the UUV where it was: valid after {back:.2f} s"
        )
    return lines, data


def select() -> tuple[list[str], dict]:
    lines, data = ["select a look-alike while tracking (15 s of it):"], {}
    for h in (0.4, 0.05):
        for away in (2.0, 5.0, 10.0):
            gate = tracked(h)
            gate.target_lost()  # the selection: a new lock (FrameInfo.lock)
            now = sum(still(gate, T0 + 2.0, 15.0, east_m=away, h_acc_m=h))
            gate.confirm()
            confirmed = first_valid_s(still(gate, T0 + 17.0, 3.0, east_m=away, h_acc_m=h))
            before = FixGate(max_reach_m=math.inf)  # the selection unseen, the reach growing
            still(before, T0, 2.0, h_acc_m=h)
            was = first_valid_s(still(before, T0 + 2.0, 15.0, east_m=away, h_acc_m=h))
            data[f"h_acc_{h}_{away:g}m"] = {
                "valid": now,
                "confirmed_valid_after_s": confirmed,
                "before_valid_after_s": was,
            }
            lines.append(
                f"  h_acc {h:.2f} m, {away:4.1f} m away: valid fixes {now}; confirmed: valid after "
                f"{confirmed:.2f} s; the gate as it was: valid after {was:.2f} s"
            )
    return lines, data


def clock() -> tuple[list[str], dict]:
    lines, data = (
        ["station clock steps, the tracker jumping at that moment: valid fixes > 3 h_acc off:"],
        {},
    )
    for wrong_m, h in ((8.0, 0.4), (1.2, 0.05)):
        for step in (10.0, -10.0):
            for follows in (True, False):
                bad, gate = off_valid(step, wrong_m, follows, h)
                alone = off_valid(
                    step, wrong_m, follows, h, with_arrival=False, max_reach_m=math.inf
                )[0]
                key = f"{wrong_m:g}m_{step:+g}s_{'stepped' if follows else 'kept'}"
                data[key] = {
                    "off_valid": bad,
                    "exposure_times_alone_off_valid": alone,
                    "steps_seen": gate.clock_steps,
                }
                lines.append(
                    f"  jump {wrong_m:3.1f} m (h_acc {h:.2f}), step {step:+5.1f} s, exposure "
                    f"{'stepped  ' if follows else 'kept course'}: {bad} (the gate as it was: {alone}); "
                    f"steps seen {gate.clock_steps}"
                )
    return lines, data


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path)
    args = p.parse_args()
    lines, data = [], {}
    for name, part in (("restart", restart), ("select", select), ("clock", clock)):
        got, data[name] = part()
        lines += got
    emit(lines, args.out, data)


if __name__ == "__main__":
    main()

"""Station clock steps of +-10 s against GNSS time (SYSTEM_TIME at 2 Hz): how many samples (and seconds) after the
step each fix's GNSS time (the station-minus-GNSS offset, GPS_INPUT's time) is right again, with the step detection
(localizer.telemetry: two samples agreeing off the median restart it) and without it (every sample into the median
of 31, as before). The safety gates' own numbers under the same steps (no valid fix more than 3 h_acc off) are
bench/careful_gates.py's.

    .venv/bin/python bench/gnss_clock_steps.py [--out bench/results/gnss_clock_steps.txt]
"""

from __future__ import annotations

import argparse
from pathlib import Path

from groundstation.testing.gnss_clock import HZ, moved_and_followed
from localizer import telemetry

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "gnss_clock_steps.txt")
    args = ap.parse_args()
    lines = []
    for step in (10.0, -10.0):
        moved, now, tel = moved_and_followed(step)
        detect = telemetry.GNSS_STEP_S
        telemetry.GNSS_STEP_S = float("inf")
        try:
            _, before, _ = moved_and_followed(step)
        finally:
            telemetry.GNSS_STEP_S = detect
        lines.append(
            f"station clock step {step:+5.1f} s, SYSTEM_TIME at {HZ:g} Hz: the telemetry's scale moved {moved / HZ:.1f} s "
            f"after it (the clock map's window; frames stamped on the new scale are ahead of it until then); the GNSS "
            f"offset right again {(now - moved) / HZ:.1f} s "
            f"after that (detected steps {tel.gnss_clock_steps}); every sample into the median: "
            f"{(before - moved) / HZ:.1f} s after that"
        )
        print(lines[-1], flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()

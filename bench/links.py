"""Stopping and links that come and go: the 1 s requirements of issue 11, measured from outside ``skyfix run``.

    .venv/bin/python bench/links.py [--trials 5] [--link-trials 2] [--out bench/results/links.txt]

The scenarios are the live tests' (``groundstation/testing/link_scenarios.py``), run here several times each:

- stop: SIGINT (SIGTERM every other trial) to ``skyfix run`` while everything flows from ``skyfix replay``,
  while a UDP video URL gets nothing, while an RTSP open hangs on a server that never answers, and while
  the UAV's MAVLink is silent; the time from the signal to the process's exit (required: ≤ 1 s), its exit
  code, and whether the last GPS_INPUT the UUV got said no fix;
- links: the UAV's MAVLink cut for 10 s, the depth publisher restarted, the Zenoh router restarted (skyfix
  its client), the video cut for 6 s; the time from the input's return to the first valid GPS_INPUT
  (required: ≤ 1 s; the video's includes waiting for its next keyframe, one a second).

Prints a table per part and writes it to ``--out``.
"""

from __future__ import annotations

import argparse
import signal
import statistics
import sys
import tempfile
import time
from pathlib import Path

from groundstation.testing.link_scenarios import (
    LINK_INPUTS,
    SHUTDOWN_STATES,
    link_comes_back,
    make_session,
    shutdown,
)

ROOT = Path(__file__).resolve().parents[1]

REQUIRED_S = 1.0


def _summary(name: str, values: list[float]) -> str:
    return (
        f"{name:16s} n={len(values)}  median {statistics.median(values):.3f} s  max {max(values):.3f} s  "
        f"[{', '.join(f'{v:.3f}' for v in values)}]  {'ok' if max(values) <= REQUIRED_S else 'OVER 1 s'}"
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trials", type=int, default=5, help="stops per input state")
    ap.add_argument("--link-trials", type=int, default=2, help="cuts per link")
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "links.txt")
    args = ap.parse_args()
    lines = [
        (
            f"bench/links.py {time.strftime('%Y-%m-%d %H:%M')} — trials {args.trials} (stop), "
            f"{args.link_trials} (links); required ≤ {REQUIRED_S:g} s"
        ),
        "",
        "stop: signal → exit (s); every exit 0 and the last GPS_INPUT a no-fix unless noted",
    ]

    def say(line: str) -> None:
        print(line, flush=True)
        lines.append(line)

    for line in lines:
        print(line)
    with tempfile.TemporaryDirectory(prefix="skyfix-links-") as tmp:
        work = Path(tmp)
        for state in SHUTDOWN_STATES:
            times, notes = [], []
            for i in range(args.trials):
                sig = signal.SIGTERM if i % 2 else signal.SIGINT
                r = shutdown(work / f"{state}{i}", state, sig)
                times.append(r["exit_s"] if r["exit_s"] is not None else float("inf"))
                if r["rc"] != 0 or not r["gps_after_signal"] or r["gps_after_signal"][-1] >= 2:
                    notes.append(
                        f"trial {i}: rc {r['rc']}, GPS_INPUT after the signal {r['gps_after_signal']}"
                    )
            say(_summary(state, times) + ("  " + "; ".join(notes) if notes else ""))
        say("")
        say("links: input back → first valid GPS_INPUT (s)")
        session = make_session(work / "session")
        for which in LINK_INPUTS:
            back, notes = [], []
            for i in range(args.link_trials):
                r = link_comes_back(work / f"{which}{i}", session, which)
                back.append(r["back_s"])
                if set(r["gps_while_missing"]) != {1}:
                    notes.append(
                        f"trial {i}: fix_types while missing {sorted(set(r['gps_while_missing']))}"
                    )
            say(_summary(which, back) + ("  " + "; ".join(notes) if notes else ""))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines) + "\n")
    print(f"written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Faults and attacks on ``skyfix fuse``, on loopback (issue 29): a real fuser process, its GPS_INPUT to a UUV endpoint
of this process, the drones and the strangers publishing fixes at 30 fps from one Zenoh session
(tests/fuse_peers.py: the UUV going north at 0.3 m/s; a real drone scatters 2 cm per axis around it).

    .venv/bin/python bench/fuse_attacks.py [--seconds 8] [--out bench/results/fuse_attacks.txt]

- strangers: ``--source a`` only; two peers publishing on ``skyfix/uuv/rov1/drone/{x,y}/fix`` 20 m east, claiming
  h_acc 0.05 m: how many of their fixes reach the fused fixes and the valid GPS_INPUT (by distance from the UUV);
- a fake among the sources: a configured-looking source 0.8 m north of the UUV claiming h_acc 0.02 m beside one
  real drone (claiming 0.2 m per axis: the two agree by their claims), and beside two: the fused error against the
  truth (north: the fake's pull; its share of the 0.8 m), the fused claim, and how often the error exceeds twice the
  claim; with the shipped shared-error sigmas and with a shared GNSS error of 0.1 m per axis;
- a fix from the future: drone a's fix stamped a day ahead halfway through: refused (counted), and the fused fixes
  before and after it (their rate, the longest gap);
- a walking fake: sources a, b, c; a and b lose the UUV from 2 s to 6 s while c walks its fixes east at 1 m/s: the largest error of an ok fused fix and of a valid GPS_INPUT, the off_track count, the error once a
  and b are back; the same with the output gate's reach unbounded (``--uuv-max-reach-m 1e6``);
- a shared GNSS error: two real drones 0.5 m north of the UUV alike (one sky's error), claiming their GNSS sigma
  (``sigma_uav_m`` 1.0 m) in their fix messages: the fused h_acc against one drone's, the error; the same taken
  as independent (``--shared-gnss-m 0``).

Prints the numbers and writes them to ``--out``.
"""

from __future__ import annotations

import argparse
import math
import tempfile
from pathlib import Path

import numpy as np

from groundstation.testing.fuse_peers import Drone, gps_input_errors_m, key, ok_errors, run_fuser

ROOT = Path(__file__).resolve().parents[1]

REAL_A, REAL_B = Drone("a", (0.02, 0.0), 0.02, 0.2), Drone("b", (-0.02, 0.0), 0.02, 0.2)
FAKE = Drone("f", (0.8, 0.0), 0.005, 0.014)


def strangers(work: Path, seconds: float, say) -> None:
    drones = [REAL_A, Drone("x", (0.0, 20.0), 0.01, 0.035), Drone("y", (0.0, 20.1), 0.01, 0.035)]
    final, fused, gps, t0 = run_fuser(work, ["a"], drones, seconds)
    err = ok_errors(fused, t0)
    far = int(np.sum(np.hypot(err[:, 0], err[:, 1]) > 5.0))
    valid = gps_input_errors_m(gps, t0)
    say(
        f"strangers x, y 20 m east (unconfigured), a configured: {len(err)} ok fused fixes, {far} of them > 5 m from "
        f"the UUV (largest error {np.hypot(err[:, 0], err[:, 1]).max():.3f} m); {len(valid)} valid GPS_INPUT, "
        f"{int(np.sum(valid > 5.0))} > 5 m; counted unconfigured: {final['fusion']['unconfigured']}"
    )


def fake(work: Path, seconds: float, say, reals: list[Drone], *extra: str) -> None:
    final, fused, _, t0 = run_fuser(
        work, [d.name for d in reals] + ["f"], [*reals, FAKE], seconds, None, *extra
    )
    err = ok_errors(fused, t0)
    fusion = final["fusion"]
    late = err[len(err) // 3 :]  # once the floors have some seconds of comparisons
    dist = np.hypot(late[:, 0], late[:, 1])
    src = {n: fusion["sources"][key(n)] for n in [d.name for d in reals] + ["f"]}
    say(
        f"fake f 0.8 m north claiming h_acc 0.020 m beside {'+'.join(d.name for d in reals)} "
        f"{' '.join(extra) or '(shipped shared sigmas)'}: {len(err)} ok fused fixes; last 2/3: north error median "
        f"{np.median(late[:, 0]):.3f} m (the fake's pull {np.median(late[:, 0]) / 0.8:.0%} of its 0.8 m), error "
        f"median {np.median(dist):.3f} max {dist.max():.3f} m, fused h_acc median {np.median(late[:, 2]):.3f} m, "
        f"error/h_acc median {np.median(dist / late[:, 2]):.2f}, > 2 h_acc {np.mean(dist > 2 * late[:, 2]):.1%}; "
        f"f used in {src['f']['used']} fusions, rejected in {src['f']['rejected']}, its claim as weighed "
        f"{src['f']['h_acc_used_m']} m (floor {src['f']['floor_m']} m); "
        + ", ".join(f"{d.name} as weighed {src[d.name]['h_acc_used_m']} m" for d in reals)
    )


def future(work: Path, seconds: float, say) -> None:
    half = seconds / 2
    final, fused, _, t0 = run_fuser(
        work, ["a", "b"], [REAL_A, REAL_B], seconds, {half: ("a", 86400.0)}
    )
    t_ok = np.array([f["t"] for f in fused if f["status"] == "ok"]) - t0
    before, after = t_ok[(t_ok > half - 2) & (t_ok < half)], t_ok[(t_ok > half) & (t_ok < half + 2)]
    a = final["fusion"]["sources"][key("a")]
    say(
        f"a fix from the future (a's, stamped +1 day at {half:g} s): refused {a['refused'].get('future', 0)} "
        f"(a's refusals {a['refused']}); ok fused fixes 2 s before {len(before)}, 2 s after {len(after)}, longest "
        f"gap after it {np.diff(t_ok[t_ok > half - 0.5]).max():.3f} s; last fused {t_ok[-1]:.2f} s of "
        f"{seconds:g}; last sources {final['fusion']['last_sources']}"
    )


def walker(work: Path, seconds: float, say, *extra: str) -> None:
    quiet = (
        2.0,
        6.0,
    )  # the UUV goes 1.2 m meanwhile: within a and b's own gates' reach when they come back
    drones = [
        Drone("a", (0.02, 0.0), 0.02, 0.1, silent_s=quiet),
        Drone("b", (-0.02, 0.0), 0.02, 0.1, silent_s=quiet),
        Drone("c", (0.0, 0.0), 0.02, 0.1, walk_ne_mps=(0.0, 1.0), walk_from_s=2.0),
    ]
    final, fused, gps, t0 = run_fuser(work, ["a", "b", "c"], drones, seconds, None, *extra)
    t_ok = np.array([f["t"] - t0 for f in fused if f["status"] == "ok"])
    err = np.hypot(*ok_errors(fused, t0)[:, :2].T)
    valid = gps_input_errors_m(gps, t0)
    back = err[t_ok > quiet[1] + 1.5]
    say(
        f"walking fake c (1.0 m/s east from 2 s, a and b silent {quiet[0]:g}-{quiet[1]:g} s) "
        f"{' '.join(extra) or '(reach 1.5 m)'}: largest ok fused error {err.max():.2f} m, valid GPS_INPUT "
        f"{valid.max():.2f} m (the fake {quiet[1] - quiet[0]:.1f} m off as a and b come back); off_track "
        f"{final['fusion']['off_track']}; a and b back: {len(back)} ok, error max "
        f"{back.max() if len(back) else float('nan'):.3f} m"
    )


def shared_gnss(work: Path, seconds: float, say, *extra: str) -> None:
    drones = [
        Drone(n, (0.5, 0.0), 0.02, math.hypot(0.02, 1.0 / math.sqrt(2)), sigma_uav_m=1.0)
        for n in "ab"
    ]
    _, fused, _, t0 = run_fuser(work, ["a", "b"], drones, seconds, None, *extra)
    err = ok_errors(fused, t0)
    one = math.sqrt(2) * drones[0].sigma_m
    say(
        f"shared GNSS error 0.5 m north in both a and b (sigma_uav_m 1.0) {' '.join(extra) or '(default)'}: fused "
        f"h_acc median {np.median(err[:, 2]):.3f} m = {np.median(err[:, 2]) / one:.3f} of one drone's {one:.3f} m; "
        f"error median {np.median(np.hypot(err[:, 0], err[:, 1])):.3f} m"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=8.0)
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "fuse_attacks.txt"))
    args = ap.parse_args()
    lines = []

    def say(text: str) -> None:
        print(text, flush=True)
        lines.append(text)

    with tempfile.TemporaryDirectory() as d:
        work = Path(d)
        strangers(work / "strangers", args.seconds, say)
        fake(work / "fake1", args.seconds, say, [REAL_A])
        fake(work / "fake1_gnss", args.seconds, say, [REAL_A], "--shared-gnss-m", "0.1")
        fake(work / "fake2", args.seconds, say, [REAL_A, REAL_B])
        fake(work / "fake2_gnss", args.seconds, say, [REAL_A, REAL_B], "--shared-gnss-m", "0.1")
        future(work / "future", args.seconds, say)
        walker(work / "walker", args.seconds + 2.0, say)
        walker(work / "walker_unbounded", args.seconds + 2.0, say, "--uuv-max-reach-m", "1e6")
        shared_gnss(work / "gnss", args.seconds, say)
        shared_gnss(work / "gnss_independent", args.seconds, say, "--shared-gnss-m", "0")
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()

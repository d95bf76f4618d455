"""Benchmark of what the live mosaic (``skyfix run --live-mosaic``) costs the fixes, at 720p30 and 1080p30.

    .venv/bin/python bench/live_mosaic.py [--sizes 720p,1080p] [--every-s 1,0.2] [--rounds 3] [--duration-s 20]
        [--floor-depth-m 2] [--busy N] [--out bench/results/live_mosaic.txt]

The session and the harness are ``bench/live_latency.py``'s (:func:`live_latency.ensure_session`,
:func:`live_latency.live`): the UAV hovering 10 m over the UUV, every frame replayed as MPEG-TS over UDP into
``skyfix run`` with its page served (``--ui 127.0.0.1:0``, nobody opening it: the live mosaic needs the page),
once without the live mosaic and once per ``--every-s`` with ``--live-mosaic --floor-depth-m M
--live-mosaic-every-s S``; the runs interleaved (off, every S1, every S2, off, ...) and repeated ``--rounds``
times, so the spread between the baseline's repeats on this shared machine is the noise the mosaic's cost is
judged against.

Per run: the share of the frames sent with an ``ok`` fix; stream slot -> GPS_INPUT at the UUV p50/p99; the
service's CPU seconds per second of video (its CPU over the second half of the replay, per wall second: the
replay sends in real time); the frames the mosaic painted, skipped (the painter busy) and had no pose for; the
load average at the run's start. ``--busy N``: every run beside N processes spinning ``while True: pass`` (a
laptop's other programs). Results: ``bench/results/live_mosaic.txt`` and ``.json``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np
from emit import emit
from live_latency import BENCH_DIR, ROOT, ensure_session, live


def variants(every_s: list[str], floor_depth_m: float) -> list[tuple[str, list[str]]]:
    """(name, extra ``skyfix run`` arguments): the live mosaic off, then on at each period."""
    return [("off", [])] + [
        (
            f"every {s} s",
            [
                "--live-mosaic",
                "--floor-depth-m",
                f"{floor_depth_m:g}",
                "--live-mosaic-every-s",
                s,
            ],
        )
        for s in every_s
    ]


def summary(res: dict) -> dict:
    """The numbers of one run this benchmark reports."""
    ok = res["pipeline"]["statuses"].get("ok", 0)
    lat = res["slot_to_gps_input_ms"]
    m = res["live_mosaic"] or {}
    return {
        "ok_pct": round(100.0 * ok / res["frames_sent"], 1),
        "p50_ms": lat["p50"],
        "p99_ms": lat["p99"],
        "cpu_s_per_video_s": round(res["cpu_pct"] / 100.0, 2),
        "painted": m.get("painted"),
        "skipped": m.get("skipped"),
        "no_pose": m.get("no_pose"),
        "dropped": res["pipeline"]["dropped"],
        "load_average": res["load_average"],
    }


def line(name: str, rnd: int, s: dict) -> str:
    return (
        f"  {name:<12} round {rnd}: ok {s['ok_pct']:5.1f} %, slot -> GPS_INPUT p50 {s['p50_ms']} ms, "
        f"p99 {s['p99_ms']} ms; CPU {s['cpu_s_per_video_s']} s per video s; painted {s['painted']}, "
        f"skipped {s['skipped']}, no pose {s['no_pose']}; pipeline dropped {s['dropped']}; "
        f"load {s['load_average']}"
    )


def spread(runs: list[dict], key: str) -> str:
    v = [r[key] for r in runs if r[key] is not None]
    return f"{np.median(v):.3g} [{min(v):.3g}-{max(v):.3g}]" if v else "-"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="720p,1080p", help="comma-separated: 720p, 1080p")
    ap.add_argument(
        "--every-s", default="1,0.2", help="comma-separated --live-mosaic-every-s values"
    )
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--duration-s", type=float, default=20.0)
    ap.add_argument(
        "--floor-depth-m", type=float, default=2.0, help="the floor under the 1 m deep UUV"
    )
    ap.add_argument("--busy", type=int, default=0, metavar="N", help="beside N busy processes")
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "live_mosaic.txt")
    args = ap.parse_args()
    runs = variants(args.every_s.split(","), args.floor_depth_m)
    lines = [
        (
            f"skyfix live mosaic cost benchmark, {time.strftime('%Y-%m-%d %H:%M:%S %Z')}, {os.cpu_count()} cores, "
            f"load average {os.getloadavg()[0]:.1f}; MPEG-TS, the page served, floor {args.floor_depth_m:g} m, "
            f"beside {args.busy} busy processes"
        )
    ]
    results: dict = {}
    for size in args.sizes.split(","):
        session = ensure_session(size, args.duration_s)
        per = results[size] = {name: [] for name, _ in runs}
        lines.append(f"{size} ({session.name}), runs interleaved:")
        for rnd in range(1, args.rounds + 1):
            for name, run_args in runs:
                work = BENCH_DIR / f"run_mosaic_{size}_{name.replace(' ', '_')}"
                work.mkdir(parents=True, exist_ok=True)
                for f in work.iterdir():
                    f.unlink()
                load = round(os.getloadavg()[0], 1)
                res = live(session, work, "mpegts", run_args, args.busy, ui=True) | {
                    "load_average": load
                }
                per[name].append(s := summary(res))
                lines.append(line(name, rnd, s))
                print(lines[-1], flush=True)
        lines.append(f"{size} median [min-max] over {args.rounds} rounds:")
        for name, _ in runs:
            lines.append(
                f"  {name:<12} ok % {spread(per[name], 'ok_pct')}, p50 ms {spread(per[name], 'p50_ms')}, "
                f"p99 ms {spread(per[name], 'p99_ms')}, CPU s/s {spread(per[name], 'cpu_s_per_video_s')}, "
                f"painted {spread(per[name], 'painted')}, skipped {spread(per[name], 'skipped')}"
            )
    emit(lines, args.out, results)
    return 0


if __name__ == "__main__":
    sys.exit(main())

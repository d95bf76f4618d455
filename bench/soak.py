"""Soak: ``skyfix run`` against a looping 1080p30 replay for ten minutes or more (issue 11, item 7).

    .venv/bin/python bench/soak.py [--session DIR] [--minutes 10] [--sample-s 10] [--out bench/results/soak.txt]

One ``skyfix run`` (:class:`live_run.ServiceRun`) is fed by ``skyfix replay`` of one session
again and again until ``--minutes`` have passed: each loop a new replay process, so the UAV's
boot clock starts over (to the service, an autopilot reboot) and the video stream restarts,
as they do in the field. Every ``--sample-s`` the service's /proc gives its resident memory,
open file descriptors, threads and CPU time, and its Zenoh status (``skyfix/status``) the
frames received, frames dropped by the pipeline, fixes and valid GPS_INPUT so far; the
table is printed as it goes and written to ``--out``.

Verdict (targets, :func:`verdict`): resident memory flat — the median over the last minute
at most 5 % above the median over the minute after the warm-up (the first
``--warmup-min`` minutes; RSS swings by about 10 % within a loop as frames and decoder
buffers come and go) — and no more file descriptors or threads in the last minute than
in that one. The same run is the baseline: its warm-up window.

Without ``--session``, ``sim_fixtures/scenarios/hd_nadir.toml`` (1920×1080, 30 fps) is
rendered once with a 48 s duration (two loops of the UUV's path, so the replay's loops join)
into ``/tmp/skyfix-soak/session``; that takes about six minutes.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import tomllib
from pathlib import Path

from live_run import ROOT, ServiceRun, proc_sample

from groundstation.runtime.zenoh_session import open_session

DEFAULT_SESSION = Path("/tmp/skyfix-soak/session")
RSS_GROWTH_MAX = 0.05


def ensure_session(path: Path) -> Path:
    if (path / "session.toml").exists():
        return path
    from sim_fixtures.generate import generate
    from sim_fixtures.scenario import scenario_from_dict

    text = (
        (ROOT / "sim_fixtures" / "scenarios" / "hd_nadir.toml")
        .read_text()
        .replace("duration_s = 3.0", "duration_s = 48.0")
    )
    print(f"generating {path} (once, several minutes) ...", flush=True)
    generate(scenario_from_dict(tomllib.loads(text)), path, text)
    return path


def row(s: dict, cpu_pct: float, status: dict) -> dict:
    pipe, gps = status.get("pipeline", {}), status.get("gps_input", {})
    return {
        "t_min": s["t_min"],
        "rss_mb": round(s["rss_mb"], 1),
        "fds": s["fds"],
        "threads": s["threads"],
        "cpu_pct": round(cpu_pct),
        "frames": status.get("video", {}).get("frames"),
        "dropped": pipe.get("dropped"),
        "fixes_ok": pipe.get("statuses", {}).get("ok"),
        "gps_valid": gps.get("sent_valid"),
        "reboots": status.get("uav", {}).get("clocks", {}).get("uav_reboots"),
    }


def soak(session: Path, work: Path, minutes: float, sample_s: float, printer) -> list[dict]:
    rows: list[dict] = []
    latest: dict = {}
    with ServiceRun(session, work) as run:
        watcher = open_session(connect=[run.zenoh])
        sub = watcher.declare_subscriber(
            "skyfix/status", lambda s: latest.update(json.loads(s.payload.to_bytes()))
        )
        try:
            t0 = time.time()
            replay, _ = run.replay("--tail-s", "0.5")
            loops = 1
            prev = proc_sample(run.proc.pid)
            next_sample = t0 + sample_s
            while time.time() - t0 < minutes * 60.0 and run.alive():
                if replay.poll() is not None:
                    replay, _ = run.replay("--tail-s", "0.5")
                    loops += 1
                if time.time() >= next_sample:
                    s = proc_sample(run.proc.pid)
                    s["t_min"] = round((s["t"] - t0) / 60.0, 2)
                    cpu = 100.0 * (s["cpu_s"] - prev["cpu_s"]) / max(1e-6, s["t"] - prev["t"])
                    rows.append({**row(s, cpu, latest), "loops": loops})
                    printer(rows[-1])
                    prev, next_sample = s, next_sample + sample_s
                time.sleep(0.2)
            replay.terminate()
            replay.wait(10)
        finally:
            sub.undeclare()
            watcher.close()
    if not run.alive() and run.final is None:
        raise RuntimeError("skyfix run died:\n" + run.log.read_text()[-3000:])
    return rows


def verdict(rows: list[dict], warmup_min: float, window_min: float = 1.0) -> tuple[dict, list[str]]:
    """The warm-up window (``window_min`` after ``warmup_min``) against the last ``window_min``: the median RSS
    (it swings by ~10 % within a replay loop) and the most fds and threads (a loop's restart adds some briefly)."""
    import statistics

    warm = [r for r in rows if warmup_min <= r["t_min"] < warmup_min + window_min] or rows[:1]
    end = [r for r in rows if r["t_min"] > rows[-1]["t_min"] - window_min]
    figures = {
        "warm": {
            "t_min": warm[0]["t_min"],
            "rss_mb": statistics.median(r["rss_mb"] for r in warm),
            "fds": max(r["fds"] for r in warm),
            "threads": max(r["threads"] for r in warm),
        },
        "end": {
            "t_min": end[-1]["t_min"],
            "rss_mb": statistics.median(r["rss_mb"] for r in end),
            "fds": max(r["fds"] for r in end),
            "threads": max(r["threads"] for r in end),
        },
        "rss_max_mb": max(r["rss_mb"] for r in rows),
        "last": rows[-1],
    }
    w, e = figures["warm"], figures["end"]
    figures["rss_growth"] = (e["rss_mb"] - w["rss_mb"]) / w["rss_mb"]
    failed = []
    if figures["rss_growth"] > RSS_GROWTH_MAX:
        failed.append(
            f"median RSS {w['rss_mb']:.1f} MB after the warm-up, {e['rss_mb']:.1f} MB at the end "
            f"({figures['rss_growth']:+.1%}, > {RSS_GROWTH_MAX:.0%})"
        )
    for key in ("fds", "threads"):
        if e[key] > w[key]:
            failed.append(f"{key}: at most {w[key]} after the warm-up, {e[key]} at the end")
    return figures, failed


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--session", type=Path, help="session to loop (default: hd_nadir rendered for 48 s, once)"
    )
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--warmup-min", type=float, default=2.0)
    ap.add_argument("--sample-s", type=float, default=10.0)
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "soak.txt")
    args = ap.parse_args()
    session = ensure_session(args.session or DEFAULT_SESSION)
    lines = [
        (
            f"skyfix soak, {time.strftime('%Y-%m-%d %H:%M:%S %Z')}, {os.cpu_count()} cores, session {session}, "
            f"{args.minutes:g} min"
        )
    ]
    print(lines[0], flush=True)

    def printer(r: dict) -> None:
        lines.append(json.dumps(r))
        print(lines[-1], flush=True)

    rows = soak(session, Path("/tmp/skyfix-bench/soak"), args.minutes, args.sample_s, printer)
    figures, failed = verdict(rows, args.warmup_min)
    w, e, last = figures["warm"], figures["end"], figures["last"]
    lines += [
        (
            f"warm-up window (from {w['t_min']} min, 1 min): median RSS {w['rss_mb']} MB, fds <= {w['fds']}, "
            f"threads <= {w['threads']}"
        ),
        (
            f"last minute (to {e['t_min']} min, {last['loops']} loops): median RSS {e['rss_mb']} MB "
            f"({figures['rss_growth']:+.1%}), fds <= {e['fds']}, threads <= {e['threads']}; max RSS of the run "
            f"{figures['rss_max_mb']} MB; frames {last['frames']}, dropped {last['dropped']}, fixes ok "
            f"{last['fixes_ok']}, valid GPS_INPUT {last['gps_valid']}, UAV reboots seen {last['reboots']}"
        ),
        "PASS" if not failed else "FAIL: " + "; ".join(failed),
    ]
    print("\n".join(lines[-3:]))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines) + "\n")
    return 0 if not failed else 1


if __name__ == "__main__":
    sys.exit(main())

"""Restarts and start-up mistakes, timed from outside ``skyfix run`` (issue 29: back within 3 s; a mistake is exit 2
and one line within a second).

    .venv/bin/python bench/restart.py [--kills 3] [--out bench/results/restart.txt]

- restart: ``deploy/field.toml`` as shipped (endpoints on loopback) under ``deploy/skyfix.service``'s restart policy,
  run by the stand-in supervisor of the tests (groundstation/testing/supervisor.py: Restart=on-failure, its RestartSec); ``kill -9``
  of the service ``--kills`` times: the time from the kill to the first GPS_INPUT of the next start (the kernel's
  receive time at the UUV's endpoint), the CPU time the new process had used by then (``/proc``: what the wall
  time comes to on an idle machine), and each start's recording folder;
- restart with fixes: the same, the bundled ``nadir_hover`` session replayed into each start (the calibration its own,
  its depth as skyfix JSON; everything else ``field.toml``'s): each start's first valid (3D) GPS_INPUT after the kill,
  and how far it lies from the last valid one before the kill (the track kept on disk: within the reach, or the
  gate holds it), the valid GPS_INPUT farther than ``field.toml``'s reach plus 3 h_acc from it (must be 0), each
  start's recording folder;
- mistakes: each start-up mistake of tests/test_cli_first_use.py, the time from the command's start to its exit
  (exit code 2, one line), and its CPU time.

On a loaded machine the wall times grow with the load (printed first): the CPU times are the start's own cost.

Prints both and writes them to ``--out``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from groundstation.testing.live import GpsInputEndpoint, skyfix, start, stop, wait_until
from groundstation.testing.supervisor import Supervisor, field_config
from localizer.geodesy import horizontal_error_m

ROOT = Path(__file__).resolve().parents[1]
BACK_S = 3.0
MISTAKE_S = 1.0
MISTAKES = {
    "--video /no/such/file.mp4": ["--video", "/no/such/file.mp4", "--gps-input", "none"],
    "--video htp://…": ["--video", "htp://192.168.2.2:5600/x", "--gps-input", "none"],
    "no --video": ["--gps-input", "udpout:192.168.2.2:14660"],
    "no --gps-input": ["--video", "rtp://0.0.0.0:5600?codec=h264"],
}


def cpu_s(pid: int) -> float:
    """The CPU time (user + system, s) process ``pid`` has used so far."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def restarts(work: Path, kills: int, say) -> None:
    endpoint = GpsInputEndpoint()
    config, _ = field_config(work, endpoint.port)

    def first_since(t: float) -> float | None:
        return next((t_recv for t_recv, _ in list(endpoint.received) if t_recv > t), None)

    try:
        with Supervisor(lambda argv: skyfix(*argv[1:-1], str(config)), work) as sup:
            say(f"RestartSec {sup.restart_s:g} s, start limit {sup.burst} in {sup.limit_s:g} s")
            if not wait_until(lambda: sup.starts and first_since(sup.starts[0][0]), 60):
                raise SystemExit(
                    f"the first start sent no GPS_INPUT: {sup.log(0).read_text()[-2000:]}"
                )
            say(f"first start → GPS_INPUT {first_since(sup.starts[0][0]) - sup.starts[0][0]:.3f} s")
            for k in range(kills):
                proc = sup.starts[-1][1]
                t_kill = time.time()
                os.kill(proc.pid, signal.SIGKILL)
                if not wait_until(lambda t=t_kill: first_since(t) is not None, 60, poll_s=0.02):
                    raise SystemExit(f"kill {k + 1}: no GPS_INPUT again within 60 s")
                cpu = cpu_s(sup.starts[-1][1].pid)
                back = first_since(t_kill) - t_kill
                t_start = sup.starts[-1][0]
                say(
                    f"kill -9 #{k + 1}: GPS_INPUT again after {back:.3f} s (restart at +{t_start - t_kill:.3f} s, "
                    f"its first GPS_INPUT {back - (t_start - t_kill):.3f} s after, {cpu:.2f} s of CPU)  "
                    f"{'ok' if back <= BACK_S else f'OVER {BACK_S:g} s'}"
                )
        folders = sorted(p.name for p in (work / "recordings").iterdir())
        say(
            f"exits {sup.exits}; recordings: {len(folders)} folders for {len(sup.starts)} starts: {', '.join(folders)}"
        )
    finally:
        endpoint.close()


SESSION = ROOT / "sim_fixtures" / "bundled" / "nadir_hover"


def _valid(received, t: float) -> list[tuple[float, dict]]:
    """The 3D GPS_INPUT received after ``t``."""
    return [(tr, m) for tr, m in list(received) if tr > t and m["fix_type"] >= 3]


def _apart_m(a: dict, b: dict) -> float:
    return float(horizontal_error_m(a["lat"] / 1e7, a["lon"] / 1e7, b["lat"] / 1e7, b["lon"] / 1e7))


def restarts_with_fixes(work: Path, kills: int, say) -> None:
    endpoint = GpsInputEndpoint()
    config, values = field_config(work, endpoint.port)
    values |= {
        "calibration": str(SESSION / "session.toml"),
        "depth_source": "skyfix",
        "depth_key": "uuv/depth",
    }
    config.write_text("".join(f"{k} = {json.dumps(v)}\n" for k, v in values.items()))
    reach_m = values["uuv_max_reach_m"]
    replays: list = []

    def replay(k: int):
        replays.append(
            start(
                skyfix(
                    "replay", str(SESSION), "--zenoh-connect", values["zenoh_listen"][0],
                    "--mavlink-out", "udpout:" + values["mavlink"].removeprefix("udpin:"),
                    "--video-out", values["video"].partition("?")[0],
                    "--video-delay-ms", str(values["video_latency_ms"]), "--uuv-listen", "",
                    "--lead-s", "0.5", "--tail-s", "0",
                ),
                work / f"replay{k}.log",
            )
        )  # fmt: skip

    far = 0
    try:
        with Supervisor(lambda argv: skyfix(*argv[1:-1], str(config)), work) as sup:
            wait_until(lambda: sup.starts, 30)
            replay(0)
            if not wait_until(lambda: _valid(endpoint.received, sup.starts[0][0]), 60):
                raise SystemExit(
                    f"no valid GPS_INPUT from the first start: {sup.log(0).read_text()[-2000:]}"
                )
            for k in range(kills):
                before = _valid(endpoint.received, sup.starts[-1][0])
                proc, kept = sup.starts[-1][1], before[-1][1]
                t_kill = time.time()
                os.kill(proc.pid, signal.SIGKILL)
                stop(replays[-1], 5.0)
                wait_until(lambda n=k + 2: len(sup.starts) >= n, 30, poll_s=0.02)
                replay(k + 1)
                if not wait_until(lambda t=t_kill: _valid(endpoint.received, t), 60, poll_s=0.02):
                    raise SystemExit(f"kill {k + 1}: no valid GPS_INPUT again within 60 s")
                wait_until(lambda: replays[-1].poll() is not None, 30)
                after = _valid(endpoint.received, t_kill)
                off = [
                    _apart_m(m, kept) for _, m in after
                    if _apart_m(m, kept) > reach_m + 3 * math.hypot(m["horiz_accuracy"], kept["horiz_accuracy"])
                ]  # fmt: skip
                far += len(off)
                say(
                    f"kill -9 #{k + 1} (valid fixes flowing): valid GPS_INPUT again after {after[0][0] - t_kill:.3f} s, "
                    f"{_apart_m(after[0][1], kept):.3f} m from the last valid before the kill (reach {reach_m:g} m); "
                    f"{len(after)} valid after, {len(off)} beyond reach + 3 h_acc"
                )
        folders = sorted(p.name for p in (work / "recordings").iterdir())
        state = (
            sorted(p.name for p in (work / "state").iterdir()) if (work / "state").is_dir() else []
        )
        say(
            f"exits {sup.exits}; {len(folders)} recording folders for {len(sup.starts)} starts; kept track files "
            f"{state}; valid GPS_INPUT beyond reach + 3 h_acc of the kept track: {far}"
        )
    finally:
        for r in replays:
            stop(r, 5.0)
        endpoint.close()


def mistakes(say) -> None:
    for name, options in MISTAKES.items():
        t0, before = time.perf_counter(), os.times()
        out = subprocess.run(
            [
                sys.executable,
                "-m",
                "groundstation.cli",
                "run",
                "--calibration",
                str(ROOT / "deploy" / "calibration.toml"),
                "--no-ui",
                *options,
            ],
            capture_output=True,
            text=True,
            cwd=ROOT,
            timeout=60,
            check=False,
        )
        took, after = time.perf_counter() - t0, os.times()
        cpu = (
            after.children_user
            + after.children_system
            - before.children_user
            - before.children_system
        )
        lines = out.stderr.splitlines()
        say(
            f"{name:28s} exit {out.returncode} in {took:.3f} s ({cpu:.2f} s of CPU), {len(lines)} line(s)  "
            f"{'ok' if took <= MISTAKE_S and out.returncode == 2 and len(lines) == 1 else 'NOT ok'}: {lines[-1][:90]}"
        )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--kills", type=int, default=3)
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "restart.txt")
    args = ap.parse_args()
    lines: list[str] = []

    def say(line: str) -> None:
        print(line, flush=True)
        lines.append(line)

    say(
        f"bench/restart.py {time.strftime('%Y-%m-%d %H:%M')} — load {os.getloadavg()[0]:.1f} on {os.cpu_count()} "
        f"cores; required: back ≤ {BACK_S:g} s, a mistake ≤ {MISTAKE_S:g} s"
    )
    with tempfile.TemporaryDirectory(prefix="skyfix-restart-") as tmp:
        restarts(Path(tmp), args.kills, say)
    with tempfile.TemporaryDirectory(prefix="skyfix-restart-fixes-") as tmp:
        restarts_with_fixes(Path(tmp), args.kills, say)
    say(f"load after: {os.getloadavg()[0]:.1f}")
    mistakes(say)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())

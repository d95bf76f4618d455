"""Field conditions, offline and live: the accuracy table of issue 8's scenarios.

    .venv/bin/python bench/conditions.py [--work /tmp/skyfix-conditions] [--out bench/results/conditions.txt]
                                         [--skyfix "PYTHON -m groundstation.cli"] [--only NAME ...]

For each scenario (``sim_fixtures/scenarios/<name>.toml``; generated once into
``--work``, with video) it reports the MAE against truth of: the geometry alone
(``skyfix evaluate --use-track``), the offline pipeline with the tracker
(``skyfix evaluate``), and the live service (``skyfix replay`` → ``skyfix run`` on
loopback, fixes read off Zenoh), with the share of frames fixed. ``--skyfix`` runs
another skyfix (e.g. an older checkout's interpreter and working directory, given as
``--skyfix-cwd``) on the same sessions, for a before/after comparison.
"""

from __future__ import annotations

import argparse
import csv
import json
import shlex
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from groundstation.testing.live import (
    SUBSCRIBER,
    free_port,
    read_jsonl,
    replay_shift,
    truth_errors_m,
    wait_for,
)

ROOT = Path(__file__).resolve().parents[1]
CONDITIONS = (
    "clock_sync",
    "clock_offset",
    "nadir_vehicle_frame",
    "slow_attitude",
    "servo_mount",
    "reboot",
)
VIDEO_LATENCY_MS = 0  # the replay sends each frame at its exposure time, as in the live tests


def generate(name: str, work: Path) -> Path:
    out = work / name
    if not (out / "video.mp4").is_file():
        subprocess.run(
            [
                sys.executable,
                "-m",
                "groundstation.cli",
                "sim",
                str(ROOT / "sim_fixtures" / "scenarios" / f"{name}.toml"),
                "--out",
                str(out),
            ],
            check=True,
            cwd=ROOT,
            capture_output=True,
        )
    return out


def offline(
    skyfix: list[str], cwd: Path, session: Path, work: Path, use_track: bool
) -> tuple[float, float]:
    """(MAE m, share of frames fixed) of ``skyfix evaluate`` (refraction)."""
    out = work / ("geo" if use_track else "tracked") / session.name
    subprocess.run(
        [
            *skyfix,
            "evaluate",
            str(session),
            "--out",
            str(out),
            *(["--use-track"] if use_track else []),
        ],
        cwd=cwd,
        capture_output=True,
        check=False,
    )
    if not (out / "evaluation.csv").is_file():  # no frame had a fix
        return float("nan"), 0.0
    with open(out / "evaluation.csv", newline="") as f:
        row = next(r for r in csv.DictReader(f) if r["method"] == "refraction")
    return float(row["mae_m"]) if row["mae_m"] not in ("", "nan") else float("nan"), float(
        row["coverage"]
    )


def no_ui(skyfix: list[str], cwd: Path) -> list[str]:
    """``--no-ui`` where that skyfix serves a web page (it would take port 8080), else nothing."""
    out = subprocess.run(
        [*skyfix, "run", "--help"], check=True, cwd=cwd, capture_output=True, text=True
    )
    return ["--no-ui"] if "--no-ui" in out.stdout else []


def live(skyfix: list[str], cwd: Path, session: Path, work: Path) -> tuple[float, float]:
    """(MAE m, share of frames fixed) of the live service on a replay of ``session``."""
    d = work / "live" / session.name
    d.mkdir(parents=True, exist_ok=True)
    mav, video, uuv = free_port(), free_port(), free_port()
    ep = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    sub_out = d / "zenoh.jsonl"
    sub_out.unlink(missing_ok=True)
    run = [
        *skyfix,
        "run",
        "--calibration",
        str(session / "session.toml"),
        "--mavlink",
        f"udpin:127.0.0.1:{mav}",
        "--video",
        f"udp://127.0.0.1:{video}",
        "--video-latency-ms",
        str(VIDEO_LATENCY_MS),
        "--zenoh-listen",
        ep,
        "--gps-input",
        f"udpout:127.0.0.1:{uuv}",
        "--duration-s",
        "40",
        *no_ui(skyfix, cwd),
    ]
    replay = [
        *skyfix,
        "replay",
        str(session),
        "--mavlink-out",
        f"udpout:127.0.0.1:{mav}",
        "--video-out",
        f"udp://127.0.0.1:{video}",
        "--zenoh-connect",
        ep,
        "--uuv-listen",
        f"udpin:127.0.0.1:{uuv}",
        "--uuv-log",
        str(d / "uuv.jsonl"),
        "--tail-s",
        "1.5",
    ]
    logs = [open(d / f"{n}.log", "w") for n in ("run", "sub", "replay")]  # noqa: SIM115 - closed below
    procs = [
        subprocess.Popen(run, cwd=cwd, stdout=logs[0], stderr=subprocess.STDOUT),
        subprocess.Popen(
            [sys.executable, "-c", SUBSCRIBER, ep, "skyfix/**", str(sub_out)],
            stdout=logs[1],
            stderr=subprocess.STDOUT,
        ),
    ]
    try:
        wait_for(
            lambda: any(r["key"] == "skyfix/status" for r in read_jsonl(sub_out)),
            30,
            "the service's status",
        )
        procs.append(subprocess.Popen(replay, cwd=cwd, stdout=logs[2], stderr=subprocess.STDOUT))
        procs[2].wait(120)
        time.sleep(1.0)
    finally:
        for p in procs:
            if p.poll() is None:
                p.terminate()
                p.wait(10)
        for f in logs:
            f.close()
    shift = replay_shift(d / "replay.log")
    fixes = [json.loads(s["payload"]) for s in read_jsonl(sub_out) if s["key"] == "skyfix/uuv/fix"]
    ok = [f for f in fixes if f["status"] == "ok"]
    n = len((session / "video_frames.csv").read_text().splitlines()) - 1
    if not ok:
        return float("nan"), 0.0
    err = truth_errors_m(
        session,
        np.array([f["t"] for f in ok]) - shift,
        np.array([f["lat"] for f in ok]),
        np.array([f["lon"] for f in ok]),
    )
    return float(err.mean()), len(ok) / n


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--work", default="/tmp/skyfix-conditions")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "conditions.txt"))
    ap.add_argument("--skyfix", default=f"{sys.executable} -m groundstation.cli")
    ap.add_argument("--skyfix-cwd", default=str(ROOT))
    ap.add_argument("--only", nargs="*", default=CONDITIONS)
    args = ap.parse_args()
    work, skyfix, cwd = Path(args.work), shlex.split(args.skyfix), Path(args.skyfix_cwd)
    work.mkdir(parents=True, exist_ok=True)
    label = cwd.name if cwd != ROOT else "this checkout"
    lines = [
        f"skyfix field conditions ({label}): MAE m (share of frames fixed)",
        f"command: {' '.join(sys.argv)}   date: {time.strftime('%Y-%m-%d %H:%M:%S %Z')}",
        "",
        f"{'scenario':<20} {'geometry only':>16} {'offline tracked':>16} {'live':>16}",
    ]
    print("\n".join(lines), flush=True)
    for name in args.only:
        session = generate(name, work)
        results = [
            offline(skyfix, cwd, session, work / label, True),
            offline(skyfix, cwd, session, work / label, False),
            live(skyfix, cwd, session, work / label),
        ]
        cells = [f"{mae:.4f} ({share:4.0%})" for mae, share in results]
        lines.append(f"{name:<20} {cells[0]:>16} {cells[1]:>16} {cells[2]:>16}")
        print(lines[-1], flush=True)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

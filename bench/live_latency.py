"""Benchmark of the live service: frame arrival → GPS_INPUT sent, drops, CPU and memory.

    .venv/bin/python bench/live_latency.py [--session DIR] [--out bench/results/live_latency.txt]

Replays a 1080p30 session of ≥ 60 s (``skyfix replay``: MAVLink over UDP, depth
over Zenoh, H.264 MPEG-TS over UDP via ffmpeg) into ``skyfix run`` on loopback
and reports, from the service's own measurements (``--stats``): the latency from
a frame's arrival (the decoded frame handed over by the video reader; decoding
and the link come before it and are what ``--video-latency-ms`` stands for) to
the GPS_INPUT carrying its fix leaving (p50/p99/max),
frames dropped by the pipeline and frames lost before it, and, sampled from /proc,
the service's CPU use (% of one core) over its first and last 10 s of video and
its resident memory then. Baseline in the same run: the same per-frame work
(tracker + pose + locate, :meth:`groundstation.pipeline.Pipeline.process`) timed
offline on the session's decoded frames, without links, queues or scheduling.
Without ``--session`` a session is generated once into ``/tmp/skyfix-bench`` by
the simulator (scenario below; this takes several minutes).
Targets (issue 5): p50 ≤ 10 ms, p99 ≤ 33 ms, no drops, flat RSS.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from groundstation.pipeline import Pipeline
from groundstation.session import load_session
from groundstation.sources.video_live import LiveFrame
from groundstation.video import open_video

SCENARIO = """\
name = "live_1080p"
description = "62 s of 1920x1080 at 30 fps, UAV hovering 10 m over the UUV: the live latency benchmark"
seed = 21
duration_s = 62.0

[camera]
width = 1920
height = 1080

[mount]
attitude_source = "gimbal_device"
gimbal_frame = "earth"
pitch_deg = -90.0

[uav]
height_m = 10.0

[uuv]
depth_m = 1.0
"""
DEFAULT_SESSION = Path("/tmp/skyfix-bench/live_1080p")
WINDOW_S = 10.0
CLK_TCK = os.sysconf("SC_CLK_TCK")


def ensure_session(path: Path) -> Path:
    if (path / "session.toml").exists():
        return path
    import tomllib

    from sim_fixtures.generate import generate
    from sim_fixtures.scenario import scenario_from_dict

    print(f"generating {path} (once) ...", flush=True)
    generate(scenario_from_dict(tomllib.loads(SCENARIO)), path, SCENARIO)
    return path


def free_port(kind=socket.SOCK_DGRAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def proc_sample(pid: int) -> tuple[float, float]:
    """(CPU seconds used so far, resident memory in MB) of a process."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    cpu_s = (int(fields[11]) + int(fields[12])) / CLK_TCK  # utime, stime
    rss_kb = next(int(line.split()[1]) for line in Path(f"/proc/{pid}/status").read_text().splitlines()
                  if line.startswith("VmRSS:"))
    return cpu_s, rss_kb / 1024.0


def offline_baseline(session_dir: Path, n_frames: int) -> dict:
    """Per-frame time (ms) of Pipeline.process on decoded frames, telemetry preloaded."""
    session = load_session(session_dir)
    cal = session.calibration
    pipeline = Pipeline(cal, session.telemetry, "default", [])
    times = []

    async def work():
        with open_video(session.video_path, expected_size=(cal.camera.width, cal.camera.height)) as video:
            for frame in video:
                if frame.index >= n_frames:
                    break
                t = float(session.frames["t"][frame.index])
                t0 = time.perf_counter()
                await pipeline.process(LiveFrame(frame.index, t, t, frame.image))
                times.append(time.perf_counter() - t0)

    asyncio.run(work())
    ms = np.array(times[1:]) * 1000.0  # frame 0 is the tracker's init
    return {"n": len(ms), "p50_ms": float(np.percentile(ms, 50)), "p99_ms": float(np.percentile(ms, 99))}


def live(session_dir: Path, work: Path) -> dict:
    mav, video, uuv, zport = free_port(), free_port(), free_port(), free_port(socket.SOCK_STREAM)
    ep = f"tcp/127.0.0.1:{zport}"
    stats = work / "stats.json"
    py = sys.executable
    run = [py, "-m", "groundstation.cli", "run", "--calibration", str(session_dir / "session.toml"),
           "--mavlink", f"udpin:127.0.0.1:{mav}", "--video", f"udp://127.0.0.1:{video}", "--video-latency-ms", "180",
           "--zenoh-listen", ep, "--gps-input", f"udpout:127.0.0.1:{uuv}", "--stats", str(stats)]
    replay = [py, "-m", "groundstation.cli", "replay", str(session_dir), "--mavlink-out", f"udpout:127.0.0.1:{mav}",
              "--video-out", f"udp://127.0.0.1:{video}", "--zenoh-connect", ep, "--uuv-listen",
              f"udpin:127.0.0.1:{uuv}", "--uuv-log", str(work / "uuv.jsonl"), "--lead-s", "2"]
    samples = []  # (time, cpu_s, rss_mb)
    with open(work / "run.log", "w") as run_log, open(work / "replay.log", "w") as replay_log:
        service = subprocess.Popen(run, stdout=run_log, stderr=subprocess.STDOUT, cwd=ROOT)
        try:
            time.sleep(3.0)
            rep = subprocess.Popen(replay, stdout=replay_log, stderr=subprocess.STDOUT, cwd=ROOT)
            while rep.poll() is None:
                samples.append((time.time(), *proc_sample(service.pid)))
                time.sleep(0.5)
            service.send_signal(signal.SIGINT)
            service.wait(30)
        finally:
            for p in (service, rep):
                if p.poll() is None:
                    p.kill()
    final = json.loads(stats.read_text())
    start = json.loads((work / "replay.log").read_text().splitlines()[0])
    frames_t = load_session(session_dir).frames["t"] + start["shift_s"]
    s = np.array(samples)

    def window(t0, t1):
        sel = (s[:, 0] >= t0) & (s[:, 0] <= t1)
        w = s[sel]
        return {"cpu_pct": 100.0 * (w[-1, 1] - w[0, 1]) / (w[-1, 0] - w[0, 0]), "rss_mb": float(w[-1, 2])}

    return {
        "frames_sent": len(frames_t),
        "frames_received": final["video"]["frames"],
        "processed": final["pipeline"]["processed"],
        "dropped": final["pipeline"]["dropped"],
        "statuses": final["pipeline"]["statuses"],
        "latency": final["latency"],
        "gps_input_sent": final["gps_input"]["sent"],
        "start": window(frames_t[0], frames_t[0] + WINDOW_S),
        "end": window(frames_t[-1] - WINDOW_S, frames_t[-1]),
        "rss_max_mb": float(s[:, 2].max()),
        "video_s": float(frames_t[-1] - frames_t[0]),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--session", type=Path, help="session to replay (default: generate a 1080p30 62 s one)")
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "live_latency.txt")
    ap.add_argument("--baseline-frames", type=int, default=300)
    args = ap.parse_args()
    session = ensure_session(args.session or DEFAULT_SESSION)
    work = Path("/tmp/skyfix-bench/live_run")
    work.mkdir(parents=True, exist_ok=True)
    for f in work.iterdir():
        f.unlink()

    base = offline_baseline(session, args.baseline_frames)
    res = live(session, work)
    cam = load_session(session).calibration.camera
    lat = res["latency"]
    lines = [
        f"skyfix live latency benchmark, {time.strftime('%Y-%m-%d %H:%M:%S %Z')}, {os.cpu_count()} cores",
        f"session {session} ({cam.width}x{cam.height}, {res['frames_sent']} frames, {res['video_s']:.1f} s)",
        (f"baseline (offline Pipeline.process per frame, {base['n']} frames): p50 {base['p50_ms']:.2f} ms, "
         f"p99 {base['p99_ms']:.2f} ms"),
        (f"live: frame arrival -> GPS_INPUT sent over {lat['n']} fixes: p50 {lat['p50_ms']:.2f} ms, "
         f"p99 {lat['p99_ms']:.2f} ms, max {lat['max_ms']:.2f} ms   (target p50 <= 10, p99 <= 33)"),
        (f"frames: sent {res['frames_sent']}, received {res['frames_received']}, processed {res['processed']}, "
         f"dropped by the pipeline {res['dropped']}   (target 0); statuses {res['statuses']}"),
        f"GPS_INPUT messages sent: {res['gps_input_sent']}",
        (f"CPU (% of one core) first {WINDOW_S:.0f} s: {res['start']['cpu_pct']:.0f} %, last {WINDOW_S:.0f} s: "
         f"{res['end']['cpu_pct']:.0f} %"),
        f"RSS: start {res['start']['rss_mb']:.1f} MB, end {res['end']['rss_mb']:.1f} MB, max {res['rss_max_mb']:.1f} MB",
    ]
    text = "\n".join(lines) + "\n"
    print(text, end="")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    args.out.with_suffix(".json").write_text(json.dumps({"baseline": base, **res}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

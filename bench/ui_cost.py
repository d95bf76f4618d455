"""What the web page costs the live service: CPU and frame → GPS_INPUT latency with the page open and without.

    .venv/bin/python bench/ui_cost.py [--session DIR] [--rounds 2] [--out bench/results/ui_cost.txt]

Replays a 1080p30 session (``skyfix replay``: MAVLink over UDP, depth over Zenoh, H.264 MPEG-TS over UDP via
ffmpeg) into ``skyfix run`` on loopback, once per mode and round, the modes interleaved (A B C A B C ...) so a
change in the machine's load falls on all of them:

- ``no-ui``: ``--no-ui``;
- ``ui-idle``: the page served, nobody watching;
- ``ws-reader``: a small Python program (its own process) reading the page's WebSocket, video and state, and
  nothing else: the service's own work for a watching page, without a browser competing for the cores;
- ``page-open``: the page open in a headless Chromium (Debian's, driven by Playwright) for the whole replay,
  receiving the video (at most 10 frames a second, 960 px wide JPEG) and the state, drawing both.

Per run, from the service's own ``--stats``: the latency from a frame's arrival to the GPS_INPUT carrying its fix
(p50/p99), frames dropped by the pipeline, the page's JPEG work inside the service (frames encoded × the encoding
thread's mean CPU time per frame, without OpenCV's helper threads, about a tenth more: steady where the whole
process's CPU swings with the machine's other load); sampled from /proc: the service's CPU (% of one core) over the video
(its first 2 s, the decoder's start-up burst, left out), and with the page open the browser's CPU (all its
processes) and the frames the page received. Baseline in the same run: the page's per-frame work alone
(:func:`groundstation.live.ui.feed.encode_jpeg` on one of the session's 1080p frames) times its rate, the CPU the
page should cost. Without ``--session`` a 30 s session is generated once into ``/tmp/skyfix-ui-bench``.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

from groundstation.live.ui.feed import encode_jpeg
from groundstation.session.read import load_session
from groundstation.video.file import open_video

SCENARIO = """\
name = "ui_1080p"
description = "30 s of 1920x1080 at 30 fps, UAV hovering 10 m over the UUV: the web page's cost benchmark"
seed = 21
duration_s = 30.0

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
DEFAULT_SESSION = Path("/tmp/skyfix-ui-bench/ui_1080p")
MODES = ("no-ui", "ui-idle", "ws-reader", "page-open")
# ws-reader: reads the page's WebSocket until SIGINT, then prints how many video frames came
WS_READER = r"""
import asyncio, signal, sys
import aiohttp

async def main(url):
    frames = 0
    stop = asyncio.Event()
    asyncio.get_running_loop().add_signal_handler(signal.SIGINT, stop.set)
    async with aiohttp.ClientSession() as s, s.ws_connect(url) as ws:
        reader = asyncio.ensure_future(stop.wait())
        while not stop.is_set():
            msg = asyncio.ensure_future(ws.receive())
            await asyncio.wait([msg, reader], return_when=asyncio.FIRST_COMPLETED)
            if msg.done() and msg.result().type == aiohttp.WSMsgType.BINARY:
                frames += 1
            elif not msg.done():
                msg.cancel()
    print(frames, flush=True)

asyncio.run(main(sys.argv[1]))
"""
SKIP_S = 2.0
CLK_TCK = os.sysconf("SC_CLK_TCK")
CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
FLAGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1",
]
PAGE_FPS = 10.0  # the feed's rate limit (groundstation.live.ui.feed)


def launch_browser(pw, profile: str):
    """Headless Chromium (playwright's ``pw``) with the operator's window size and :data:`FLAGS`, its profile in
    ``profile``: the page as a field laptop shows it."""
    return pw.chromium.launch_persistent_context(
        profile,
        executable_path=CHROMIUM,
        headless=True,
        args=FLAGS,
        viewport={"width": 1400, "height": 1000},
    )


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


def cpu_s(pid: int) -> float:
    """CPU seconds (user + system) a process has used so far."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLK_TCK


def browser_cpu_s(root: int) -> float:
    """CPU seconds used so far by the Chromium processes below ``root`` (this process)."""
    parent, names = {}, {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            text = stat.read_text()
        except OSError:
            continue
        pid = int(stat.parent.name)
        names[pid] = text[text.index("(") + 1 : text.rindex(")")]
        parent[pid] = int(text.rsplit(")", 1)[1].split()[1])
    total = 0.0
    for pid, name in names.items():
        p = pid
        while p in parent and p != root and p > 1:
            p = parent[p]
        if p == root and "chrom" in name:
            try:
                total += cpu_s(pid)
            except OSError:
                pass
    return total


def encode_baseline(session_dir: Path, n: int = 100) -> dict:
    """CPU ms per frame of the page's JPEG work on one of the session's frames."""
    session = load_session(session_dir)
    with open_video(session.video_path) as video:
        image = next(iter(video)).image
    encode_jpeg(image, 960, 80)
    # CPU, OpenCV's helper threads included (this process does nothing else meanwhile)
    t0 = time.process_time()
    for _ in range(n):
        encode_jpeg(image, 960, 80)
    ms = (time.process_time() - t0) / n * 1000.0
    return {
        "frame": f"{image.shape[1]}x{image.shape[0]}",
        "encode_ms": ms,
        "cpu_pct_at_page_fps": ms * PAGE_FPS / 10.0,
    }


def one_run(session_dir: Path, work: Path, mode: str) -> dict:
    mav, video, uuv, zport = free_port(), free_port(), free_port(), free_port(socket.SOCK_STREAM)
    ep = f"tcp/127.0.0.1:{zport}"
    stats = work / f"stats-{mode}.json"
    py = sys.executable
    ui = ["--no-ui"] if mode == "no-ui" else ["--ui", "127.0.0.1:0"]
    run = [
        py,
        "-m",
        "groundstation.cli",
        "run",
        "--calibration",
        str(session_dir / "session.toml"),
        "--mavlink",
        f"udpin:127.0.0.1:{mav}",
        "--video",
        f"udp://127.0.0.1:{video}",
        "--video-latency-ms",
        "180",
        "--zenoh-listen",
        ep,
        "--gps-input",
        f"udpout:127.0.0.1:{uuv}",
        "--stats",
        str(stats),
        *ui,
    ]
    replay = [
        py,
        "-m",
        "groundstation.cli",
        "replay",
        str(session_dir),
        "--mavlink-out",
        f"udpout:127.0.0.1:{mav}",
        "--video-out",
        f"udp://127.0.0.1:{video}",
        "--zenoh-connect",
        ep,
        "--uuv-listen",
        f"udpin:127.0.0.1:{uuv}",
        "--uuv-log",
        str(work / f"uuv-{mode}.jsonl"),
        "--lead-s",
        "2",
    ]
    run_log, replay_log = work / f"run-{mode}.log", work / f"replay-{mode}.log"
    samples = []  # (time, service CPU s, browser CPU s)
    received = None
    with (
        open(run_log, "w") as rl,
        open(replay_log, "w") as pl,
        tempfile.TemporaryDirectory() as profile,
    ):
        service = subprocess.Popen(run, stdout=rl, stderr=subprocess.STDOUT, cwd=ROOT)
        rep = reader = None
        pw = context = None
        try:
            url = None
            for _ in range(200):
                m = re.search(r"web page: (\S+)", run_log.read_text())
                if m or mode == "no-ui" and "skyfix run: UAV" in run_log.read_text():
                    url = m[1] if m else None
                    break
                time.sleep(0.1)
            if mode == "ws-reader":
                reader = subprocess.Popen(
                    [py, "-c", WS_READER, url.replace("http://", "ws://") + "ws"],
                    stdout=subprocess.PIPE,
                    text=True,
                )
            if mode == "page-open":
                from playwright.sync_api import sync_playwright

                pw = sync_playwright().start()
                context = launch_browser(pw, profile)
                page = context.new_page()
                page.goto(url)
                page.wait_for_selector("#conn.ok", timeout=30_000)
            time.sleep(1.0)
            rep = subprocess.Popen(replay, stdout=pl, stderr=subprocess.STDOUT, cwd=ROOT)
            while rep.poll() is None:
                samples.append(
                    (
                        time.time(),
                        cpu_s(service.pid),
                        browser_cpu_s(os.getpid()) if context else 0.0,
                    )
                )
                if context:
                    page.wait_for_timeout(500)  # lets Playwright's event loop run
                else:
                    time.sleep(0.5)
            if context:
                received = int(page.eval_on_selector("#video", "c => c.dataset.received"))
            if reader:
                reader.send_signal(signal.SIGINT)
                received = int(reader.communicate(timeout=30)[0].strip())
            service.send_signal(signal.SIGINT)
            service.wait(60)
        finally:
            if context:
                context.close()
            if pw:
                pw.stop()
            for p in (service, rep, reader):
                if p is not None and p.poll() is None:
                    p.kill()
    final = json.loads(stats.read_text())
    shift = json.loads(replay_log.read_text().splitlines()[0])["shift_s"]
    frames_t = load_session(session_dir).frames["t"] + shift
    s = np.array(samples)
    sel = (s[:, 0] >= frames_t[0] + SKIP_S) & (s[:, 0] <= frames_t[-1])
    w = s[sel]
    dt = w[-1, 0] - w[0, 0]
    return {
        "mode": mode,
        "cpu_pct": 100.0 * (w[-1, 1] - w[0, 1]) / dt,
        "browser_cpu_pct": 100.0 * (w[-1, 2] - w[0, 2]) / dt if mode == "page-open" else None,
        "latency": final["latency"],
        "frames_received": final["video"]["frames"],
        "processed": final["pipeline"]["processed"],
        "dropped": final["pipeline"]["dropped"],
        "page_frames": received,
        "jpeg_encoded": final.get("ui", {}).get("frames_encoded"),
        "encode_ms": final.get("ui", {}).get("encode_ms"),
        "video_s": float(frames_t[-1] - frames_t[0]),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--session", type=Path, help="session to replay (default: generate a 1080p30 30 s one)"
    )
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "ui_cost.txt")
    args = ap.parse_args()
    session = ensure_session(args.session or DEFAULT_SESSION)
    work = Path("/tmp/skyfix-ui-bench/runs")
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)

    base = encode_baseline(session)
    runs = []
    for r in range(args.rounds):
        for mode in MODES:
            res = one_run(session, work, mode)
            print(
                f"round {r + 1} {mode}: CPU {res['cpu_pct']:.1f} %, latency p50 {res['latency']['p50_ms']:.1f} ms "
                f"p99 {res['latency']['p99_ms']:.1f} ms, dropped {res['dropped']}, page frames {res['page_frames']}",
                flush=True,
            )
            runs.append(res)

    def med(mode, get):
        values = [get(x) for x in runs if x["mode"] == mode and get(x) is not None]
        return statistics.median(values) if values else float("nan")

    cam = load_session(session).calibration.camera
    lines = [
        (
            f"skyfix web page cost benchmark, {time.strftime('%Y-%m-%d %H:%M:%S %Z')}, {os.cpu_count()} cores, "
            f"load average {os.getloadavg()[0]:.1f}"
        ),
        (
            f"session {session} ({cam.width}x{cam.height}, {runs[0]['video_s']:.1f} s of video), {args.rounds} rounds "
            "per mode, interleaved; medians"
        ),
        (
            f"baseline: the page's JPEG work alone, {base['frame']} -> 960 px wide: {base['encode_ms']:.2f} ms CPU a frame, "
            f"{base['cpu_pct_at_page_fps']:.1f} % of one core at {PAGE_FPS:g} frames/s"
        ),
        (
            f"{'mode':<10} {'service CPU %':>14} {'of it JPEG %':>13} {'p50 ms':>8} {'p99 ms':>8} {'dropped':>8} "
            f"{'page fps':>9} {'browser CPU %':>14}"
        ),
    ]
    for mode in MODES:
        page_fps = med(
            mode,
            lambda x: x["page_frames"] / x["video_s"] if x["page_frames"] is not None else None,
        )
        jpeg = med(
            mode,
            lambda x: (
                x["jpeg_encoded"] * x["encode_ms"] / 10.0 / x["video_s"]
                if x["jpeg_encoded"] and x["encode_ms"]
                else None
            ),
        )
        lines.append(
            f"{mode:<10} {med(mode, lambda x: x['cpu_pct']):>14.1f} {jpeg:>13.1f} "
            f"{med(mode, lambda x: x['latency']['p50_ms']):>8.1f} "
            f"{med(mode, lambda x: x['latency']['p99_ms']):>8.1f} {med(mode, lambda x: x['dropped']):>8.0f} "
            f"{page_fps:>9.1f} {med(mode, lambda x: x['browser_cpu_pct']):>14.1f}"
        )

    def paired(
        mode, get
    ):  # per round, the mode minus --no-ui (the same round's load): their median
        a = [get(x) for x in runs if x["mode"] == mode]
        b = [get(x) for x in runs if x["mode"] == "no-ui"]
        return statistics.median(x - y for x, y in zip(a, b, strict=True)), [
            round(float(x - y), 1) for x, y in zip(a, b)
        ]

    for mode in MODES[1:]:
        d_cpu, each_cpu = paired(mode, lambda x: x["cpu_pct"])
        d_p50, _ = paired(mode, lambda x: x["latency"]["p50_ms"])
        d_p99, _ = paired(mode, lambda x: x["latency"]["p99_ms"])
        lines.append(
            f"{mode} minus --no-ui: service CPU {d_cpu:+.1f} % of one core (per round {each_cpu}), "
            f"latency p50 {d_p50:+.1f} ms, p99 {d_p99:+.1f} ms"
        )
    lines.append(
        f"(the baseline predicts {base['cpu_pct_at_page_fps']:+.1f} % for a watching page)"
    )
    text = "\n".join(lines) + "\n"
    print(text, end="")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    args.out.with_suffix(".json").write_text(json.dumps({"baseline": base, "runs": runs}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

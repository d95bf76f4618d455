"""``skyfix latency --video URL``: the camera's glass-to-first-packet latency, measured.

The command serves a page (``http://127.0.0.1:8765/``, no internet needed) that
shows the station clock as a time code (:mod:`groundstation.latency.timecode`) on every
display frame; open it full screen on the laptop and point the UAV's camera at
it. Each frame of the stream is timed by its packets (its stream slot, as
``skyfix run`` times it) and the code in it read back: the slot minus the time the
code showed is the latency from glass to first packet. The page draws the time
its frame will reach the screen (the animation frame's time plus one display
period), keeps to the station clock by asking the command for it (so a phone or
another screen works too), and reports its display period: a code is on screen
for one period and the camera catches it somewhere within, so half a period is
taken off. The display's own lag (panel response) is not measured: a few ms on a
laptop panel. Prints the distribution and the ``--video-latency-ms`` to configure,
then one JSON line with the numbers.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from urllib.parse import parse_qs, urlsplit

import numpy as np

from groundstation.latency.timecode import CELLS, marker_cells, read_timecode
from groundstation.runtime.zenoh_session import ZenohError, open_session
from groundstation.video.frames import LiveFrame, VideoError
from groundstation.video.live import VideoLive

log = logging.getLogger("skyfix.latency")

MAX_LATENCY_S = 3.0  # a reading further from the slot than this is a misread, not a latency

PAGE = """<!doctype html>
<html><head><meta charset="utf-8"><title>skyfix latency</title>
<style>html,body{margin:0;height:100%;background:#fff;overflow:hidden}canvas{display:block}
#t{position:fixed;bottom:1vh;width:100%;text-align:center;font:4vh monospace;color:#000}</style></head>
<body><canvas id="c"></canvas><div id="t"></div><script>
const MARKERS = __MARKERS__, CELLS = __CELLS__;
const c = document.getElementById("c"), g = c.getContext("2d"), label = document.getElementById("t");
let offsetMs = 0, bestRtt = Infinity, periods = [], last = null;
function now() { return performance.timeOrigin + performance.now() + offsetMs; }
async function sync() {
  const period = periods.length ? [...periods].sort((a, b) => a - b)[periods.length >> 1] : 0;
  const t0 = performance.timeOrigin + performance.now();
  const r = await fetch("/now?period_ms=" + period.toFixed(3), {cache: "no-store"});
  const t1 = performance.timeOrigin + performance.now(), server = (await r.json()).t_unix * 1000;
  if (t1 - t0 <= bestRtt * 1.5) { bestRtt = Math.min(bestRtt, t1 - t0); offsetMs = server - (t0 + t1) / 2; }
}
function draw(ts) {
  if (last !== null) { periods.push(ts - last); if (periods.length > 120) periods.shift(); }
  last = ts;
  const period = periods.length ? [...periods].sort((a, b) => a - b)[periods.length >> 1] : 16.7;
  const t = Math.floor(now() + period) % 1e9, groups = [Math.floor(t / 1e6), Math.floor(t / 1e3) % 1e3, t % 1e3];
  c.width = innerWidth; c.height = innerHeight;
  g.fillStyle = "#fff"; g.fillRect(0, 0, c.width, c.height);
  const side = Math.floor(Math.min(c.width / 4, c.height * 0.8) / CELLS) * CELLS, cell = side / CELLS;
  const gap = (c.width - 3 * side) / 4, top = (c.height - side) / 2;
  g.fillStyle = "#000";
  groups.forEach((id, k) => {
    const left = gap + k * (side + gap), m = MARKERS[id];
    for (let i = 0; i < CELLS * CELLS; i++) if (!m[i])
      g.fillRect(Math.floor(left + (i % CELLS) * cell), Math.floor(top + Math.floor(i / CELLS) * cell),
                 Math.ceil(cell), Math.ceil(cell));
  });
  label.textContent = new Date(t).toISOString().slice(11, 23) + "  (station clock, sync ±" +
      (bestRtt / 2).toFixed(1) + " ms)";
  requestAnimationFrame(draw);
}
sync(); setInterval(sync, 1000); requestAnimationFrame(draw);
</script></body></html>
"""


class TimecodePage:
    """The page and the station clock, served over HTTP in a thread; remembers the display period it reports."""

    def __init__(self, host: str, port: int):
        page = PAGE.replace("__MARKERS__", json.dumps(marker_cells(), separators=(",", ":")))
        body = page.replace("__CELLS__", str(CELLS)).encode()
        owner = self
        self.period_s: float | None = None

        class Handler(BaseHTTPRequestHandler):
            def do_GET(self):
                url = urlsplit(self.path)
                if url.path == "/now":
                    period = parse_qs(url.query).get("period_ms", ["0"])[0]
                    try:
                        if 2.0 <= float(period) <= 100.0:
                            owner.period_s = float(period) / 1000.0
                    except ValueError:
                        pass
                    data, kind = json.dumps({"t_unix": time.time()}).encode(), "application/json"
                elif url.path == "/":
                    data, kind = body, "text/html; charset=utf-8"
                else:
                    self.send_error(404)
                    return
                self.send_response(200)
                self.send_header("Content-Type", kind)
                self.send_header("Cache-Control", "no-store")
                self.send_header("Content-Length", str(len(data)))
                self.end_headers()
                self.wfile.write(data)

            def log_message(self, *args):
                pass

        self.server = ThreadingHTTPServer((host, port), Handler)
        self.url = f"http://{host}:{self.server.server_address[1]}/"
        self._thread = threading.Thread(
            target=self.server.serve_forever, name="timecode-page", daemon=True
        )

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self.server.shutdown()
        self.server.server_close()


def summary(samples_s: list[float], period_s: float) -> dict:
    """The latency distribution (ms) and the value to configure: the median less half a display period."""
    a = np.asarray(samples_s) * 1000.0
    q = {f"p{p}": round(float(np.percentile(a, p)), 1) for p in (5, 25, 50, 75, 95)}
    return {
        "n": len(a),
        **q,
        "display_period_ms": round(period_s * 1000.0, 2),
        "video_latency_ms": round(q["p50"] - period_s * 500.0, 1),
    }


async def measure(
    url: str,
    duration_s: float,
    max_samples: int,
    page: TimecodePage,
    display_hz: float,
    session=None,
) -> dict:
    """Read the time code from the stream's frames until enough samples or time; the summary. ``session``: the
    Zenoh session a ``zenoh:`` video comes on."""
    samples: list[float] = []
    frames = 0
    busy = False
    pool = ThreadPoolExecutor(1)
    loop = asyncio.get_running_loop()
    done = asyncio.Event()

    def on_frame(frame: LiveFrame) -> None:
        nonlocal frames, busy
        frames += 1
        if (
            busy
        ):  # reading a code takes longer than a frame at high resolutions: take the next free one
            return
        busy = True
        loop.run_in_executor(pool, read_timecode, frame.image, frame.t_slot).add_done_callback(
            lambda f, t_slot=frame.t_slot: loop.call_soon_threadsafe(
                took, t_slot, None if f.exception() is not None else f.result()
            )
        )

    def took(t_slot: float, t_code: float | None) -> None:
        nonlocal busy
        busy = False
        if t_code is not None and -0.1 <= t_slot - t_code <= MAX_LATENCY_S:
            samples.append(t_slot - t_code)
            if len(samples) >= max_samples:
                done.set()

    video = VideoLive(url, 0.0, on_frame, session=session)
    task = asyncio.create_task(video.run())
    try:
        await asyncio.wait_for(done.wait(), timeout=duration_s)
    except TimeoutError:
        pass
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
        pool.shutdown(wait=True)
    period_s = page.period_s or 1.0 / display_hz
    out = {"frames": frames, "video": video.status(time.time())}
    if samples:
        out["latency"] = summary(samples, period_s)
    return out


def latency(args: argparse.Namespace) -> int:
    logging.basicConfig(
        level=logging.WARNING, format="%(asctime)s %(name)s %(levelname)s: %(message)s"
    )
    try:
        page = TimecodePage(args.host, args.port)
    except OSError as e:
        print(f"skyfix latency: error: --port {args.port}: {e.strerror}", file=sys.stderr)
        return 2
    with page:
        print(
            f"Open {page.url} full screen on this laptop and film it with the UAV's camera "
            f"({args.video}); measuring for up to {args.duration_s:g} s ...",
            flush=True,
        )
        session = None
        try:
            # BlueOS's camera manager on Zenoh (groundstation.video.zenoh_video)
            if args.video.startswith("zenoh:"):
                session = open_session(args.zenoh_connect or (), config_file=args.zenoh_config)
            result = asyncio.run(
                measure(args.video, args.duration_s, args.samples, page, args.display_hz, session)
            )
        except (VideoError, ZenohError) as e:
            print(f"skyfix latency: error: {e}", file=sys.stderr)
            return 2
        finally:
            if session is not None:
                session.close()
    lat = result.get("latency")
    if lat is None:
        why = result["video"]["error"] or "no time code recognised"
        print(
            f"skyfix latency: no measurement in {result['frames']} frames: {why}", file=sys.stderr
        )
        print(json.dumps(result))
        return 1
    print(
        f"glass to first packet over {lat['n']} frames: p5 {lat['p5']} ms, p25 {lat['p25']}, "
        f"median {lat['p50']}, p75 {lat['p75']}, p95 {lat['p95']} ms (display period {lat['display_period_ms']} ms)"
    )
    print(f"configure: --video-latency-ms {lat['video_latency_ms']:g}")
    print(json.dumps(result))
    return 0


def register(subparsers, name: str, help: str | None = None) -> None:
    """Adds the subcommand ``name`` with its one-line ``help`` (both from :data:`groundstation.cli.COMMANDS`)."""
    p = subparsers.add_parser(name, help=help, description=__doc__.split("\n\n")[0])
    p.add_argument("--video", required=True, help="the UAV's video, as for skyfix run")
    p.add_argument(
        "--zenoh-connect",
        action="append",
        metavar="ENDPOINT",
        help="a zenoh: video's Zenoh endpoint (BlueOS's router, e.g. tls/192.168.2.2:7447)",
    )
    p.add_argument("--zenoh-config", help="a zenoh: video's Zenoh JSON5 config file")
    p.add_argument("--host", default="127.0.0.1", help="address the time code page is served on")
    p.add_argument(
        "--port", type=int, default=8765, help="port of the time code page (0: any free one)"
    )
    p.add_argument("--duration-s", type=float, default=60.0, help="stop after this many seconds")
    p.add_argument("--samples", type=int, default=300, help="stop after this many readings")
    p.add_argument(
        "--display-hz",
        type=float,
        default=60.0,
        help="display refresh rate, when the page has not reported its own",
    )
    p.set_defaults(func=latency)

"""Benchmark of the target's life: what tracking, acquisition and selection cost per frame, and the frames held.

    .venv/bin/python bench/target.py [SESSION] [--out bench/results]

On a session's decoded frames (default: the bundled ``nadir_hover``), all in one run:

- baseline: :meth:`TrackingSession.step` while tracking, with the session's poses
  computed at once (what ``skyfix process`` does per frame);
- live per frame: :meth:`groundstation.live.pipeline.Pipeline.process` (the frame's pose
  computed once, the step, the geometry with the same pose), telemetry preloaded;
- awaiting a target near the UUV's own estimate (3 m off, 1-sigma 3 m), until it is
  confirmed, and with an estimate 40 m off (never found: the steady cost of searching);
- a selection by click; a selection 1 s back with the catch-up through the held frames;
- the memory the held frames take (``--select-history-s``), at this size and at 1080p.

Times are CPU time of the process (all threads), steadier than wall time on a shared
machine. Prints the numbers and writes them to ``OUT/target-<session>.json``.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
import time
from pathlib import Path

import numpy as np
import pymap3d

ROOT = Path(__file__).resolve().parents[1]

from groundstation.live.pipeline import Pipeline
from groundstation.session.read import load_session
from groundstation.video.file import open_video
from groundstation.video.frames import live_frame
from localizer.pose import camera_pose
from localizer.tracking.session import Prior, TrackingSession


def _ms(times_s) -> dict:
    a = np.asarray(times_s) * 1000.0
    return {
        "n": len(a),
        "p50_ms": round(float(np.percentile(a, 50)), 3),
        "p99_ms": round(float(np.percentile(a, 99)), 3),
        "mean_ms": round(float(a.mean()), 3),
    }


def _timed(fn, *args, **kw):
    """``(result, CPU seconds of this process, all threads)``: steadier than wall time on a shared machine."""
    t0 = time.process_time()
    out = fn(*args, **kw)
    return out, time.process_time() - t0


def bench(path: Path) -> dict:
    session = load_session(path)
    cal, t = session.calibration, session.frames["t"]
    with open_video(session.video_path, grey=True) as video:
        decoded = list(video)
    frames = [f.bgr() for f in decoded]
    pose = camera_pose(cal, session.telemetry, t)
    truth = session.truth
    out = {
        "session": str(path),
        "frames": len(frames),
        "size": [cal.camera.width, cal.camera.height],
    }

    ts = TrackingSession(cal)
    ts.select(frames[0], pose, 0, box=cal.init_bbox)
    steps = [_timed(ts.step, frames[i], pose, i)[1] for i in range(1, len(frames))]
    out["tracking_step"] = _ms(steps)

    pipeline = Pipeline(cal, session.telemetry, "default", [])
    live = []

    async def run_live():
        for i, frame in enumerate(decoded):
            t0 = time.process_time()
            await pipeline.process(live_frame(frame, float(t[i])))
            live.append(time.process_time() - t0)

    asyncio.run(run_live())
    out["live_per_frame"] = _ms(live[1:])  # frame 0 is the selection

    def estimate(north_m: float) -> Prior:
        lat, lon = (
            np.interp(t[0], truth["t"], truth["lat"]),
            np.interp(t[0], truth["t"], truth["lon"]),
        )
        lat, lon, _ = pymap3d.enu2geodetic(-2.0, north_m, 0.0, lat, lon, 0.0)
        return Prior(float(lat), float(lon), 3.0)

    near, far = estimate(2.0), estimate(40.0)
    ts = TrackingSession(cal)
    acquiring, acquired_at = [], None
    for i in range(len(frames)):
        result, dt = _timed(ts.step, frames[i], pose, i, near)
        if result.ok:
            acquired_at = i
            break
        acquiring.append(dt)
    out["acquiring"] = {**_ms(acquiring), "first_ok_frame": acquired_at}
    ts = TrackingSession(cal)
    searching = [_timed(ts.step, frames[i], pose, i, far)[1] for i in range(60)]
    out["awaiting_far_estimate"] = {**_ms(searching), "state": ts.state.value}

    tr = session.track
    # UUV visible
    k = next(
        i for i in range(len(t) // 2, len(t)) if np.isfinite(np.interp(t[i], tr["t"], tr["u"]))
    )
    u, v = float(np.interp(t[k], tr["t"], tr["u"])), float(np.interp(t[k], tr["t"], tr["v"]))
    clicks = [
        _timed(TrackingSession(cal).select, frames[k], pose, k, point=(u + 2.0, v - 1.0))[1]
        for _ in range(10)
    ]
    out["select_click"] = _ms(clicks)
    fps = (len(t) - 1) / (t[-1] - t[0])
    # a selection 1 s back, then the catch-up through the frames held since
    back = min(round(fps), len(t) - k - 1)

    def select_and_catch_up():
        s = TrackingSession(cal)
        s.select(frames[k], pose, k, box=_box_at(u, v, cal.init_bbox))
        for j in range(k + 1, k + 1 + back):
            s.step(frames[j], pose, j)

    out["select_1s_back_and_catch_up"] = {
        **_ms([_timed(select_and_catch_up)[1] for _ in range(5)]),
        "frames_caught_up": back,
    }
    held = pipeline._held
    per_frame = frames[0].nbytes
    out["held"] = {
        "history_s": pipeline.history_s,
        "frames": len(held),
        "mb": round(sum(h.frame.image.nbytes for h in held) / 1e6, 1),
        "mb_per_s_at_this_size": round(per_frame * fps / 1e6, 1),
        "mb_per_s_at_1080p30": round(1920 * 1080 * 3 * 30 / 1e6, 1),
    }
    return out


def _box_at(u: float, v: float, like) -> tuple[int, int, int, int]:
    w, h = like[2], like[3]
    return round(u - (w - 1) / 2), round(v - (h - 1) / 2), w, h


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument(
        "session", nargs="?", default=str(ROOT / "sim_fixtures" / "bundled" / "nadir_hover")
    )
    ap.add_argument("--out", default=str(ROOT / "bench" / "results"))
    args = ap.parse_args(argv)
    res = bench(Path(args.session))
    lines = [f"{res['session']} ({res['size'][0]}x{res['size'][1]}, {res['frames']} frames)"]
    for key in (
        "tracking_step",
        "live_per_frame",
        "acquiring",
        "awaiting_far_estimate",
        "select_click",
        "select_1s_back_and_catch_up",
    ):
        r = res[key]
        extra = {k: v for k, v in r.items() if k not in ("n", "p50_ms", "p99_ms", "mean_ms")}
        lines.append(
            f"  {key:28s} p50 {r['p50_ms']:7.2f} ms  p99 {r['p99_ms']:7.2f} ms  mean {r['mean_ms']:7.2f} ms"
            f"  (n {r['n']}) {extra or ''}"
        )
    h = res["held"]
    lines.append(
        f"  held frames ({h['history_s']:g} s): {h['frames']} frames, {h['mb']} MB here; "
        f"{h['mb_per_s_at_this_size']} MB per second held at this size, {h['mb_per_s_at_1080p30']} at 1080p30"
    )
    print("\n".join(lines))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / f"target-{Path(args.session).resolve().name}.json").write_text(
        json.dumps(res, indent=2) + "\n"
    )
    print(f"results: {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The camera's height from the UUV's size: accuracy against the simulator's truth, and its cost.

    .venv/bin/python bench/size_height.py [CASE ...] [--out bench/results] [--sessions DIR] [--regenerate]
                                          [--schedule HZ,SURE_HZ,MIN_FRAMES ...]

For each case (:data:`CASES`: ``sim_fixtures/scenarios/size_surface.toml`` with overrides: the UUV at
the surface and 1.5-2 m deep, nadir and 20-35° off nadir, 720p and 1080p, 8-20 m up) a session
with video is generated (kept in ``--sessions`` and reused unless ``--regenerate``), its
``[water] takeoff_height_above_surface_m`` written ``error_m`` wrong (the configured height is that
much off, as a barometer that drifted), and the video tracked by ``skyfix process``'s own pass with
the height measured from the UUV's size (:class:`groundstation.height_from_size.HeightFromSize`, mode
``check``). Against the truth, computed from the scenario's motion (:class:`sim_fixtures.motion.Motion`,
independent of the localizer):

- per measured frame: the measured height's error (mean, standard deviation, MAE, p95) and the
  share within twice its 1-sigma;
- the estimate (configured − measured, 30 s window): at the end, its error against the true
  bias, its 1-sigma; over the run, the share of the sure estimates within twice their 1-sigma;
- what it is worth: the MAE of the fixes (the tracker's pixels, refraction) with the configured
  height, and with it corrected by the final estimate (a constant correction: what the height's
  fusion would do with a barometer's bias that does not drift);
- cost: CPU time (of the tracking thread) per measured frame against the tracker's per tracked
  frame (:meth:`TrackingSession.step`), in the same run;
- the measuring schedule (``--schedule``, :func:`scheduled`; by default ``skyfix process``'s own: at most
  :data:`~groundstation.height_from_size.MEASURE_HZ` a second, :data:`~groundstation.height_from_size.SURE_HZ` once
  sure, sure from :data:`~localizer.size_range.MIN_FRAMES` measurements): the frames it measures, taken from the
  measurements at :data:`FRAMES_HZ` (a measurement depends on its frame alone), how many, the estimate at the end,
  when it became sure and its sure estimates within twice their 1-sigma.

Prints a table and writes ``OUT/size_height.json``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import re
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

from groundstation.height_from_size import MEASURE_HZ, SURE_HZ, HeightFromSize
from groundstation.offline import track as track_video
from groundstation.offline.evaluate import errors_m
from groundstation.offline.process import locate_frames
from groundstation.offline.track import track_session
from groundstation.session.read import load_session
from localizer import size_range
from localizer.size_range import SizeHeight
from localizer.tracking.session import TrackingSession
from sim_fixtures.generate import generate
from sim_fixtures.motion import Motion
from sim_fixtures.scenario import load_scenario, with_overrides

BASE = ROOT / "sim_fixtures" / "scenarios" / "size_surface.toml"
#: Frames measured a second throughout (every frame offered: the per-frame errors; the schedules pick from them)
FRAMES_HZ = 5.0


class TimedTracking(TrackingSession):
    """The tracker, with the CPU time its steps take."""

    cpu_s = 0.0
    steps = 0

    def step(self, *args, **kwargs):
        t0 = time.thread_time()
        try:
            return super().step(*args, **kwargs)
        finally:
            TimedTracking.cpu_s += time.thread_time() - t0
            TimedTracking.steps += 1


def _case(width, height, pitch_deg, uav_m, depth_m, error_m, seed):
    return {
        "camera": {"width": width, "height": height},
        "mount": {"pitch_deg": pitch_deg},
        "uav": {"height_m": uav_m},
        "uuv": {"depth_m": depth_m, "depth_swing_m": 0.03 if depth_m < 0.3 else 0.3},
        "seed": seed,
        "error_m": error_m,
    }


#: name → overrides of the base scenario, and the configured height's error (m)
CASES = {
    "surface_nadir_720p_10m": _case(1280, 720, -90.0, 10.0, 0.12, +0.8, 61),
    "surface_30deg_720p_10m": _case(1280, 720, -60.0, 10.0, 0.12, +0.8, 62),
    "deep_30deg_720p_12m": _case(1280, 720, -60.0, 12.0, 1.5, -0.8, 63),
    "deep_20deg_720p_8m": _case(1280, 720, -70.0, 8.0, 2.0, +0.8, 64),
    "surface_35deg_720p_16m": _case(1280, 720, -55.0, 16.0, 0.12, +1.2, 65),
    "deep_nadir_1080p_15m": _case(1920, 1080, -90.0, 15.0, 1.5, +0.8, 66),
    "surface_25deg_1080p_15m": _case(1920, 1080, -65.0, 15.0, 0.12, -1.2, 67),
    "surface_25deg_1080p_20m": _case(1920, 1080, -65.0, 20.0, 0.12, +0.8, 68),
    "deep_30deg_1080p_20m": _case(1920, 1080, -60.0, 20.0, 1.5, +0.8, 69),
    "surface_30deg_720p_20m": _case(1280, 720, -60.0, 20.0, 0.12, +0.8, 70),
}


class Recording(HeightFromSize):
    """Every measurement (with its frame's time), the estimate after each, and the CPU time measuring took; at
    :data:`FRAMES_HZ` throughout (not less often once sure, as ``process`` measures): the per-frame errors over every
    frame offered."""

    def __init__(self, *args):
        super().__init__(*args, measure_hz=FRAMES_HZ, sure_hz=FRAMES_HZ)
        self.results: list = []
        self.timed: list = []  # (t_unix, result)
        self.estimates: list = []
        self.cpu_s = 0.0
        self._due_t = float("nan")  # the frame last found due: the one measured next

    def due(self, t_unix):
        if not super().due(t_unix):
            return False
        self._due_t = t_unix
        return True

    def measure(self, *args):
        t0 = time.thread_time()
        try:
            return super().measure(*args)
        finally:
            self.cpu_s += time.thread_time() - t0

    def take(self, result):
        super().take(result)
        self.results.append(result)
        self.timed.append((self._due_t, result))
        if isinstance(result, SizeHeight):
            self.estimates.append((result.t_unix, self.estimate))


def session_for(name: str, case: dict, sessions: Path, regenerate: bool):
    """The case's scenario and session (generated unless there), its configured height ``error_m`` off."""
    overrides = {k: v for k, v in case.items() if k != "error_m"}
    sc = with_overrides(load_scenario(BASE), name=name, **overrides)
    out = sessions / name
    if regenerate or not (out / "video.mp4").is_file():
        generate(sc, out)
    toml = out / "session.toml"
    configured = sc.site.takeoff_height_above_surface_m + case["error_m"]
    toml.write_text(
        re.sub(
            r"takeoff_height_above_surface_m = [-\d.e]+",
            f"takeoff_height_above_surface_m = {configured!r}",
            toml.read_text(),
        )
    )
    return sc, out


def scheduled(size: Recording, schedule: tuple[float, float, int], true_bias_at) -> dict:
    """What a schedule (measure_hz, sure_hz, min_frames) makes of the measurements ``size`` took at
    :data:`FRAMES_HZ`: the frames it measures (:meth:`HeightFromSize.due` of those offered, in order), taken into an
    estimate of its own as ``process`` takes them; ``true_bias_at(t)``: the configured height's true error."""
    measure_hz, sure_hz, min_frames = schedule
    mine = HeightFromSize(size.cal, size.tel, "check", measure_hz, sure_hz)
    measured, first_sure, sure_err, sure_sig = 0, None, [], []
    kept, size_range.MIN_FRAMES = size_range.MIN_FRAMES, min_frames
    try:
        for t_unix, result in size.timed:
            if not mine.due(t_unix):
                continue
            measured += 1
            mine.take(result)
            e = mine.estimate
            if e is not None and e.sure:
                first_sure = t_unix if first_sure is None else first_sure
                sure_err.append(e.bias_m - float(true_bias_at(t_unix)))
                sure_sig.append(e.sigma_m)
    finally:
        size_range.MIN_FRAMES = kept
    e = mine.estimate
    t0 = size.timed[0][0] if size.timed else float("nan")
    return {
        "schedule": list(schedule),
        "measured": measured,
        "ok": mine.measured,
        "sure_after_s": _f(first_sure and first_sure - t0),
        "final_bias_err_m": _f(e and e.bias_m - float(true_bias_at(size.timed[-1][0]))),
        "final_sigma_m": _f(e and e.sigma_m),
        "final_sure": bool(e and e.sure),
        "sure_estimates": len(sure_err),
        "sure_within_2sigma": _stat(np.mean, np.abs(sure_err) <= 2 * np.array(sure_sig)),
    }


def run_case(
    name: str, case: dict, sessions: Path, regenerate: bool, schedules: list[tuple] = ()
) -> dict:
    sc, path = session_for(name, case, sessions, regenerate)
    session = load_session(path)
    cal = session.calibration
    size = Recording(cal, session.telemetry, "check")
    TimedTracking.cpu_s, TimedTracking.steps = 0.0, 0
    track_video.TrackingSession = TimedTracking
    try:
        tracked = track_session(session, size=size)
    finally:
        track_video.TrackingSession = TrackingSession
    t_frames = session.frames["t"]
    motion = Motion(sc)

    def true_uav_height(t):
        tau = np.interp(t, t_frames, np.arange(len(t_frames)) / sc.fps)
        return -motion.uav_ned(tau)[..., 2]

    heights = [r for r in size.results if isinstance(r, SizeHeight)]
    t = np.array([h.t_unix for h in heights])
    measured = np.array([h.uav_height_m for h in heights])
    sigma = np.array([h.sigma_total_m for h in heights])
    configured = np.array([h.configured_m for h in heights])
    truth = true_uav_height(t) if len(t) else np.array([])
    err = measured - truth
    true_bias = configured - truth  # the configured height's error at each measurement
    sure = [(tt, e) for tt, e in size.estimates if e is not None and e.sure]
    sure_err = np.array([e.bias_m - float(np.interp(tt, t, true_bias)) for tt, e in sure])
    sure_sig = np.array([e.sigma_m for _, e in sure])
    final = size.estimate
    pixels = (tracked.t, tracked.u, tracked.v, tracked.status)
    mae_configured = float(np.nanmean(errors_m(locate_frames(session, pixels), session.truth)))
    if final is not None:
        water = dataclasses.replace(
            cal.water,
            takeoff_height_above_surface_m=(
                cal.water.takeoff_height_above_surface_m - final.bias_m
            ),
        )
        session.calibration = dataclasses.replace(cal, water=water)
        mae_corrected = float(np.nanmean(errors_m(locate_frames(session, pixels), session.truth)))
        session.calibration = cal
    else:
        mae_corrected = float("nan")
    out = {
        "case": name,
        "width": sc.camera.width,
        "off_nadir_deg": 90.0 + sc.mount.pitch_deg,
        "uav_height_m": sc.uav.height_m,
        "depth_m": sc.uuv.depth_m,
        "error_m": case["error_m"],
        "frames": len(t_frames),
        "offered": len(size.results),
        "measured": len(heights),
        "rejected": dict(size.rejected),
        "frame_err_mean_m": _stat(np.mean, err),
        "frame_err_std_m": _stat(np.std, err),
        "frame_mae_m": _stat(np.mean, np.abs(err)),
        "frame_p95_m": _stat(lambda a: np.percentile(a, 95), np.abs(err)),
        "frame_within_2sigma": _stat(np.mean, np.abs(err) <= 2 * sigma),
        "frame_sigma_median_m": _stat(np.median, sigma),
        "final_bias_m": _f(final and final.bias_m),
        "final_true_bias_m": _stat(np.mean, true_bias[-20:]),
        "final_bias_err_m": _f(final and final.bias_m - float(np.interp(t[-1], t, true_bias))),
        "final_sigma_m": _f(final and final.sigma_m),
        "final_sure": bool(final and final.sure),
        "sure_estimates": len(sure),
        "sure_within_2sigma": _stat(np.mean, np.abs(sure_err) <= 2 * sure_sig),
        "sure_abs_err_max_m": _stat(np.max, np.abs(sure_err)),
        "fix_mae_configured_m": mae_configured,
        "fix_mae_corrected_m": mae_corrected,
        "track_ms_per_frame": 1000 * TimedTracking.cpu_s / max(TimedTracking.steps, 1),
        "size_ms_per_measured": 1000 * size.cpu_s / max(len(size.results), 1),
        "schedules": [
            scheduled(size, sc_, lambda tt: np.interp(tt, t, true_bias) if len(t) else np.nan)
            for sc_ in schedules
        ],
    }
    return out


def _f(x) -> float:
    """A number for the JSON: NaN for None."""
    return float("nan") if x is None else float(x)


def _stat(fn, x) -> float:
    """``fn(x)``, NaN for an empty ``x``."""
    return float(fn(x)) if len(x) else float("nan")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="bench/size_height.py")
    p.add_argument(
        "cases", nargs="*", default=list(CASES), help=f"cases (default all): {', '.join(CASES)}"
    )
    p.add_argument("--out", default=str(ROOT / "bench" / "results"))
    p.add_argument(
        "--sessions",
        default=str(ROOT / "bench" / "results" / "size_sessions"),
        help="where the generated sessions are kept",
    )
    p.add_argument("--regenerate", action="store_true")
    p.add_argument(
        "--schedule",
        action="append",
        help="HZ,SURE_HZ,MIN_FRAMES: a measuring schedule to compare (repeatable; default: process's own, "
        f"{MEASURE_HZ:g},{SURE_HZ:g},{size_range.MIN_FRAMES})",
    )
    args = p.parse_args(argv)
    schedules = [
        (float(a), float(b), int(c))
        for a, b, c in (
            x.split(",")
            for x in args.schedule or [f"{MEASURE_HZ},{SURE_HZ},{size_range.MIN_FRAMES}"]
        )
    ]
    rows = []
    for name in args.cases:
        t0 = time.perf_counter()
        row = run_case(name, CASES[name], Path(args.sessions), args.regenerate, schedules)
        rows.append(row)
        print(
            f"{name}: {row['measured']}/{row['offered']} measured; frame error {row['frame_err_mean_m']:+.3f} ± "
            f"{row['frame_err_std_m']:.3f} m (MAE {row['frame_mae_m']:.3f}, p95 {row['frame_p95_m']:.3f}, "
            f"{row['frame_within_2sigma']:.0%} in 2σ); estimate {row['final_bias_m']:+.3f} ± {row['final_sigma_m']:.3f}"
            f" m vs true {row['final_true_bias_m']:+.3f} ({'sure' if row['final_sure'] else 'not sure'}; sure estimates "
            f"in 2σ {row['sure_within_2sigma']:.0%} of {row['sure_estimates']}); fixes MAE {row['fix_mae_configured_m']:.3f}"
            f" -> {row['fix_mae_corrected_m']:.3f} m; {row['size_ms_per_measured']:.1f} ms per measured frame vs "
            f"{row['track_ms_per_frame']:.1f} ms tracking a frame (CPU); without a measurement: {row['rejected']} "
            f"({time.perf_counter() - t0:.0f} s)",
            flush=True,
        )
        for sch in row["schedules"]:
            print(
                "  schedule {:g} Hz, {:g} Hz once sure, sure from {} measurements: {} measured ({} ok); estimate error "
                "{:+.3f} ± {:.3f} m ({}), sure after {:.1f} s, sure estimates in 2σ {:.0%} of {}".format(
                    *sch["schedule"],
                    sch["measured"],
                    sch["ok"],
                    sch["final_bias_err_m"],
                    sch["final_sigma_m"],
                    "sure" if sch["final_sure"] else "not sure",
                    sch["sure_after_s"],
                    sch["sure_within_2sigma"],
                    sch["sure_estimates"],
                ),
                flush=True,
            )
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "size_height.json").write_text(json.dumps(rows, indent=1))
    print(f"-> {out / 'size_height.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

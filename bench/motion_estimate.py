"""The motion estimate's cost and its time offset, before and after measuring fewer frames with fewer corners.

    .venv/bin/python bench/motion_estimate.py [--sessions wobble_41,wobble_43,1080p] [--out bench/results/motion_estimate.txt]

Each session's video is decoded to its luma plane (as ``skyfix process`` reads it) and its frames fed to a
:class:`~groundstation.latency.video_motion.RotationMeter` in the calling thread, whose CPU time
(``time.thread_time``) is the measuring's alone; the rotations go to
:func:`~groundstation.latency.estimate.offset_from_rotations`. Variants: ``before`` (every frame; 150 corners, found
again below 80, a 21 px window), ``stride`` (every :func:`~groundstation.latency.video_motion.measured_every`-th
frame, those corners), ``corners`` (every frame, the module's corners and window) and ``after`` (both: what
``skyfix process`` does). Sessions (generated once into /tmp/skyfix-bench): ``wobble_<seed>``, 40 s of 320x180, a
camera fixed to an airframe wobbling 2° at 1.2 Hz (the offset well determined), link delay 20 ms; ``1080p``,
``bench/offline_speed.py``'s 40 s nadir hover under a gimbal (weakly determined), link delay 45 ms (the
simulator's default). No TIMESYNC in either.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from emit import emit
from offline_speed import BENCH_DIR, ensure_session

import groundstation.latency.video_motion as vm
from groundstation.latency.estimate import offset_from_rotations
from groundstation.session.read import load_session

WOBBLE = """name = "motion_wobble_{seed}"
description = "40 s, a camera fixed to an airframe wobbling 2 deg at 1.2 Hz, no TIMESYNC, link delay 20 ms"
seed = {seed}
duration_s = 40.0
[camera]
width = 320
height = 180
[mount]
attitude_source = "fixed"
fixed_rpy_deg = [0.0, -85.0, 0.0]
camera_offset_m = [0.12, 0.0, 0.10]
[uav]
height_m = 10.0
wobble_deg = 2.0
wobble_hz = 1.2
[uuv]
depth_m = 1.2
[link]
delay_s = 0.020
[telemetry]
timesync_hz = 0.0
"""
#: the true link delay (s) by the session name's first part
DELAY_S = {"wobble": 0.020, "1080p": 0.045}
#: the meter's corners before this change: (MAX_CORNERS, REDETECT_BELOW, LK_WINDOW_PX)
BEFORE = (150, 80, 21)
AFTER = (vm.MAX_CORNERS, vm.REDETECT_BELOW, vm.LK_WINDOW_PX)
VARIANTS = {
    "before": (False, BEFORE),
    "stride": (True, BEFORE),
    "corners": (False, AFTER),
    "after": (True, AFTER),
}


def session_path(name: str) -> Path:
    """The session ``name`` (see the module doc), generated once."""
    if name == "1080p":
        return ensure_session("1080p")
    seed = int(name.split("_")[1])
    path = BENCH_DIR / f"motion_wobble_{seed}"
    if not (path / "video_frames.csv").exists():
        import tomllib

        from sim_fixtures.generate import generate
        from sim_fixtures.scenario import scenario_from_dict

        text = WOBBLE.format(seed=seed)
        print(f"generating {path} (once) ...", flush=True)
        generate(scenario_from_dict(tomllib.loads(text)), path, text)
    return path


def measure(path: Path, stride: bool, corners: tuple[int, int, int]) -> tuple[int, float, str]:
    """Frames measured, CPU ms per video frame and the offset's description of one variant on one session."""
    vm.MAX_CORNERS, vm.REDETECT_BELOW, vm.LK_WINDOW_PX = corners
    s = load_session(path)
    t = s.frames["t"]
    row_of = {int(f): i for i, f in enumerate(s.frames["frame"])}
    every = vm.measured_every(len(t), float(t[1] - t[0])) if stride else 1
    meter, rotations, cpu_s, measured = vm.RotationMeter(s.calibration.camera), [], 0.0, 0
    with s.open_video(grey=True) as video:
        for frame in video.prefetch():
            row = row_of.get(frame.index)
            if row is None or row % every:
                continue
            c0 = time.thread_time()
            r = meter.measure(float(t[row]), frame.image)
            cpu_s += time.thread_time() - c0
            measured += 1
            if r is not None:
                rotations.append(r)
    found = offset_from_rotations(s.calibration, s.telemetry, rotations)
    return measured, 1000.0 * cpu_s / len(t), found.describe()


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sessions", default="wobble_41,wobble_43,1080p")
    p.add_argument("--out", type=Path, help="also write the results here")
    args = p.parse_args(argv)
    lines = []
    for name in args.sessions.split(","):
        path = session_path(name)
        lines.append(
            f"{name}: {path.name}, true link delay {DELAY_S[name.split('_')[0]] * 1000:.0f} ms"
        )
        for variant, (stride, corners) in VARIANTS.items():
            measured, cpu_ms, offset = measure(path, stride, corners)
            lines.append(
                f"  {variant:8s} {measured:5d} frames measured, CPU {cpu_ms:5.2f} ms per video frame: {offset}"
            )
            print(lines[-1], flush=True)
    lines.append(
        f"load average (1, 5, 15 min) at the end: {', '.join(f'{x:.1f}' for x in os.getloadavg())}"
    )
    emit(lines, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())

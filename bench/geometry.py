"""Microseconds per fix: single frames and a 10 000-fix batch, with and without refraction.

Run: ``.venv/bin/python bench/geometry.py`` (from the project root). Prints a table and
writes it to ``bench/results/geometry.txt``. Every number is the median over
several repeats (time.perf_counter). Baselines measured in the same run:
``pixel_to_ray`` alone (the camera model) and ``pixel_to_offset`` alone (the ray
geometry without pose alignment, geodesy or the accuracy estimate).
"""

from __future__ import annotations

import math
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from localizer.calibration import Calibration
from localizer.camera import pixel_to_ray
from localizer.fix import locate
from localizer.pose import camera_pose
from localizer.ray import pixel_to_offset
from localizer.telemetry import Telemetry

BATCH = 10_000
SINGLE_CALLS = 200  # calls per timed single-fix loop
REPEATS = 7
T0_UNIX = 1_763_800_000.0
BOOT0_MS = 250_000
RESULTS = Path(__file__).resolve().parent / "results" / "geometry.txt"

CALIBRATION = {
    "camera": {
        "width": 1920,
        "height": 1080,
        "fx": 1664.0,
        "fy": 1664.0,
        "cx": 959.5,
        "cy": 539.5,
        "distortion": [-0.12, 0.08, 0.0004, -0.0002, -0.01],
    },
    "mount": {"attitude_source": "gimbal_device", "camera_offset_m": [0.10, 0.0, 0.25]},
    "water": {"takeoff_height_above_surface_m": 2.10, "refractive_index": 1.34},
}


def telemetry(duration_s: float = 30.0, rate_hz: float = 50.0) -> Telemetry:
    """A hovering UAV (30 m over the water) with a gimbal 35° off nadir, slowly turning."""
    tel = Telemetry()
    for i in range(int(duration_s * rate_hz) + 1):
        boot_ms = BOOT0_MS + round(i * 1000 / rate_hz)
        t = T0_UNIX + (boot_ms - BOOT0_MS) / 1000
        yaw = 0.02 * i / rate_hz
        tel.add_system_time(boot_ms, round(t * 1e6), t)
        tel.add_attitude(boot_ms, 0.01, -0.02, yaw, (0.0, 0.0, 0.02), t)
        tel.add_position(boot_ms, 47.5, 8.5, 412.0, 27.9, (0.0, 0.0, 0.0), t)
        half_p, half_y = math.radians(-55.0) / 2, (yaw + 0.3) / 2
        q = (
            math.cos(half_y) * math.cos(half_p),
            -math.sin(half_y) * math.sin(half_p),
            math.cos(half_y) * math.sin(half_p),
            math.sin(half_y) * math.cos(half_p),
        )
        tel.add_gimbal(boot_ms, q, 64, t)
        tel.add_depth(t, 2.0)
    return tel


def per_call_us(fn, calls: int) -> float:
    """Time per call (µs) of ``fn`` run ``calls`` times."""
    start = time.perf_counter()
    for _ in range(calls):
        fn()
    return (time.perf_counter() - start) / calls * 1e6


def main() -> int:
    cal = Calibration.from_dict(CALIBRATION, "bench")
    cam = cal.camera
    tel = telemetry()
    rng = np.random.default_rng(0)
    t = T0_UNIX + rng.uniform(1.0, 29.0, BATCH)
    u = rng.uniform(0.0, cam.width - 1.0, BATCH)
    v = rng.uniform(0.0, cam.height - 1.0, BATCH)
    pose = camera_pose(cal, tel, t)
    pose1 = camera_pose(cal, tel, t[:1])
    assert np.all(pose.status == "ok")
    R, h, d = pose.R_ned_from_cv, pose.height_m, pose.depth_m

    cases = [  # (what, one fix per call, BATCH fixes in one call)
        (
            "baseline: pixel_to_ray (camera model only)",
            lambda: pixel_to_ray(cam, u[0], v[0]),
            lambda: pixel_to_ray(cam, u, v),
        ),
        (
            "baseline: pixel_to_offset, straight ray",
            lambda: pixel_to_offset(cam, R[0], u[0], v[0], h[0], d[0], None),
            lambda: pixel_to_offset(cam, R, u, v, h, d, None),
        ),
        (
            "baseline: pixel_to_offset, refracted",
            lambda: pixel_to_offset(cam, R[0], u[0], v[0], h[0], d[0], 1.34),
            lambda: pixel_to_offset(cam, R, u, v, h, d, 1.34),
        ),
    ]
    for refraction in (False, True):
        label = "refracted" if refraction else "straight ray (paper)"
        cases += [
            (
                f"locate (+ lat/lon, h_acc), {label}",
                lambda r=refraction: locate(cal, pose1, u[:1], v[:1], refraction=r),
                lambda r=refraction: locate(cal, pose, u, v, refraction=r),
            ),
            (
                f"camera_pose + locate, {label}",
                lambda r=refraction: locate(
                    cal, camera_pose(cal, tel, t[:1]), u[:1], v[:1], refraction=r
                ),
                lambda r=refraction: locate(cal, camera_pose(cal, tel, t), u, v, refraction=r),
            ),
        ]
    # repeats interleaved over the cases, so a change in machine load hits them all alike
    single = {name: [] for name, _, _ in cases}
    batched = {name: [] for name, _, _ in cases}
    for _, one, many in cases:  # warm-up
        one(), many()
    for _ in range(REPEATS):
        for name, one, many in cases:
            single[name].append(per_call_us(one, SINGLE_CALLS))
            batched[name].append(per_call_us(many, 1) / BATCH)
    rows = [
        (name, statistics.median(single[name]), statistics.median(batched[name]))
        for name, _, _ in cases
    ]

    now = time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime())
    machine = f"{platform.machine()}, {os.cpu_count()} CPUs, load avg {os.getloadavg()[0]:.2f}"
    lines = [
        f"skyfix geometry benchmark: microseconds per fix, median of {REPEATS} repeats",
        f"single = 1 fix per call x {SINGLE_CALLS} calls; batched = {BATCH} fixes in one call",
        f"command: .venv/bin/python bench/geometry.py   date: {now}",
        f"python {platform.python_version()}, numpy {np.__version__}, {machine}",
        "",
        f"{'what':<48} {'single µs/fix':>14} {'batched µs/fix':>15}",
    ]
    lines += [f"{name:<48} {s:>14.1f} {b:>15.2f}" for name, s, b in rows]
    text = "\n".join(lines) + "\n"
    print(text, end="")
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(text)
    print(f"written to {RESULTS}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())

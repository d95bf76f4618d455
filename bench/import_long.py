"""A long onboard video imported: frames per second and peak memory of ``skyfix import``.

    .venv/bin/python bench/import_long.py [--minutes 2] [--size 3840x2160] [--out bench/results/import_long.txt]

Writes a DataFlash log (``groundstation/testing/dataflash_log.py``: ATT, IMU, POS, GPS at their usual rates, a yaw swinging
slowly) and a video of ``--minutes`` at 30 fps and ``--size`` (x264 ultrafast: a textured floor turning with the
logged yaw), then runs ``skyfix import`` in a child process twice: with the start given (the container's
timestamps only: demuxing, no decoding) and with the start found from the image's motion (the whole video
decoded). Each: wall time, frames per second of the video's length, and the child's peak RSS — a video held in
memory would show as gigabytes. Baselines in the same run: PyAV demuxing the same file alone, and OpenCV decoding
it alone (``bench/offline_speed.py --decode-only opencv``).
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import subprocess
import sys
import tempfile
import time
from fractions import Fraction
from pathlib import Path

import av
import cv2
import numpy as np
from emit import emit

from groundstation.testing.dataflash_log import DataflashWriter

ROOT = Path(__file__).resolve().parents[1]

UNIX0 = 1_796_000_000.0  # the log's first fix, UNIX s
BOOT0 = 10.0  # ... at this boot time
FPS = 30


def yaw_deg(t_s):
    return 20.0 * np.sin(2 * np.pi * t_s / 17.0) + 8.0 * np.sin(2 * np.pi * t_s / 5.3)


def write_log(path: Path, seconds: float) -> None:
    w = DataflashWriter(path, ("ATT", "IMU", "POS", "GPS"))
    for k in range(round(seconds * 25)):
        t = BOOT0 + k / 25
        us = round(t * 1e6)
        rate = np.radians(
            20.0 * 2 * np.pi / 17.0 * np.cos(2 * np.pi * (t - BOOT0) / 17.0)
            + 8.0 * 2 * np.pi / 5.3 * np.cos(2 * np.pi * (t - BOOT0) / 5.3)
        )
        w.write("ATT", us, 0.0, 0.0, 0.0, 0.0, 0.0, float(yaw_deg(t - BOOT0)) % 360.0, 0)
        w.write("IMU", us, 0, 0.0, 0.0, float(rate))
        if k % 5 == 0:
            w.write("POS", us, round(63.44 * 1e7), round(10.4 * 1e7), 60.0, 10.0, 10.0)
            gps_s = UNIX0 + (t - BOOT0) + 18 - 315964800
            week = int(gps_s // 604800)
            w.write(
                "GPS",
                us,
                0,
                6,
                round((gps_s - week * 604800) * 1000),
                week,
                12,
                80,
                round(63.44 * 1e7),
                round(10.4 * 1e7),
                6000,
                0.0,
                0.0,
                0.0,
                0.0,
                1,
            )
    w.close()


def write_video(path: Path, seconds: float, size: tuple[int, int], start_s: float) -> int:
    """A nadir camera over a textured floor turning with the log's yaw from ``start_s`` into the log."""
    rng = np.random.default_rng(3)
    w, h = size
    side = int(math.hypot(w, h)) + 8
    floor = cv2.GaussianBlur(rng.integers(0, 255, (side, side, 3), dtype=np.uint8), (0, 0), 3)
    n = round(seconds * FPS)
    with av.open(str(path), "w") as out:
        s = out.add_stream("libx264", rate=FPS, options={"preset": "ultrafast", "crf": "28"})
        s.width, s.height, s.pix_fmt = w, h, "yuv420p"
        s.time_base = Fraction(1, FPS)
        for i in range(n):
            # looking down, a yaw to the right turns the image left
            angle = float(yaw_deg(start_s + i / FPS))
            M = cv2.getRotationMatrix2D((side / 2, side / 2), angle, 1.0)
            M[:, 2] -= [(side - w) / 2, (side - h) / 2]
            img = cv2.warpAffine(floor, M, (w, h))
            f = av.VideoFrame.from_ndarray(img, format="bgr24")
            f.pts = i
            for p in s.encode(f):
                out.mux(p)
        for p in s.encode():
            out.mux(p)
    return n


def child(cmd: list[str]) -> tuple[float, float, int]:
    """Wall seconds, peak RSS (MB) of the child, exit code."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    t0 = time.perf_counter()
    rc = subprocess.run(cmd, check=False, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    if rc.returncode:
        print(rc.stderr[-2000:], file=sys.stderr)
    return wall, max(peak, before) / 1024.0, rc.returncode


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--minutes", type=float, default=2.0)
    p.add_argument("--size", default="3840x2160")
    p.add_argument("--out", type=Path, help="also write the results here")
    args = p.parse_args()
    size = tuple(int(x) for x in args.size.split("x"))
    seconds = args.minutes * 60.0
    with tempfile.TemporaryDirectory() as work:
        work = Path(work)
        start_s = 30.0  # the video starts 30 s into the log
        write_log(work / "flight.bin", seconds + 60.0)
        t0 = time.perf_counter()
        n = write_video(work / "camera.mp4", seconds, size, start_s)
        encode_s = time.perf_counter() - t0
        (work / "depth.csv").write_text(
            "t,depth_m\n" + "".join(f"{UNIX0 + i:.1f},1.0\n" for i in range(int(seconds) + 90))
        )
        f = 1800.0 * size[0] / 3840  # a 4K camera's focal length, scaled
        (work / "cal.toml").write_text(
            f"[camera]\nwidth = {size[0]}\nheight = {size[1]}\nfx = {f}\nfy = {f}\ncx = {(size[0] - 1) / 2}\n"
            f'cy = {(size[1] - 1) / 2}\ndistortion = [0.0, 0.0, 0.0, 0.0, 0.0]\n\n[mount]\nattitude_source = "fixed"\n'
            "fixed_rpy_deg = [0.0, -90.0, 0.0]\ncamera_offset_m = [0.0, 0.0, 0.0]\n\n[water]\n"
            "takeoff_height_above_surface_m = 0.0\nrefractive_index = 1.34\n"
        )
        t0 = time.perf_counter()
        with av.open(str(work / "camera.mp4")) as c:
            packets = sum(1 for _ in c.demux(c.streams.video[0]))
        demux_s = time.perf_counter() - t0
        decode = child(
            [
                sys.executable,
                str(ROOT / "bench" / "offline_speed.py"),
                "--decode-only",
                "opencv",
                str(work / "camera.mp4"),
            ]
        )
        base = [
            sys.executable,
            "-m",
            "groundstation.cli",
            "import",
            "--dataflash",
            str(work / "flight.bin"),
            "--video",
            str(work / "camera.mp4"),
            "--depth",
            str(work / "depth.csv"),
            "--calibration",
            str(work / "cal.toml"),
            "--quiet",
        ]
        given = child(
            base
            + [
                "--video-start-unix",
                f"{UNIX0 + start_s - BOOT0 + BOOT0:.3f}",
                "--out",
                str(work / "given"),
            ]
        )
        motion = child(base + ["--out", str(work / "motion")])
        found = json.loads((work / "motion" / "import.json").read_text()) if motion[2] == 0 else {}
    lines = [
        (
            f"skyfix import of a {args.minutes:g} min {size[0]}x{size[1]} {FPS} fps video ({n} frames, "
            f"{packets} packets; encoded in {encode_s:.0f} s)"
        ),
        f"  baseline: PyAV demuxing alone: {demux_s:.2f} s ({n / demux_s:.0f} frames/s)",
        (
            f"  baseline: OpenCV decoding alone (BGR): {decode[0]:.2f} s ({n / decode[0]:.0f} frames/s), "
            f"peak RSS {decode[1]:.0f} MB"
        ),
        (
            f"  start given: {given[0]:.2f} s ({n / given[0]:.0f} frames/s of video), peak RSS {given[1]:.0f} MB, "
            f"exit {given[2]}"
        ),
        (
            f"  start from the motion (the whole video decoded): {motion[0]:.2f} s ({n / motion[0]:.0f} frames/s of "
            f"video), peak RSS {motion[1]:.0f} MB, exit {motion[2]}; found "
            f"{(found.get('video_start_unix', math.nan) - (UNIX0 + start_s)) * 1000:+.1f} ms from the truth "
            f"(± {found.get('video_start_sigma_s', math.nan) * 1000:.1f} ms)"
        ),
    ]
    emit(lines, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())

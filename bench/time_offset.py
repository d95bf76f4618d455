"""An unstated UAV link delay, offline: held-out style sessions before and after the motion estimate.

    .venv/bin/python bench/time_offset.py [--work /tmp/skyfix-time] [--out bench/results/time_offset.txt]
                                          [--before "PYTHON -m groundstation.cli" --before-cwd DIR]

Each session (generated once into ``--work``, 640x360, 8 s, with video) has a camera fixed to
an airframe wobbling 2° at 1.2 Hz, no TIMESYNC in its tlog and a link delay of 15–25 ms; one
has ATTITUDE at only 4 Hz. ``skyfix evaluate`` (the tracker on the video, refraction) scores:

- **stated**: the same session with the delay written in ``[timing] mavlink_latency_s``;
- **before**: the delay unknown, taken as 0 (``--before``: another skyfix, e.g. main's checkout;
  default this one with ``--no-motion-offset``);
- **after**: as it comes: the frames' offset to the telemetry estimated from the video's motion,
  applied when settled (the estimate, its sigma and whether it settled are shown);

MAE against the simulator's truth, after/stated, and the share of fixes within 2·h_acc. ``2σ time``
is that share for the geometry alone (``--use-track``, the delay unknown) with every input sigma but
the time's set to 0: how honest the unknown delay's sigma (``[timing] unknown_latency_sigma_s``) is;
``σ=0`` the same without it (what h_acc claimed before).
"""

from __future__ import annotations

import argparse
import csv
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: (name, seed, link delay s, ATTITUDE Hz)
SESSIONS = (
    ("held_41_20ms", 41, 0.020, 50.0),
    ("held_42_15ms", 42, 0.015, 50.0),
    ("held_43_25ms", 43, 0.025, 50.0),
    ("held_44_20ms_4hz", 44, 0.020, 4.0),
)
SCENARIO = """name = "{name}"
description = "held-out style: a camera fixed to an airframe wobbling 2 deg at 1.2 Hz, no TIMESYNC, link delay {delay} s"
seed = {seed}
duration_s = 8.0
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
delay_s = {delay}
[telemetry]
timesync_hz = 0.0
attitude_hz = {attitude_hz}
"""
ONLY_TIME = "\n[uncertainty]\npixel_px = 0.0\ntilt_deg = 0.0\nyaw_deg = 0.0\nheight_m = 0.0\ndepth_m = 0.0\ntime_s = 0.0\n"
SKYFIX = [sys.executable, "-m", "groundstation.cli"]


def generate(name: str, seed: int, delay: float, attitude_hz: float, work: Path) -> Path:
    out = work / name
    if not (out / "video.mp4").is_file():
        scenario = work / f"{name}.toml"
        scenario.write_text(
            SCENARIO.format(name=name, seed=seed, delay=delay, attitude_hz=attitude_hz)
        )
        subprocess.run(
            [*SKYFIX, "sim", str(scenario), "--out", str(out), "--quiet"],
            check=True,
            cwd=ROOT,
            capture_output=True,
        )
    return out


def variant(session: Path, name: str, extra: str) -> Path:
    """A copy of ``session`` with ``extra`` appended to its session.toml."""
    out = session.parent / name
    shutil.rmtree(out, ignore_errors=True)
    shutil.copytree(session, out)
    with open(out / "session.toml", "a") as f:
        f.write(extra)
    return out


def evaluate(
    skyfix: list[str], cwd: Path, session: Path, out: Path, *flags: str
) -> tuple[float, float, str]:
    """(MAE m, share within 2·h_acc, stderr) of ``skyfix evaluate`` (refraction)."""
    shutil.rmtree(out, ignore_errors=True)
    done = subprocess.run(
        [*skyfix, "evaluate", str(session), "--out", str(out), "--quiet", *flags],
        cwd=cwd,
        capture_output=True,
        text=True,
        check=False,
    )
    if not (out / "evaluation.csv").is_file():
        raise RuntimeError(f"evaluate {session} {flags}: {done.stderr[-2000:]}")
    with open(out / "evaluation.csv", newline="") as f:
        row = next(r for r in csv.DictReader(f) if r["method"] == "refraction")
    return float(row["mae_m"]), float(row["within_2sigma"]), done.stderr


def estimate_of(stderr: str) -> str:
    line = next(
        (x for x in stderr.splitlines() if "offset to the telemetry from the video's motion" in x),
        "",
    )
    if not line:
        return "none"
    found = line.split("motion: ", 1)[1]
    return found.split(" (1-sigma)")[0] + (" settled" if "settled;" in found else " NOT settled")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--work", default="/tmp/skyfix-time")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "time_offset.txt"))
    ap.add_argument("--before", default=None, help="another skyfix command for the 'before' column")
    ap.add_argument("--before-cwd", default=str(ROOT))
    args = ap.parse_args()
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    before = shlex.split(args.before) if args.before else SKYFIX
    before_flags = () if args.before else ("--no-motion-offset",)
    before_label = (
        f"{args.before} in {args.before_cwd}"
        if args.before
        else "this checkout, --no-motion-offset"
    )
    lines = [
        "skyfix: a UAV link delay neither stated nor measured, offline (skyfix evaluate, tracker, refraction)",
        f"before: {before_label}",
        f"command: {shlex.join(sys.argv)}   date: {time.strftime('%Y-%m-%d %H:%M:%S %Z')}",
        "",
        (
            f"{'session':<18} {'delay':>6} {'estimate ms':>22} {'MAE stated':>10} {'before':>8} {'after':>8} "
            f"{'after/stated':>12} {'2σ before':>9} {'2σ after':>9} {'2σ time':>8} {'σ=0':>6}"
        ),
    ]
    print("\n".join(lines), flush=True)
    for name, seed, delay, attitude_hz in SESSIONS:
        session = generate(name, seed, delay, attitude_hz, work)
        stated = variant(session, f"{name}_stated", f"\n[timing]\nmavlink_latency_s = {delay}\n")
        honest = variant(session, f"{name}_only_time", ONLY_TIME)
        blind = variant(
            session, f"{name}_blind", ONLY_TIME + "\n[timing]\nunknown_latency_sigma_s = 0.0\n"
        )
        mae_stated, _, _ = evaluate(SKYFIX, ROOT, stated, work / "ev" / f"{name}_stated")
        mae_before, in_before, _ = evaluate(
            before, Path(args.before_cwd), session, work / "ev" / f"{name}_before", *before_flags
        )
        mae_after, in_after, err = evaluate(SKYFIX, ROOT, session, work / "ev" / f"{name}_after")
        _, in_time, _ = evaluate(
            SKYFIX, ROOT, honest, work / "ev" / f"{name}_only_time", "--use-track"
        )
        _, in_blind, _ = evaluate(SKYFIX, ROOT, blind, work / "ev" / f"{name}_blind", "--use-track")
        lines.append(
            f"{name:<18} {delay * 1000:4.0f}ms {estimate_of(err):>22} {mae_stated:10.4f} {mae_before:8.4f} "
            f"{mae_after:8.4f} {mae_after / mae_stated:12.2f} {in_before:9.1%} {in_after:9.1%} {in_time:8.1%} "
            f"{in_blind:6.0%}"
        )
        print(lines[-1], flush=True)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""``skyfix mosaic``'s memory on short and long recordings: its peak resident memory must not grow with the length.

    .venv/bin/python bench/mosaic_memory.py [--work /tmp/skyfix-mosaic-memory] [--durations 4 24]
                                            [--out bench/results/mosaic_memory.txt]

Sessions (rendered once into ``--work``): ``sim_fixtures/scenarios/bottom_survey.toml`` (a straight survey line at
1.5 m/s, the floor 4 m down) at 640x360 for each of ``--durations`` seconds. Each is made into a mosaic
(``--floor-depth-m 4``, frames at 2 Hz) in a fresh Python process, twice: with the default number of the blend's
tiles held in memory (:data:`groundstation.offline.mosaic.MAX_TILES`) and with only 4 (the rest spilled to disk).
The process reports its own peak RSS (``VmHWM`` of /proc/self/status) after the imports and at the end; the table gives both, the
difference, the frames, the grid and the tiles painted, the seconds, and whether the two runs' GeoTIFFs hold the
same pixels (the spilling changes nothing).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

from sim_fixtures.generate import generate
from sim_fixtures.scenario import load_scenario, with_overrides

ROOT = Path(__file__).resolve().parents[1]
SMALL_TILES = 4

CHILD = """
import hashlib, json, sys, time
from pathlib import Path
import rasterio
from groundstation.offline import mosaic
from groundstation.session.read import load_session
def hwm_kb():  # this process's own peak RSS (ru_maxrss would keep the parent's across the exec)
    return int(next(l for l in open("/proc/self/status") if l.startswith("VmHWM")).split()[1])
before_kb = hwm_kb()
session, out, max_tiles = load_session(sys.argv[1]), Path(sys.argv[2]), int(sys.argv[3])
out.mkdir(parents=True, exist_ok=True)
t0 = time.perf_counter()
side = mosaic.make_mosaic(session, out, 4.0, max_tiles=max_tiles)
seconds = time.perf_counter() - t0
peak_kb = hwm_kb()  # before the check below reads the GeoTIFF
digest = hashlib.sha256()
with rasterio.open(out / mosaic.NAME) as d:
    for _, window in d.block_windows(1):
        digest.update(d.read(window=window).tobytes())
digest = digest.hexdigest()[:12]
print(json.dumps({"before_kb": before_kb, "peak_kb": peak_kb,
                  "seconds": seconds, "frames": side["frames"], "size_px": side["size_px"],
                  "filled": side["filled_share"], "digest": digest}))
"""


def session(work: Path, duration_s: float) -> Path:
    out = work / f"survey_{duration_s:g}s"
    if not (out / "video.mp4").is_file():
        sc = load_scenario(ROOT / "sim_fixtures" / "scenarios" / "bottom_survey.toml")
        generate(
            with_overrides(sc, duration_s=duration_s, camera={"width": 640, "height": 360}), out
        )
    return out


def measure(folder: Path, out: Path, max_tiles: int) -> dict:
    done = subprocess.run(
        [sys.executable, "-c", CHILD, str(folder), str(out), str(max_tiles)],
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    from groundstation.offline.mosaic import MAX_TILES, TILE

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", type=Path, default=Path("/tmp/skyfix-mosaic-memory"))
    ap.add_argument("--durations", type=float, nargs="+", default=[4.0, 24.0])
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "mosaic_memory.txt")
    args = ap.parse_args()
    lines = [
        (
            f"skyfix mosaic peak RSS, bottom_survey 640x360, frames at 2 Hz, tiles of {TILE}x{TILE} cells "
            "(16 bytes a cell)"
        ),
        (
            f"{'session':16s} {'tiles held':>10s} {'frames':>6s} {'grid':>11s} {'filled':>6s} "
            f"{'imports MB':>10s} {'peak MB':>8s} {'mosaic MB':>9s} {'s':>6s} {'pixels':>12s}"
        ),
    ]
    print(lines[0])
    print(lines[1])
    for duration in args.durations:
        folder = session(args.work, duration)
        for max_tiles in (MAX_TILES, SMALL_TILES):
            r = measure(folder, args.work / f"mosaic_{duration:g}s_{max_tiles}", max_tiles)
            line = (
                f"{folder.name:16s} {max_tiles:10d} {r['frames']:6d} "
                f"{r['size_px'][0]:5d}x{r['size_px'][1]:<5d} {r['filled']:6.2f} "
                f"{r['before_kb'] / 1024:10.0f} {r['peak_kb'] / 1024:8.0f} "
                f"{(r['peak_kb'] - r['before_kb']) / 1024:9.0f} {r['seconds']:6.1f} {r['digest']:>12s}"
            )
            print(line, flush=True)
            lines.append(line)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines) + "\n")
    print(f"-> {args.out}")


if __name__ == "__main__":
    main()

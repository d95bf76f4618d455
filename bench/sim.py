"""Generator speed: ``python bench/sim.py [SCENARIO.toml] [--out FILE]``.

Generates the scenario (default ``scenarios/bench_720p.toml``, 10 s of 720p30)
into a temporary directory and, as the baseline measured in the same run on the
same machine, encodes the same number of frames of one still image with the same
FFmpeg settings. Prints both and appends them to ``FILE`` (default
``bench/results/sim.txt``).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from sim_fixtures.bundle import SCENARIOS
from sim_fixtures.generate import Encoder, generate
from sim_fixtures.scenario import load_scenario


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="bench/sim.py")
    p.add_argument("scenario", nargs="?", default=str(SCENARIOS / "bench_720p.toml"))
    p.add_argument("--out", default=str(Path(__file__).resolve().parent / "results" / "sim.txt"))
    args = p.parse_args(argv)
    sc = load_scenario(args.scenario)
    with tempfile.TemporaryDirectory() as tmp:
        report = generate(sc, Path(tmp) / "session")
        still = np.random.default_rng(0).integers(
            0, 255, (sc.camera.height, sc.camera.width, 3), dtype=np.uint8
        )
        t0 = time.perf_counter()
        enc = Encoder(
            Path(tmp) / "still.mp4", sc.camera.width, sc.camera.height, sc.fps, sc.render.crf
        )
        for _ in range(report.frames):
            enc.write(still)
        enc.close()
        encode_s = time.perf_counter() - t0
    line = (
        f"{datetime.now(UTC):%Y-%m-%dT%H:%M:%SZ} {sc.name}: {report.frames} frames "
        f"{sc.camera.width}x{sc.camera.height}, generated in {report.total_s:.1f} s "
        f"({report.total_s / sc.duration_s:.2f} s per second of video; render+encode {report.render_s:.1f} s); "
        f"baseline: encoding {report.frames} still frames {encode_s:.1f} s"
    )
    print(line)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with open(out, "a") as f:
        f.write(line + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Regenerate the bundled sessions: ``python -m sim_fixtures.bundle [NAME...]``.

Each bundled session is ``sim_fixtures/bundled/<name>/``, generated from
``sim_fixtures/scenarios/<name>.toml``. Generation is deterministic from each
scenario's seed (the video's bytes may differ between FFmpeg versions).
"""

from __future__ import annotations

import sys
from pathlib import Path

from .generate import generate
from .scenario import load_scenario

HERE = Path(__file__).parent
SCENARIOS = HERE / "scenarios"
BUNDLED_DIR = HERE / "bundled"
BUNDLED = (
    "nadir_hover",
    "oblique_2m",
    "vehicle_yaw",
    "mount_orientation",
    "fixed_camera",
    "occlusion",
    "clock_offset",
)


def main(argv=None) -> int:
    names = (argv if argv is not None else sys.argv[1:]) or BUNDLED
    for name in names:
        path = SCENARIOS / f"{name}.toml"
        report = generate(load_scenario(path), BUNDLED_DIR / name, scenario_text=path.read_text())
        size = sum(f.stat().st_size for f in report.session.iterdir())
        print(f"{name}: {report.frames} frames in {report.total_s:.1f} s, {size / 1e6:.2f} MB")
    total = sum(f.stat().st_size for f in BUNDLED_DIR.rglob("*") if f.is_file())
    print(f"bundled total: {total / 1e6:.2f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())

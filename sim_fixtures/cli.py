"""``skyfix sim SCENARIO.toml --out DIR``: generate a synthetic session from a scenario file."""

from __future__ import annotations

from pathlib import Path

from .generate import generate
from .scenario import load_scenario


def run(args) -> int:
    path = Path(args.scenario)
    sc = load_scenario(path)
    report = generate(sc, args.out, scenario_text=path.read_text())
    counts = ", ".join(f"{k} {n}" for k, n in sorted(report.messages.items()))
    print(f"{sc.name}: {report.frames} frames {sc.camera.width}x{sc.camera.height} rendered and encoded in "
          f"{report.render_s:.1f} s ({report.total_s:.1f} s in all); tlog: {counts} -> {report.session}")
    return 0


def register(subparsers) -> None:
    p = subparsers.add_parser("sim", help="generate a synthetic session (video, telemetry, truth) from a scenario")
    p.add_argument("scenario", help="scenario TOML file (see sim_fixtures/scenarios/)")
    p.add_argument("--out", required=True, help="session directory to write")
    p.set_defaults(func=run)

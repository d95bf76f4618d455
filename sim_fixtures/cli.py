"""``skyfix sim SCENARIO.toml --out DIR``: generate a synthetic session from a scenario file."""

from __future__ import annotations

from pathlib import Path

from groundstation.outputs import output_dir

from .generate import generate
from .scenario import load_scenario


def run(args) -> int:
    path = Path(args.scenario)
    sc = load_scenario(path)
    output_dir(args.out)
    report = generate(
        sc,
        args.out,
        scenario_text=path.read_text(),
        video=not args.no_video,
        progress=not args.quiet,
    )
    counts = ", ".join(f"{k} {n}" for k, n in sorted(report.messages.items()))
    made = (
        f"rendered and encoded in {report.render_s:.1f} s" if not args.no_video else "without video"
    )
    print(
        f"{sc.name}: {report.frames} frames {sc.camera.width}x{sc.camera.height} {made} "
        f"({report.total_s:.1f} s in all); tlog: {counts} -> {report.session}"
    )
    return 0


def register(subparsers, name: str, help: str | None = None) -> None:
    """Adds the subcommand ``name`` with its one-line ``help`` (both from :data:`groundstation.cli.COMMANDS`)."""
    p = subparsers.add_parser(name, help=help)
    p.add_argument("scenario", help="scenario TOML file (see sim_fixtures/scenarios/)")
    p.add_argument("--out", required=True, help="session directory to write")
    p.add_argument(
        "--no-video",
        action="store_true",
        help="no video.mp4 (fast): telemetry, depth, truth and track.csv for geometry-only tests",
    )
    p.add_argument("--quiet", action="store_true", help="no progress output")
    p.set_defaults(func=run)

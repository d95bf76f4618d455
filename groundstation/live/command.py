"""``skyfix run``'s command line: its options (:mod:`.config`), the checks before anything starts
(:mod:`.preflight`: a mistake is exit 2 and one line), then the service (:mod:`.service`, imported only then).

``--check`` runs every check, prints what it checked in one line and exits 0 (or 2 with the first mistake), without
starting anything.
"""

from __future__ import annotations

import argparse

from groundstation.live import config, preflight


def run(args: argparse.Namespace) -> int:
    """``skyfix run``: exit code 0 after a clean stop (or a passed ``--check``), 2 for a mistake."""
    cfg = config.run_config(args)
    preflight.start_checks(args, cfg)
    if args.check:
        print(f"skyfix run --check: ok: {preflight.full_check(args, cfg)}")
        return 0
    from groundstation.live import service

    return service.run(cfg)


def register(subparsers, name: str, help: str | None = None) -> None:
    """Adds the subcommand ``name`` with its one-line ``help`` (both from :data:`groundstation.cli.COMMANDS`)."""
    p = subparsers.add_parser(
        name,
        help=help,
        usage="%(prog)s --calibration FILE --video URL|none --gps-input URL|none [--config FILE] [options]",
        description="The live service: reads the UAV's MAVLink telemetry and video and the UUV's depth (Zenoh); "
        "publishes each fix on Zenoh (--fix-key) and sends GPS_INPUT to the UUV's autopilot "
        "(--gps-input); health on --status-key once a second. --video and --gps-input are named, or "
        "said to be none. Several UUVs in one video: one [[uuv]] table each in the --config file (id, its "
        "depth, keys, GPS_INPUT link, init_bbox). Stops on Ctrl-C or SIGTERM.",
        epilog="example: skyfix run --calibration cal.toml --mavlink udpin:0.0.0.0:14550 --video udp://0.0.0.0:5600 "
        "--zenoh-connect tcp/192.168.2.2:7447 --gps-input udpout:192.168.2.2:14660",
    )
    p.add_argument(
        "--check",
        action="store_true",
        help="check the configuration end to end (files, URLs and their "
        "schemes, credentials, free ports), print what was checked and exit 0, or 2 at the first "
        "mistake; starts nothing",
    )
    config.add_arguments(p)
    p.set_defaults(func=run)

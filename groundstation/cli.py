"""The ``skyfix`` command: one subcommand per module, each adding itself with ``register``."""

from __future__ import annotations

import argparse
import importlib
import sys
from importlib.metadata import version

from groundstation.mavlink.ingest import LinkError
from groundstation.session.read import SessionError
from groundstation.zenoh_session import ZenohError
from localizer.calibration import ConfigError

SUBCOMMANDS = (
    "groundstation.offline.process",
    "groundstation.offline.import_flight",
    "groundstation.offline.evaluate",
    "sim_fixtures.cli",
    "groundstation.live.service",
    "groundstation.live.console",
    "groundstation.fuse.service",
    "groundstation.replay",
    "groundstation.calibration.command",
    "groundstation.offline.export",
    "groundstation.offline.report",
    "groundstation.latency.meter",
    "groundstation.latency.estimate",
)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="skyfix", description="UUV position from UAV imagery")
    parser.add_argument("--version", action="version", version=f"skyfix {version('skyfix')}")
    sub = parser.add_subparsers(dest="command", required=True)
    for name in SUBCOMMANDS:
        importlib.import_module(name).register(sub)
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except (SessionError, ConfigError, LinkError, ZenohError) as e:
        print(f"skyfix {args.command}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())

"""The ``skyfix`` command: one subcommand per module, each adding itself with ``register``."""

from __future__ import annotations

import argparse
import importlib
import sys
from importlib.metadata import version

from localizer.calibration import ConfigError

from .mavlink_io import LinkError
from .session import SessionError
from .zenoh_session import ZenohError

SUBCOMMANDS = (
    "groundstation.process",
    "groundstation.evaluate",
    "sim_fixtures.cli",
    "groundstation.service",
    "groundstation.console",
    "groundstation.replay",
    "groundstation.calibrate",
    "groundstation.export",
    "groundstation.report",
    "groundstation.latency",
    "groundstation.latency_estimate",
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

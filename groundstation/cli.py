"""The ``skyfix`` command: one subcommand per entry of :data:`COMMANDS`, each added by its module's ``register``.

Only the chosen subcommand's module is imported (the modules pull in pymavlink, Zenoh, aiohttp, OpenCV, ...):
the others are listed with their one-line help and nothing else.
"""

from __future__ import annotations

import argparse
import atexit
import gc
import importlib
import os
import sys
import threading

#: Every subcommand, in ``skyfix --help``'s order: its name, the module whose
#: ``register(subparsers, name, help)`` adds it (its arguments, its ``func``) and its one-line help.
COMMANDS = (
    ("process", "groundstation.offline.process", "process a recorded session into positions.csv"),
    (
        "import",
        "groundstation.offline.import_flight",
        "a flight's own records (DataFlash log, camera video, depth) as a session",
    ),
    (
        "evaluate",
        "groundstation.offline.evaluate",
        "accuracy of sessions with truth.csv: refraction vs straight ray",
    ),
    (
        "mosaic",
        "groundstation.offline.mosaic",
        "a georeferenced mosaic of the bottom (Cloud-Optimised GeoTIFF) from a session's video",
    ),
    (
        "tiles",
        "groundstation.map.tiles",
        "a GeoTIFF (the mosaic, an orthophoto) as web-map tiles: a Z/X/Y.png folder, an MBTiles file",
    ),
    (
        "sim",
        "sim_fixtures.cli",
        "generate a synthetic session (video, telemetry, truth) from a scenario",
    ),
    (
        "run",
        "groundstation.live.command",
        "the live service: MAVLink, Zenoh and video in; fixes and GPS_INPUT out",
    ),
    ("status", "groundstation.live.console", "the live service's status, once or --watch"),
    ("select", "groundstation.live.console", "select the UUV in the live service (box or click)"),
    ("release", "groundstation.live.console", "let go of the target: no fix until a new selection"),
    (
        "acquire",
        "groundstation.live.console",
        "await a target again (automatic acquisition near the UUV's own position)",
    ),
    (
        "confirm",
        "groundstation.live.console",
        "the target tracked now is the UUV: the safety gates take it however far from the last trusted track",
    ),
    (
        "fuse",
        "groundstation.fuse.service",
        "several drones over one UUV: their fixes fused, one GPS_INPUT to the UUV",
    ),
    (
        "replay",
        "groundstation.session.replay",
        "re-stream a recorded session live (MAVLink, Zenoh depth, video)",
    ),
    (
        "calibrate",
        "groundstation.calibration.command",
        "camera calibration: from board images, or imported from OpenCV/Kalibr/ROS",
    ),
    (
        "export",
        "groundstation.offline.export",
        "positions.csv as GeoJSON, KML, GPX or CSV (QGIS, Google Earth)",
    ),
    (
        "report",
        "groundstation.offline.report",
        "PNG plots of a run: top view, error/accuracy over time, statuses",
    ),
    (
        "latency",
        "groundstation.latency.meter",
        "measure the camera's glass-to-first-packet latency with a time code",
    ),
    (
        "estimate-latency",
        "groundstation.latency.estimate",
        "a recording's video-to-telemetry time offset, from image motion",
    ),
    (
        "deploy",
        "groundstation.live.deploy",
        "print a shipped deployment file (systemd unit, configuration, Zenoh) or copy them all",
    ),
)


class _Version(argparse.Action):
    """``--version``: the installed package's version, looked up only when asked for."""

    def __init__(self, option_strings, dest, **kwargs):
        super().__init__(
            option_strings,
            dest=argparse.SUPPRESS,
            default=argparse.SUPPRESS,
            nargs=0,
            help="show program's version number and exit",
        )

    def __call__(self, parser, namespace, values, option_string=None):
        from importlib.metadata import version

        print(f"skyfix {version('skyfix')}")
        parser.exit()


def _one_line_errors() -> tuple[type[Exception], ...]:
    """The errors a subcommand reports as one line and exit code 2; imported only once one is raised."""
    from groundstation.mavlink.ingest import LinkError
    from groundstation.runtime.zenoh_session import ZenohError
    from groundstation.session import SessionError
    from localizer.calibration import ConfigError

    return (SessionError, ConfigError, LinkError, ZenohError)


def main(argv=None) -> int:
    """The command ``argv``; None: the program's (``sys.argv``), after which the interpreter exits: its objects are
    frozen first (:func:`gc.freeze`), so its exit does not collect them (a tenth of a CPU-second after ``skyfix
    process --uuv all``, on one core with the other idle: ``bench/process_timeline.py``), and :func:`_leave`
    ends it."""
    try:
        rc = _main(sys.argv[1:] if argv is None else list(argv))
    finally:
        if argv is None:
            gc.freeze()
    if argv is None:
        _leave(rc)
    return rc


def _leave(rc: int) -> None:
    """End the program with exit code ``rc`` at once when a thread besides the main one is still running: a
    thread left inside a native call (``skyfix run`` stopped while opening a stream from a server that never
    answers: FFmpeg waits out its open timeout) would wake in the interpreter's finalization and crash it
    (SIGSEGV after the service's orderly stop: 4 of 30 such stops on a loaded machine, 0 of 40 since;
    tests/test_live_links.py). What the interpreter does before its finalization still runs, in its order (the
    threads' exit hooks: process pools told to stop and joined; then :mod:`atexit`: logging's and
    multiprocessing's clean-up) and the output is flushed; only the finalization is skipped, which has nothing left
    to save: the command has returned."""
    if all(t is threading.main_thread() or not t.is_alive() for t in threading.enumerate()):
        return
    threading._shutdown()  # what the interpreter does first at its exit: wake and join what waits for it
    atexit._run_exitfuncs()  # ... then this
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe, a closed stream: nothing more can reach it
            pass
    os._exit(rc)


def _main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="skyfix", description="UUV position from UAV imagery")
    parser.add_argument("--version", action=_Version)
    sub = parser.add_subparsers(dest="command", required=True)
    # skyfix's own options take no value: the first word that is not an option is the subcommand.
    chosen = next((a for a in argv if not a.startswith("-")), None)
    for name, module, help_line in COMMANDS:
        if name == chosen:
            importlib.import_module(module).register(sub, name, help_line)
        else:
            sub.add_parser(name, help=help_line)  # listed only: never the one parsed
    args = parser.parse_args(argv)
    from groundstation.outputs import tidied

    try:
        with tidied():  # a failed command leaves no empty output folder
            return args.func(args)
    except KeyboardInterrupt:
        return 130
    except _one_line_errors() as e:
        print(f"skyfix {args.command}: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())

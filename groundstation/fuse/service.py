"""``skyfix fuse``: several drones' fixes of one UUV in, one fused fix stream and the UUV's GPS_INPUT out.

Each drone's ``skyfix run`` publishes its fixes on its own key under the UUV's
(``--fix-key skyfix/uuv/<id>/drone/<drone>/fix``) and sends no GPS_INPUT; the fuser (on any
laptop, or on the UUV's companion computer) subscribes to ``skyfix/uuv/<id>/drone/*/fix``,
takes the drones named with ``--source`` (any other key's fixes are counted, never fused; without a
``--source`` it does not start), fuses (:mod:`groundstation.fuse.fuser`) and is the one that sends GPS_INPUT
(:mod:`groundstation.runtime.gps_input`, its gate judging accuracy, age and order only: each
source was judged against its own track). Out, on Zenoh: the fused fixes (``skyfix.fix/1``,
unchanged) on ``skyfix/uuv/<id>/fix``, the status (``skyfix.fuse-status/1``) once a second on
``skyfix/uuv/<id>/fuse/status`` with a liveliness token, and for late joiners queryables
answering the latest of both. A drone that drops out leaves the others' fixes going out with
no gap; one that joins is used after its own gate confirmed it (a second).

Before anything is opened, the start's checks of ``skyfix run`` (:mod:`groundstation.runtime.preflight`): the
drones named (``--source``), GPS_INPUT's connection string and signing key (readable by its owner only), and a
Zenoh that trusts nobody by default (TLS with mutual authentication and access control beyond loopback, no
multicast scouting, its credentials files readable, the private ones by their owner only; ``--zenoh-insecure``
for a network of the team's own); without ``--zenoh-listen`` or ``--zenoh-config`` it listens on loopback only
(:data:`LOCAL_LISTEN`). A mistake is exit 2 and one line naming the value.

Workers (:mod:`groundstation.runtime.workers`, stopped in this order): the subscription and the
queryables, then the status, then GPS_INPUT (its last message says no fix).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import math
import signal
import time
from dataclasses import dataclass
from pathlib import Path

import zenoh
from pydantic import ValidationError

from groundstation.mavlink.link import read_signing_key
from groundstation.messages import FUSE_STATUS_SCHEMA, FixMessage, FuseStatusMessage
from groundstation.runtime import parts
from groundstation.runtime.logs import Throttle, kind_of
from groundstation.runtime.preflight import (
    link_problem,
    private_file,
    zenoh_credentials,
    zenoh_problem,
)
from groundstation.runtime.queries import ZenohControl
from groundstation.runtime.threads import Handoff
from groundstation.runtime.usage import Usage
from groundstation.runtime.workers import INPUTS, LAST, OUTPUTS, Workers, run_to_end, stopped
from groundstation.runtime.zenoh_fix import ZenohFixSink, ZenohStatus
from groundstation.runtime.zenoh_session import open_session, subscribe
from localizer.calibration import ConfigError
from localizer.fix_gate import MAX_ACCEL_MPS2, MAX_REACH_M, MAX_SPEED_MPS, FixGate
from localizer.fusion import SharedSigmas

from .fuser import CLOCK_TOLERANCE_S, MAX_HZ, Fuser

log = logging.getLogger("skyfix.fuse")

#: the fuser's Zenoh listener without --zenoh-listen or --zenoh-config: this machine only, a port of the system's
LOCAL_LISTEN = "tcp/127.0.0.1:0"
#: the fuser's outputs, registered parts (:mod:`groundstation.runtime.parts`): the fused fixes on Zenoh, GPS_INPUT
#: when ``--gps-input`` names a link
FUSE_OUTPUTS = ("zenoh", "gps_input")
HANDOFF_FIXES = 512  # fix messages received but not yet taken by the event loop (beyond: oldest dropped, counted)


@dataclass(frozen=True)
class Arrival:
    """What the sinks know of a fused fix beyond the fix: when its newest source fix arrived; no window."""

    t_recv: float
    window: None = None


class FixSources:
    """Worker subscribing to the drones' fix messages and handing each to the fuser, then its result to ``sinks``."""

    def __init__(self, session: zenoh.Session, key: str, fuser: Fuser, sinks: list):
        self.session = session
        self.key = key
        self.fuser = fuser
        self.sinks = sinks
        self.received = 0
        self.bad = 0
        self.handoff: Handoff | None = None
        self._throttle = Throttle()

    async def run(self) -> None:
        self.handoff = Handoff(
            asyncio.get_running_loop(), lambda item: self.on_payload(*item), HANDOFF_FIXES
        )
        await subscribe(self.session, self.key, self.handoff)

    def on_payload(self, key: str, data: bytes, t_recv: float) -> None:
        self.received += 1
        try:
            fix = FixMessage.model_validate_json(data).to_fix()
        except ValidationError as e:
            self.bad += 1
            err = e.errors()[0]
            where = ".".join(str(x) for x in err["loc"]) or "payload"
            if self._throttle(kind_of(f"{key} {where} {err['type']}")):
                log.warning("fix on %s refused: %s: %s (%r)", key, where, err["msg"], data[:120])
            return
        fused = self.fuser.on_fix(key, fix, t_recv)
        if fused is not None:
            for sink in self.sinks:
                sink.on_fix(fused, Arrival(t_recv))

    def status(self, now: float) -> dict:
        return {
            "key": self.key,
            "received": self.received,
            "bad": self.bad,
            "handoff": self.handoff.status() if self.handoff else None,
        }


async def serve(args: argparse.Namespace) -> dict:
    """Run the fuser until stopped; returns the final status."""
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    session = open_session(
        args.zenoh_connect or (),
        args.zenoh_listen,
        multicast=args.zenoh_multicast,
        config_file=args.zenoh_config,
    )
    closers = []
    try:
        max_age_s = args.fix_max_age_ms / 1000.0
        fuser = Fuser(
            lambda: FixGate(
                max_speed_mps=args.uuv_max_speed_mps,
                max_accel_mps2=args.uuv_max_accel_mps2,
                max_h_acc_m=args.fix_max_h_acc_m,
                max_age_s=max_age_s,
            ),
            args.uuv_max_accel_mps2,
            args.max_hz,
            sources=args.source_keys,
            max_speed_mps=args.uuv_max_speed_mps,
            clock_tolerance_s=args.clock_tolerance_ms / 1000.0,
            max_reach_m=args.uuv_max_reach_m,
            shared=SharedSigmas(
                gnss_m=args.shared_gnss_m,
                height_m=args.shared_height_m,
                clock_s=args.shared_clock_ms / 1000.0,
            ),
        )
        gate = FixGate(max_h_acc_m=args.fix_max_h_acc_m, max_age_s=max_age_s, judge_track=False)
        outputs = fuse_outputs(args, session, gate)
        fix_sink = next(out for _, out in outputs if isinstance(out, ZenohFixSink))
        closers.append(fix_sink.close)
        workers = Workers()
        workers.section("uuv", lambda now: args.uuv)
        sources = workers.add(
            FixSources(session, args.sources, fuser, [out for _, out in outputs]),
            INPUTS,
            "input",
        )
        workers.section("fusion", fuser.status)
        workers.section("fix", lambda now: fix_sink.latest)
        status_sink = ZenohStatus(
            session,
            args.status_key,
            args.alive_key,
            workers.status,
            model=FuseStatusMessage,
            schema=FUSE_STATUS_SCHEMA,
        )
        queryables = ZenohControl(
            session,
            None,
            "skyfix/cmd",
            {args.fix_key: lambda: fix_sink.latest, args.status_key: lambda: status_sink.latest},
        )
        workers.add(queryables, INPUTS, "control", lambda now: queryables.status())
        workers.section(
            "zenoh",
            lambda now: {
                "peers": len(list(session.info.peers_zid())) + len(list(session.info.routers_zid()))
            },
        )
        workers.section("process", Usage().status)
        workers.add(status_sink, OUTPUTS)
        for part, out in outputs:
            workers.add(out, LAST, part.section)
        log.info(
            "skyfix fuse: UUV %s, fixes from %s (taken from %s), fused on %s, GPS_INPUT %s",
            args.uuv,
            sources.key,
            ", ".join(args.source_keys),
            args.fix_key,
            args.gps_input,
        )
        await workers.run(stopped(stop, args.duration_s))
        return workers.status(time.time())
    finally:
        for close in closers:
            close()
        session.close()


def fuse_outputs(
    args: argparse.Namespace, session, gate: FixGate
) -> list[tuple[parts.Part, parts.Output]]:
    """The fuser's outputs (:data:`FUSE_OUTPUTS`) built by name from the registry the live service's come from, with
    their parts: the arguments are the UUV's options and the run's (``fix_key``, ``gps_input``, its signing key and
    rate, ``fix_max_age_ms``), ``gate`` GPS_INPUT's (accuracy, age and order only)."""
    built = []
    for name in FUSE_OUTPUTS:
        part = parts.part("output", name)
        out = part.build(
            parts.OutputInput(name, args, args, session, gate, parts.settings(part, {}))
        )
        if out is not None:  # gps_input without a link: nothing
            built.append((part, out))
    return built


def run(args: argparse.Namespace) -> int:
    """``skyfix fuse``: exit code 0 after a clean stop."""
    logging.basicConfig(
        level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s: %(message)s"
    )
    base = f"skyfix/uuv/{args.uuv}"
    args.sources = args.sources or f"{base}/drone/*/fix"
    preflight(args, base)
    args.fix_key = args.fix_key or f"{base}/fix"
    args.status_key = args.status_key or f"{base}/fuse/status"
    args.alive_key = args.alive_key or f"{base}/fuse/alive"
    final = run_to_end("fuse", serve(args), (OSError, zenoh.ZError), args.stats)
    if final is None:
        return 2
    log.info("stopped: %s", json.dumps(final["fusion"]))
    return 0


def preflight(args: argparse.Namespace, base: str) -> None:
    """The start's checks (see the module doc): ``args.source_keys`` and ``args.zenoh_listen`` set;
    :class:`ConfigError` for the first mistake."""
    args.source_keys = source_keys(args.source, base, args.sources)
    if args.gps_input and not args.gps_input.startswith("zenoh:"):
        why = link_problem(args.gps_input)
        if why:
            raise ConfigError("options", "--gps-input", args.gps_input, why)
    if args.gps_input_signing_key:
        private_file("options", "--gps-input-signing-key", args.gps_input_signing_key)
        read_signing_key(args.gps_input_signing_key)
    if args.zenoh_config and not Path(args.zenoh_config).is_file():
        raise ConfigError("options", "--zenoh-config", args.zenoh_config, "no such file")
    if not (args.zenoh_listen or args.zenoh_config):
        args.zenoh_listen = [LOCAL_LISTEN]
    flag = (
        "--zenoh-config"
        if args.zenoh_config
        else "--zenoh-connect"
        if args.zenoh_connect
        else "--zenoh-listen"
    )
    value = args.zenoh_config or ", ".join(args.zenoh_connect or args.zenoh_listen or ())
    why = zenoh_problem(
        args.zenoh_connect or (),
        args.zenoh_listen or (),
        multicast=args.zenoh_multicast,
        config_file=args.zenoh_config,
        insecure=args.zenoh_insecure,
    )
    if why:
        raise ConfigError("options", flag, value, why)
    if args.zenoh_config:
        zenoh_credentials(
            args.zenoh_config,
            args.zenoh_connect or (),
            args.zenoh_listen or (),
            "options",
            "--zenoh-config",
        )


def source_keys(sources: list[str] | None, base: str, keyexpr: str) -> list[str]:
    """The fix keys of the ``--source`` drones (an id is ``BASE/drone/ID/fix``, a key with ``/`` as it is), each within
    the subscription ``keyexpr``; :class:`ConfigError` for none, or for one the subscription does not cover."""
    if not sources:
        raise ConfigError(
            "options",
            "--source",
            None,
            "missing: name each drone whose fixes may be fused (--source a "
            "--source b): no drone is trusted by default",
        )
    keys = [s if "/" in s else f"{base}/drone/{s}/fix" for s in sources]
    for s, key in zip(sources, keys, strict=True):
        if not s or any(c in s for c in "*$?#"):
            raise ConfigError("options", "--source", s, "one drone's id or fix key, no wildcards")
        try:
            covered = zenoh.KeyExpr(keyexpr).includes(zenoh.KeyExpr(key))
        except zenoh.ZError as e:
            raise ConfigError("options", "--source", s, f"not a Zenoh key ({e})") from None
        if not covered:
            raise ConfigError("options", "--source", s, f"{key} is not within --sources {keyexpr}")
    return keys


def _number(low: float, name: str, strict: bool = False):
    def parse(text: str) -> float:
        try:
            x = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} = {text!r}: not a number") from None
        if not (math.isfinite(x) and (x > low if strict else x >= low)):
            raise argparse.ArgumentTypeError(
                f"{name} = {text}: must be {'>' if strict else '≥'} {low:g}"
            )
        return x

    return parse


def _chunk(text: str) -> str:
    if not text or any(c in text for c in "/*$?#"):
        raise argparse.ArgumentTypeError(f"--uuv = {text!r}: one Zenoh key chunk (no / * $ ? #)")
    return text


def register(subparsers, name: str, help: str | None = None) -> None:
    """Adds the subcommand ``name`` with its one-line ``help`` (both from :data:`groundstation.cli.COMMANDS`)."""
    p = subparsers.add_parser(
        name,
        help=help,
        description="Subscribes to the drones' fixes of one UUV (each drone's skyfix run with --fix-key "
        "skyfix/uuv/ID/drone/NAME/fix), takes those of the --source drones only, aligns them in time, "
        "rejects a drone that disagrees beyond its sigmas, fuses the rest by their covariances, publishes "
        "the fused fixes on skyfix/uuv/ID/fix and sends them as GPS_INPUT (--gps-input). Stops on Ctrl-C "
        "or SIGTERM.",
        epilog="example: skyfix fuse --uuv rov1 --source a --source b --zenoh-connect tcp/192.168.2.2:7447 --gps-input udpout:192.168.2.2:14660",
    )
    p.add_argument(
        "--uuv",
        type=_chunk,
        metavar="ID",
        default="uuv",
        help="the UUV's id, in the keys (default %(default)s)",
    )
    p.add_argument(
        "--source",
        action="append",
        metavar="DRONE",
        help="a drone whose fixes may be fused: its id (its fixes on skyfix/uuv/ID/drone/DRONE/fix) or its "
        "whole fix key; once per drone, at least one. Fixes on any other key are counted, never fused",
    )
    p.add_argument(
        "--sources",
        metavar="KEYEXPR",
        help="the key expression subscribed to, the --source keys within it "
        "(default skyfix/uuv/ID/drone/*/fix)",
    )
    p.add_argument("--fix-key", metavar="KEY", help="the fused fixes (default skyfix/uuv/ID/fix)")
    p.add_argument(
        "--status-key", metavar="KEY", help="the 1 Hz status (default skyfix/uuv/ID/fuse/status)"
    )
    p.add_argument(
        "--alive-key", metavar="KEY", help="liveliness token (default skyfix/uuv/ID/fuse/alive)"
    )
    p.add_argument(
        "--gps-input",
        metavar="URL",
        help="GPS_INPUT to the UUV's autopilot: a MAVLink URL "
        "(udpout:HOST:PORT, tcp:HOST:PORT, /dev/ttyUSB0,57600) or zenoh:KEY (BlueOS's mavlink/in)",
    )
    p.add_argument(
        "--gps-input-hz",
        metavar="HZ",
        type=_number(5.0, "--gps-input-hz"),
        default=10.0,
        help="GPS_INPUT at least this often (the latest state again without a new fix; default 10, ≥ 5)",
    )
    p.add_argument(
        "--gps-input-signing-key",
        metavar="FILE",
        help="sign GPS_INPUT (MAVLink 2) with this key file",
    )
    p.add_argument(
        "--max-hz",
        metavar="HZ",
        type=_number(0.0, "--max-hz", strict=True),
        default=MAX_HZ,
        help="fused fixes per second at most (default %(default)g)",
    )
    p.add_argument(
        "--fix-max-age-ms",
        metavar="MS",
        type=_number(0.0, "--fix-max-age-ms", strict=True),
        default=500.0,
        help="a fix older than this is not sent as valid (default %(default)g)",
    )
    p.add_argument(
        "--fix-max-h-acc-m",
        metavar="M",
        type=_number(0.0, "--fix-max-h-acc-m", strict=True),
        default=2.5,
        help="a fix less accurate than this is not used (default %(default)g)",
    )
    p.add_argument(
        "--clock-tolerance-ms",
        metavar="MS",
        type=_number(0.0, "--clock-tolerance-ms", strict=True),
        default=CLOCK_TOLERANCE_S * 1000.0,
        help="a fix stamped further ahead of this machine's clock is "
        "refused as from the future (default %(default)g)",
    )
    p.add_argument(
        "--shared-gnss-m",
        metavar="M",
        type=_number(0.0, "--shared-gnss-m"),
        default=None,
        help="1-sigma (per axis) of the GNSS error all drones share: one sky, one RTK base (default: each fix's "
        "own GNSS sigma, sigma_uav_m, taken as shared whole; 0: the drones' receivers err independently)",
    )
    p.add_argument(
        "--shared-height-m",
        metavar="M",
        type=_number(0.0, "--shared-height-m"),
        default=0.3,
        help="1-sigma of the height error all barometers share (the weather's trend), at most each fix's "
        "own (default %(default)g)",
    )
    p.add_argument(
        "--shared-clock-ms",
        metavar="MS",
        type=_number(0.0, "--shared-clock-ms"),
        default=10.0,
        help="1-sigma of the clock error all stations share, times the UUV's speed (default %(default)g)",
    )
    p.add_argument(
        "--uuv-max-speed-mps",
        metavar="MPS",
        type=_number(0.0, "--uuv-max-speed-mps", strict=True),
        default=MAX_SPEED_MPS["bluerov2"],
        help="the UUV's top speed, for each drone's gate",
    )
    p.add_argument(
        "--uuv-max-reach-m",
        metavar="M",
        type=_number(0.0, "--uuv-max-reach-m", strict=True),
        default=MAX_REACH_M,
        help="the fused fixes' track reaches at most this far from its last fix, however long since "
        "(default %(default)g, as skyfix run's gate)",
    )
    p.add_argument(
        "--uuv-max-accel-mps2",
        metavar="MPS2",
        type=_number(0.0, "--uuv-max-accel-mps2", strict=True),
        default=MAX_ACCEL_MPS2["bluerov2"],
        help="the UUV's largest acceleration",
    )
    p.add_argument(
        "--zenoh-connect", action="append", metavar="ENDPOINT", help="Zenoh endpoint to connect to"
    )
    p.add_argument(
        "--zenoh-listen", action="append", metavar="ENDPOINT", help="Zenoh endpoint to listen on"
    )
    p.add_argument(
        "--zenoh-config", metavar="FILE", help="Zenoh JSON5 config file (deploy/zenoh/*.json5)"
    )
    p.add_argument("--zenoh-multicast", action="store_true", help="Zenoh multicast scouting on")
    p.add_argument(
        "--zenoh-insecure",
        action="store_true",
        help="allow Zenoh without TLS, mutual authentication and access control beyond this machine (a network "
        "of the team's own only: anyone on it can feed the fuser; deploy/zenoh/README.md)",
    )
    p.add_argument(
        "--duration-s",
        metavar="S",
        type=_number(0.0, "--duration-s", strict=True),
        help="stop after this long",
    )
    p.add_argument("--stats", metavar="FILE", help="write the final status here as JSON")
    p.set_defaults(func=run)

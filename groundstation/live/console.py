"""``skyfix status | select | release | acquire | confirm``: the operator's console in a shell, over Zenoh.

Each command queries the running service's queryable ``<prefix>/<command>``
(:mod:`groundstation.live.control`) and prints its JSON answer; ``skyfix status`` prints
a short summary instead (``--json`` for the whole status), once or every
``--interval-s`` with ``--watch`` (Ctrl-C stops). No answer within ``--timeout-s``,
or a refused command, is one line on stderr and exit code 2 (``--watch`` keeps
asking). Without ``--zenoh-connect`` or ``--zenoh-config`` they connect to
:data:`~groundstation.runtime.zenoh_session.LOCAL_ENDPOINT`, where a ``skyfix run`` on this
machine listens by default.

    skyfix status --watch
    skyfix status --zenoh-connect tcp/192.168.2.1:7447 --watch
    skyfix select --box 320,180,40,36 --frame 1234
    skyfix select --point 331,190
    skyfix release
    skyfix confirm          # the target tracked now is the UUV (the safety gates: see groundstation.live.control)
"""

from __future__ import annotations

import argparse
import json
import sys
import time

from groundstation.runtime.zenoh_session import LOCAL_ENDPOINT, open_session


class ConsoleError(Exception):
    """No answer, or a refused command; one line."""


def ask(session, key: str, payload: dict | None, timeout_s: float) -> dict:
    """The first answer of the queryable ``key`` as JSON; :class:`ConsoleError` for an error reply or none."""
    kw = {"payload": json.dumps(payload)} if payload is not None else {}
    for reply in session.get(key, timeout=timeout_s, **kw):
        if reply.ok is not None:
            return json.loads(reply.ok.payload.to_string())
        text = reply.err.payload.to_string()
        try:
            text = json.loads(text)["error"]
        except (ValueError, KeyError, TypeError):
            pass
        raise ConsoleError(text)
    raise ConsoleError(f"no skyfix service answered on {key} within {timeout_s:g} s")


def _age(now: float, t) -> str:
    return "-" if t is None else f"{now - t:.2f} s"


def summary(status: dict) -> str:
    """A few lines an operator reads at a glance: the target, the latest fix, the inputs, GPS_INPUT, the height from
    the UUV's size, the reference's offset, the web page."""
    now = status.get("t", time.time())
    target = status.get("target") or {}
    line = [time.strftime("%H:%M:%S", time.localtime(now)) + f"  target {target.get('state')}"]
    if target.get("origin"):
        line.append(f"({target['origin']})")
    if target.get("since_t") is not None:
        line.append(f"for {_age(now, target['since_t'])}")
    if target.get("u") is not None:
        line.append(f"at ({target['u']:.1f}, {target['v']:.1f}) px")
    fix = status.get("fix") or {}
    if fix:
        where = fix.get("status")
        if where == "ok":
            acc = fix.get("h_acc_m")
            where = f"{fix['lat']:.7f}, {fix['lon']:.7f}" + (
                f" ±{acc:.2f} m" if acc is not None else ""
            )
        line.append(
            f"| fix frame {fix.get('frame')}: {where}, exposure {_age(now, fix.get('t'))} ago"
        )
    lines = [" ".join(line)]
    inputs = []
    for name in ("video", "depth", "uuv_position"):
        part = status.get(name)
        if part:
            inputs.append(f"{name} age {part.get('age_s', '-')} s")
            if name == "depth" and part.get("depth_m") is not None:
                sigma = part.get("sigma_m")
                inputs[-1] += (
                    f" ({part['depth_m']:.2f} m"
                    + (f" ±{sigma:.2f}" if sigma is not None else "")
                    + f", {part.get('source')})"
                )
    pipeline = status.get("pipeline") or {}
    inputs.append(f"frames {pipeline.get('processed')} (dropped {pipeline.get('dropped')})")
    gps = status.get("gps_input")
    if gps:
        gates = gps.get("gates") or {}
        inputs.append(
            f"GPS_INPUT sent {gps.get('sent')} (valid {gps.get('sent_valid')}), gates {gates.get('state')}"
        )
    lines.append("  " + ", ".join(inputs))
    size = status.get("height_from_size")
    if (
        size
        and size.get("frames")
        and size.get("bias_m") is not None
        and size.get("sigma_m") is not None
    ):
        lines.append(
            f"  height from the UUV's size: configured - measured {size['bias_m']:+.2f} ± {size['sigma_m']:.2f} m"
            f" over {size['frames']} frames ({'sure' if size['sure'] else 'not sure'})"
        )
    if status.get("reference"):
        lines.append("  " + _reference(status["reference"]))
    if status.get("bottom"):
        lines.append("  " + _bottom(status["bottom"]))
    ui = status.get("ui")
    if ui and ui.get("url"):
        lines.append(
            f"  web page {ui['url']}{' (with its token)' if ui.get('token') else ''}, "
            f"{ui.get('viewers')} open"
        )
    return "\n".join(lines)


def _bottom(b: dict) -> str:
    """The status's ``bottom`` section in a line: whether the fixes take the estimate, what it is and how sure."""
    line = (
        f"pose from the bottom {b['state']}: {b['frames']} frames in {b['window_s']:g} s, {b['fits']} estimates "
        f"({b['refused']} gave none), {b['corrected']} fixes corrected, {b['kept_own']} kept their own"
    )
    if b["tilt_fwd_deg"] is None:
        return line
    told = [w for w, on in (("tilt", b["tilt_applied"]), ("heading", b["heading_applied"])) if on]
    return (
        f"{line}; tilt fwd {b['tilt_fwd_deg']:+.2f}° right {b['tilt_right_deg']:+.2f}° ± {b['sigma_tilt_deg']:.2f}°, "
        f"heading {b['heading_deg']:+.2f}° ± {b['sigma_heading_deg']:.2f}°, walk north {b['walk_n_m']:+.2f} "
        f"east {b['walk_e_m']:+.2f} ± {b['sigma_walk_m']:.2f} m ({' and '.join(told) or 'the walk only'} applied), "
        f"{b['features']} features, {b['age_s']:.1f} s old"
    )


def _reference(ref: dict) -> str:
    """The status's ``reference`` section in a line: whether its offset is added to the fixes, how sure it is, and a
    buoy's reports."""
    last = "never seen" if ref["age_s"] is None else f"last seen {ref['age_s']:.1f} s ago"
    if ref["state"] != "applied":
        line = f"reference {ref['state']}: {ref['seen']} of {ref['searched']} frames found, {last}"
    else:
        line = (
            f"reference applied: offset north {ref['offset_n_m']:+.3f} ± {ref['sigma_n_m']:.3f} m, "
            f"east {ref['offset_e_m']:+.3f} ± {ref['sigma_e_m']:.3f} m, {ref['sightings']} sightings in "
            f"{ref['window_s']:g} s, {last}"
        )
    buoy = ref.get("buoy")
    if not buoy:
        return line
    age = buoy["last_report_age_s"]
    return (
        f"{line}; buoy system {buoy['system_id']}: {buoy['reports']} reports, "
        f"{'none yet' if age is None else f'the last {age:.1f} s ago'}, "
        f"{buoy['refused']} malformed and {sum(buoy['foreign'].values())} of other systems refused"
    )


def _pair(text: str, n: int, what: str) -> list[float]:
    try:
        values = [float(x) for x in text.split(",")]
    except ValueError:
        values = []
    if len(values) != n:
        raise argparse.ArgumentTypeError(f"{text!r}: expected {what}")
    return values


def run(args: argparse.Namespace) -> int:
    prefix = args.prefix.rstrip("/")
    local = not args.zenoh_connect and not args.zenoh_config
    session = open_session(
        (LOCAL_ENDPOINT,) if local else args.zenoh_connect or (), config_file=args.zenoh_config
    )
    try:
        if args.command == "status":
            return _status(session, f"{prefix}/status", args)
        payload = None
        if args.command == "select":
            payload = {"box": args.box} if args.box is not None else {"point": args.point}
            if args.frame is not None:
                payload["frame"] = args.frame
        try:
            print(json.dumps(ask(session, f"{prefix}/{args.command}", payload, args.timeout_s)))
        except ConsoleError as e:
            print(f"skyfix {args.command}: error: {e}", file=sys.stderr)
            return 2
        return 0
    finally:
        session.close()


def _status(session, key: str, args) -> int:
    while True:
        try:
            status = ask(session, key, None, args.timeout_s)
            print(json.dumps(status) if args.json else summary(status), flush=True)
            code = 0
        except ConsoleError as e:
            print(f"skyfix status: error: {e}", file=sys.stderr, flush=True)
            code = 2
        if not args.watch:
            return code
        try:
            time.sleep(args.interval_s)
        except KeyboardInterrupt:
            return 0


def register(subparsers, name: str, help: str | None = None) -> None:
    """Adds the subcommand ``name`` (status, select, release, acquire or confirm) with its one-line ``help`` (both from
    :data:`groundstation.cli.COMMANDS`)."""
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument(
        "--zenoh-connect",
        action="append",
        metavar="ENDPOINT",
        help="Zenoh endpoint of the service (or a router), e.g. tcp/192.168.2.1:7447 (repeatable; "
        f"default without --zenoh-config: {LOCAL_ENDPOINT}, where skyfix run listens by default)",
    )
    common.add_argument("--zenoh-config", help="Zenoh JSON5 config file (deploy/zenoh/*.json5)")
    common.add_argument(
        "--prefix", default="skyfix/cmd", help="the service's --control-prefix (default skyfix/cmd)"
    )
    common.add_argument(
        "--timeout-s", type=float, default=3.0, help="how long to wait for the answer"
    )
    common.set_defaults(func=run)
    if name == "status":
        p = subparsers.add_parser(
            name, parents=[common], help=help, description=__doc__.split("\n\n")[0]
        )
        p.add_argument(
            "--watch", action="store_true", help="ask again every --interval-s until Ctrl-C"
        )
        p.add_argument("--interval-s", type=float, default=1.0)
        p.add_argument(
            "--json", action="store_true", help="print the whole status as one JSON line"
        )
    elif name == "select":
        p = subparsers.add_parser(name, parents=[common], help=help)
        what = p.add_mutually_exclusive_group(required=True)
        what.add_argument(
            "--box",
            type=lambda s: _pair(s, 4, "X,Y,W,H"),
            metavar="X,Y,W,H",
            help="box around the UUV, pixels of the distorted frame",
        )
        what.add_argument(
            "--point", type=lambda s: _pair(s, 2, "U,V"), metavar="U,V", help="a click on the UUV"
        )
        p.add_argument(
            "--frame", type=int, help="the frame the box or click belongs to (default: the newest)"
        )
    elif name in ("release", "acquire", "confirm"):
        subparsers.add_parser(name, parents=[common], help=help)
    else:
        raise ValueError(f"not a console command: {name!r}")

"""Opening the Zenoh session the live service and replay share.

Peer mode by default, multicast scouting off unless asked (a field laptop should
not discover every Zenoh node on the boat's network by surprise), explicit
``connect``/``listen`` endpoints such as ``tcp/192.168.2.2:7447``. A JSON5 config
file (see ``deploy/zenoh/``) may set everything else; the endpoints and flags
given here are applied on top of it. Unless the file says otherwise, a lost router or
peer is tried again every :data:`RETRY` ms (Zenoh's default backs off to 4 s), so a
router that restarts is back in use within about half a second.

Nobody on the network is trusted by default (:func:`trust_problem`, checked by ``skyfix run`` at every start):
beyond this machine's loopback Zenoh speaks TLS with mutual authentication (``tls/`` or ``quic/`` endpoints and the
team's certificates, ``enable_mtls``), and a peer or router that listens there checks who sends what
(``access_control``): ``deploy/zenoh/peer.json5`` and ``deploy/zenoh/README.md``.
"""

from __future__ import annotations

import asyncio
import json
import re
import time
from collections.abc import Sequence

import zenoh

#: connect/retry: 100 ms, doubling to 500 ms
RETRY = {"period_init_ms": 100, "period_max_ms": 500, "period_increase_factor": 2}
#: Where ``skyfix run`` listens without ``--zenoh-listen`` or ``--zenoh-config`` (this machine only), and where
#: ``skyfix status``, ``select``, ``release`` and ``acquire`` look for it without ``--zenoh-connect``
LOCAL_ENDPOINT = "tcp/127.0.0.1:7448"
_RUST_LOCATION = re.compile(r"\s+at\s+/\S+?\.rs:\d+\.?")
#: Zenoh protocols that authenticate both ends and encrypt (with ``enable_mtls`` and a root CA)
SECURE_PROTOCOLS = ("tls", "quic")
#: The password of the shipped example ``deploy/zenoh/usrpwd.json5``, refused wherever it is used
EXAMPLE_PASSWORD = "CHANGE-ME"
_JSON5_MESSAGE = re.compile(r'Json5Err\(Message \{ msg: "(.*?)", location: .*')


class ZenohError(OSError):
    """A Zenoh session that cannot be opened or configured; the message is one line without Rust internals."""


def _clean(e: Exception) -> str:
    """Zenoh's error text without source locations and debug wrappers."""
    text = _JSON5_MESSAGE.sub(r"\1", _RUST_LOCATION.sub("", str(e)))
    return " ".join(text.split()).rstrip(".")


def make_config(
    connect: Sequence[str] = (),
    listen: Sequence[str] = (),
    *,
    multicast: bool = False,
    mode: str | None = None,
    config_file: str | None = None,
) -> zenoh.Config:
    """A :class:`zenoh.Config`: ``config_file`` (JSON5) if given, then mode, scouting and endpoints."""
    conf = zenoh.Config.from_file(config_file) if config_file else zenoh.Config()
    if mode is not None or config_file is None:
        conf.insert_json5("mode", json.dumps(mode or "peer"))
    if not multicast:
        conf.insert_json5("scouting/multicast/enabled", "false")
    if json.loads(conf.get_json("connect/retry")) is None:
        conf.insert_json5("connect/retry", json.dumps(RETRY))
    if connect:
        conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
    if listen:
        conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    return conf


def _setting(conf: zenoh.Config, key: str):
    """The value at ``key`` of a configuration (None when unset)."""
    return json.loads(conf.get_json(key) or "null")


def endpoints(conf: zenoh.Config, which: str) -> list[str]:
    """The ``which`` (``connect`` or ``listen``) endpoints of a configuration in its mode: its own, or Zenoh's
    defaults for the mode when it leaves them unset (``listen`` of a peer: ``tcp/[::]:0``, every interface)."""
    value = _setting(conf, f"{which}/endpoints") or []
    return value if isinstance(value, list) else value.get(_setting(conf, "mode") or "peer", [])


def is_loopback(endpoint: str) -> bool:
    """Whether a Zenoh endpoint (``tcp/127.0.0.1:7448``, ``tls/[::1]:7447``, ``unixsock-stream/...``) stays on
    this machine."""
    proto, _, address = endpoint.partition("#")[0].partition("/")
    if proto.startswith("unixsock") or proto == "vsock":
        return True
    host = address.rpartition(":")[0].strip("[]").lower()
    return host == "localhost" or host == "::1" or host.startswith("127.")


def trust_problem(conf: zenoh.Config, *, insecure: bool = False) -> str | None:
    """Why the configuration lets strangers command the service or feed it, in one line; None when it does not.

    Refused: the shipped example password; unless ``insecure`` (a network of the team's own), an endpoint beyond
    loopback that is not TLS/QUIC, TLS without mutual authentication or a root CA, multicast scouting, and a peer
    or router listening beyond loopback without ``access_control``."""
    if _setting(conf, "transport/auth/usrpwd/password") == EXAMPLE_PASSWORD:
        return f"transport/auth/usrpwd/password is the example {EXAMPLE_PASSWORD!r}: give each user a password of its own"
    if insecure:
        return None
    hint = "(deploy/zenoh/README.md; a network of the team's own only: zenoh_insecure = true)"
    if _setting(conf, "scouting/multicast/enabled") is not False:
        return f"multicast scouting connects to whatever answers on the network {hint}"
    outside = [
        e for which in ("connect", "listen") for e in endpoints(conf, which) if not is_loopback(e)
    ]
    for endpoint in outside:
        if endpoint.partition("/")[0] not in SECURE_PROTOCOLS:
            return (
                f"{endpoint}: plain {endpoint.partition('/')[0]} beyond this machine: anyone on the network could "
                f"command skyfix and feed it; use tls/ with the team's certificates {hint}"
            )
    tls = _setting(conf, "transport/link/tls") or {}
    if outside and not (tls.get("enable_mtls") and tls.get("root_ca_certificate")):
        return (
            f"{outside[0]}: TLS without transport/link/tls/enable_mtls and root_ca_certificate: anyone could "
            f"connect {hint}"
        )
    listening = [e for e in endpoints(conf, "listen") if not is_loopback(e)]
    if (
        listening
        and _setting(conf, "mode") != "client"
        and not _setting(conf, "access_control/enabled")
    ):
        return (
            f"{listening[0]}: listens beyond this machine without access_control: every certificate could "
            f"command skyfix and feed it {hint}"
        )
    return None


def open_session(
    connect: Sequence[str] = (),
    listen: Sequence[str] = (),
    *,
    multicast: bool = False,
    mode: str | None = None,
    config_file: str | None = None,
) -> zenoh.Session:
    """An open Zenoh session; the caller must ``close()`` it (in ``finally``), or the process hangs at exit.

    Raises :class:`ZenohError` (one line naming the endpoints or file) when it cannot be opened.
    """
    where = (
        ", ".join(
            [f"connect {c}" for c in connect]
            + [f"listen {e}" for e in listen]
            + ([f"config {config_file}"] if config_file else [])
        )
        or "defaults"
    )
    try:
        return zenoh.open(
            make_config(connect, listen, multicast=multicast, mode=mode, config_file=config_file)
        )
    except zenoh.ZError as e:
        raise ZenohError(f"Zenoh ({where}): {_clean(e)}") from None


def put_json(target, obj: dict, session: zenoh.Session) -> None:
    """Publish ``obj`` as JSON (encoding application/json, timestamped) on a publisher or key."""
    payload = json.dumps(obj, allow_nan=False)
    if isinstance(target, str):
        session.put(
            target,
            payload,
            encoding=zenoh.Encoding.APPLICATION_JSON,
            timestamp=session.new_timestamp(),
        )
    else:
        target.put(
            payload, encoding=zenoh.Encoding.APPLICATION_JSON, timestamp=session.new_timestamp()
        )


async def subscribe(session: zenoh.Session, key: str, handoff) -> None:
    """Subscribe to ``key`` until cancelled: Zenoh's thread hands each sample over as ``(key, payload bytes,
    t_recv_unix)`` through ``handoff`` (a bounded :class:`~groundstation.runtime.threads.Handoff`), nothing more."""

    def on_sample(sample: zenoh.Sample) -> None:
        handoff.put((str(sample.key_expr), sample.payload.to_bytes(), time.time()))

    sub = session.declare_subscriber(key, on_sample)
    try:
        await asyncio.Event().wait()
    finally:
        handoff.close()
        sub.undeclare()

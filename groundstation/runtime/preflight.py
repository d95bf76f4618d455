"""The start's checks that ``skyfix run`` and ``skyfix fuse`` share: a MAVLink connection string's form, a Zenoh
session's settings (it can be made, it lets no stranger command or feed the process) and the credentials files it
names (readable, the private ones by their owner only)."""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path

from localizer.contract import ConfigError

#: pymavlink connection kinds skyfix's transports open (:func:`groundstation.mavlink.transport.open_transport`)
NETWORK_LINKS = ("tcp", "tcpin", "udpout", "udpin", "udp")
#: Zenoh configuration keys naming credentials: (key, private: must not be readable by others)
ZENOH_CREDENTIALS = (
    ("transport/link/tls/root_ca_certificate", False),
    ("transport/link/tls/listen_certificate", False),
    ("transport/link/tls/listen_private_key", True),
    ("transport/link/tls/connect_certificate", False),
    ("transport/link/tls/connect_private_key", True),
    ("transport/auth/usrpwd/dictionary_file", True),
)


def link_problem(url: str) -> str | None:
    """Why a pymavlink-style connection string is not one skyfix opens, None when it is."""
    kind, sep, rest = url.partition(":")
    if sep and kind in NETWORK_LINKS:
        _, colon, port = rest.rpartition(":")
        if not colon or not port.isdigit() or int(port) > 65535:
            return f"expected {kind}:HOST:PORT"
        return None
    device = url.partition(",")[0]
    if device.startswith("/"):
        return None if Path(device).exists() else f"no such device {device}"
    return f"unknown scheme {kind}: (expected {', '.join(k + ':' for k in NETWORK_LINKS)} or a serial device)"


def zenoh_problem(
    connect, listen, *, multicast: bool, config_file: str | None, insecure: bool
) -> str | None:
    """Why a Zenoh session of these settings (:func:`~groundstation.runtime.zenoh_session.make_config`'s) cannot be made or
    lets strangers command or feed its process (:func:`~groundstation.runtime.zenoh_session.trust_problem`); None when
    neither. ``skyfix run`` and ``skyfix fuse`` check it at every start."""
    from groundstation.runtime.zenoh_session import make_config, trust_problem

    try:
        conf = make_config(connect, listen, multicast=multicast, config_file=config_file)
    except Exception as e:  # noqa: BLE001 - zenoh raises ZError (and ValueError) on a bad file or endpoint
        return f"not a Zenoh configuration: {e}"
    return trust_problem(conf, insecure=insecure)


def private_file(source: str, key: str, path: str) -> None:
    """:class:`ConfigError` when the credentials file ``path`` cannot be read or others may read it."""
    try:
        mode = os.stat(path).st_mode
        Path(path).read_bytes()
    except OSError as e:
        raise ConfigError(source, key, path, f"cannot read: {e.strerror or e}") from None
    if mode & (stat.S_IRWXG | stat.S_IRWXO):
        raise ConfigError(
            source, key, path, f"others may read it (mode {stat.S_IMODE(mode):04o}): chmod 600"
        )


def zenoh_credentials(config_file: str, connect, listen, source: str, key: str) -> list[str]:
    """The credentials files a Zenoh configuration names (TLS keys, a password file) read, the private ones
    readable by their owner only (:func:`private_file`); the paths checked. :class:`ConfigError` naming ``source``
    and ``key`` (where the configuration file was given) when the file is no Zenoh configuration."""
    from groundstation.runtime.zenoh_session import make_config

    try:
        conf = make_config(connect, listen, config_file=config_file)
    except Exception as e:  # noqa: BLE001 - zenoh raises ZError (and ValueError) on a bad file or endpoint
        raise ConfigError(source, key, config_file, f"not a Zenoh configuration: {e}") from None
    checked = []
    for setting, private in ZENOH_CREDENTIALS:
        path = json.loads(conf.get_json(setting) or "null")
        if not path:
            continue
        if private:
            private_file(config_file, setting, path)
        elif not os.access(path, os.R_OK):
            raise ConfigError(config_file, setting, path, "cannot read")
        checked.append(path)
    return checked

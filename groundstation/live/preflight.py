"""What ``skyfix run`` checks before it starts anything: a mistake is one line and exit 2 before the dive, not a
service that runs forever logging it.

At every start (:func:`start_checks`: no socket opened, nothing written): the video and GPS_INPUT named, or said
to be none (:func:`groundstation.live.config.unnamed_inputs`); the video as FFmpeg would open it (a file that
exists, a scheme this FFmpeg knows: ``htp://`` is refused, not retried forever); every MAVLink connection string's
form (``udpin:HOST:PORT``, ``tcp:HOST:PORT``, … or a serial device that exists); the files named exist.

``skyfix run --check`` (:func:`full_check`) adds what takes longer, still without starting anything: the
calibration and the Zenoh configuration parse; the credentials read (the GPS_INPUT signing key, the Zenoh TLS keys
and password file) and are not readable by others; the recording's folder can be made; every port the run would
bind (the web page, the MAVLink inputs, the video's, the Zenoh listeners) is free.
"""

from __future__ import annotations

import argparse
import ctypes
import errno
import os
import socket
from collections.abc import Iterator
from functools import cache
from pathlib import Path

from groundstation.config_files import load_calibration
from groundstation.live import config
from groundstation.mavlink.ingest import LinkError
from groundstation.runtime.preflight import (
    link_problem,
    private_file,
    zenoh_credentials,
    zenoh_problem,
)
from localizer.contract import ConfigError


def origin(args: argparse.Namespace, name: str) -> tuple[str, str]:
    """``(source, key)`` an error about option ``name`` names: the config file and its key, or ``options`` and the
    flag given."""
    if getattr(args, name, None) in (None, False) and getattr(args, "config", None):
        return args.config, name
    return "options", config.flag(name)


@cache
def ffmpeg_protocols() -> frozenset[str] | None:
    """The input protocols the FFmpeg that PyAV loaded opens (``avio_enum_protocols``); None when its library cannot
    be found (then no scheme is refused)."""
    import av  # noqa: F401 - loads libavformat into this process

    with open("/proc/self/maps") as maps:
        path = next((line.split()[-1] for line in maps if "libavformat" in line), None)
    if path is None:
        return None
    enum = ctypes.CDLL(path).avio_enum_protocols
    enum.restype, enum.argtypes = ctypes.c_char_p, [ctypes.POINTER(ctypes.c_void_p), ctypes.c_int]
    opaque, names = ctypes.c_void_p(), set()
    while (name := enum(ctypes.byref(opaque), 0)) is not None:
        names.add(name.decode())
    return frozenset(names)


def video_problem(url: str) -> str | None:
    """Why FFmpeg would never open ``url`` (see :mod:`groundstation.video.inputs`), None when it may."""
    from groundstation.video.frames import VideoError
    from groundstation.video.inputs import parse_video_input

    try:
        video = parse_video_input(url)
    except VideoError as e:
        return str(e).removeprefix(f"{url}: ")
    if video.kind == "file" and not Path(video.file).is_file():
        return "no such file" if not Path(video.file).exists() else "not a file"
    if video.kind == "v4l2" and not Path(video.file).exists():
        return f"no such device {video.file}"
    if video.kind == "url":
        scheme = url.partition("://")[0].lower()
        known = ffmpeg_protocols()
        if known is not None and scheme not in known:
            return f"unknown scheme {scheme}:// (udp, rtp, rtsp, a file, or one FFmpeg opens: {', '.join(sorted(known))})"
    return None


def _links(cfg: config.RunConfig) -> Iterator[tuple[str, str]]:
    """Every MAVLink connection string of the run: (option, value)."""
    if cfg.mavlink_backend == "pymavlink":
        yield "mavlink", cfg.mavlink
    for u in cfg.uuvs:
        if u.gps_input and not u.gps_input.startswith("zenoh:"):
            yield "gps_input", u.gps_input
        if u.depth_mavlink:
            yield "depth_mavlink", u.depth_mavlink


def _files(cfg: config.RunConfig) -> Iterator[tuple[str, str]]:
    """Every file the run reads: (option, path)."""
    yield "calibration", cfg.calibration
    if cfg.zenoh_config:
        yield "zenoh_config", cfg.zenoh_config
    if cfg.mavlink_signing_key:
        yield "mavlink_signing_key", cfg.mavlink_signing_key
    for u in cfg.uuvs:
        if u.gps_input_signing_key:
            yield "gps_input_signing_key", u.gps_input_signing_key


def start_checks(args: argparse.Namespace, cfg: config.RunConfig) -> None:
    """The checks of every start (see the module doc); :class:`ConfigError` for the first mistake."""
    config.unnamed_inputs(args)
    if cfg.video:
        why = video_problem(cfg.video)
        if why:
            raise ConfigError(*origin(args, "video"), cfg.video, why)
    for name, url in _links(cfg):
        why = link_problem(url)
        if why:  # as the link itself says it (LinkError), naming the option too
            source, key = origin(args, name)
            raise LinkError(
                f"MAVLink {url!r}: cannot open: {why} ({key}{'' if source == 'options' else ' in ' + source})"
            )
    for name, path in _files(cfg):
        if not Path(path).is_file():
            raise ConfigError(*origin(args, name), path, "no such file")
    _zenoh_trust(args, cfg)


def _zenoh_trust(args: argparse.Namespace, cfg: config.RunConfig) -> None:
    """:class:`ConfigError` when the run's Zenoh lets strangers command it or feed it (:func:`zenoh_problem`)."""
    name = (
        "zenoh_config"
        if cfg.zenoh_config
        else "zenoh_connect"
        if cfg.zenoh_connect
        else "zenoh_listen"
    )
    value = cfg.zenoh_config or ", ".join(cfg.zenoh_connect or cfg.zenoh_listen_endpoints)
    why = zenoh_problem(
        cfg.zenoh_connect,
        cfg.zenoh_listen_endpoints,
        multicast=cfg.zenoh_multicast,
        config_file=cfg.zenoh_config,
        insecure=cfg.zenoh_insecure,
    )
    if why:
        raise ConfigError(*origin(args, name), value, why)


def _credentials(args, cfg: config.RunConfig) -> list[str]:
    """Checks every credentials file (:func:`private_file`, certificates only readable); what was checked."""
    from groundstation.mavlink.link import read_signing_key

    checked = []
    if cfg.mavlink_signing_key:
        private_file(*origin(args, "mavlink_signing_key"), cfg.mavlink_signing_key)
        read_signing_key(cfg.mavlink_signing_key, "--mavlink-signing-key")
        checked.append(cfg.mavlink_signing_key)
    for u in cfg.uuvs:
        if u.gps_input_signing_key:
            private_file(*origin(args, "gps_input_signing_key"), u.gps_input_signing_key)
            read_signing_key(u.gps_input_signing_key)
            checked.append(u.gps_input_signing_key)
    if cfg.zenoh_config:
        checked += zenoh_credentials(
            cfg.zenoh_config, cfg.zenoh_connect, cfg.zenoh_listen, *origin(args, "zenoh_config")
        )
    return checked


def _bind(kind: int, host: str, port: int) -> str | None:
    """Why ``(host, port)`` cannot be bound now (``kind``: SOCK_STREAM or SOCK_DGRAM), None when it can."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, kind) as s:
        if kind == socket.SOCK_STREAM:
            # as the servers bind: TIME_WAIT is no owner
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host.strip("[]"), port))
        except OSError as e:
            return "in use by another program" if e.errno == errno.EADDRINUSE else e.strerror
    return None


def _ports(cfg: config.RunConfig) -> Iterator[tuple[str, str, int, str, int]]:
    """Every port the run binds: (option, value, socket kind, host, port)."""
    from groundstation.live.ui.bind import parse_bind
    from groundstation.video.inputs import parse_video_input

    if not cfg.no_ui:
        host, port = parse_bind(cfg.ui)
        yield "ui", cfg.ui, socket.SOCK_STREAM, host, port
    for name, url in _links(cfg):
        kind, _, rest = url.partition(":")
        if kind in ("udpin", "udp", "tcpin"):
            host, _, port = rest.rpartition(":")
            yield (
                name,
                url,
                socket.SOCK_STREAM if kind == "tcpin" else socket.SOCK_DGRAM,
                host or "0.0.0.0",
                int(port),
            )
    if cfg.video:
        video = parse_video_input(cfg.video)
        if video.port is not None:
            yield "video", cfg.video, socket.SOCK_DGRAM, "0.0.0.0", video.port
    for endpoint in _zenoh_listeners(cfg):
        proto, _, address = endpoint.partition("/")
        host, _, port = address.partition("#")[0].rpartition(":")
        if proto in ("tcp", "tls") and port.isdigit():
            yield "zenoh_listen", endpoint, socket.SOCK_STREAM, host, int(port)
        elif proto == "udp" and port.isdigit():
            yield "zenoh_listen", endpoint, socket.SOCK_DGRAM, host, int(port)


def _zenoh_listeners(cfg: config.RunConfig) -> list[str]:
    """The endpoints the run's Zenoh session listens on: the flags' or the default's, else its configuration file's
    (its own, or those of its mode when the file leaves them to Zenoh's defaults)."""
    from groundstation.runtime.zenoh_session import endpoints, make_config

    if not cfg.zenoh_config:
        return list(cfg.zenoh_listen_endpoints)
    return endpoints(
        make_config(cfg.zenoh_connect, cfg.zenoh_listen, config_file=cfg.zenoh_config), "listen"
    )


def _recording_folder(args, cfg: config.RunConfig) -> str:
    """Whether the recording's folder can be made (``record``: new or empty); what it will be."""
    name = "record" if cfg.record else "recordings"
    target = Path(cfg.recording)
    if cfg.record and target.is_dir() and any(target.iterdir()):
        raise ConfigError(
            *origin(args, name),
            cfg.record,
            "exists and is not empty (a recording is never "
            "overwritten; --recordings PARENT records each start into a new folder of its own)",
        )
    existing = next(p for p in (target, *target.parents) if p.exists())
    if not existing.is_dir() or not os.access(existing, os.W_OK | os.X_OK):
        raise ConfigError(
            *origin(args, name),
            cfg.recording,
            f"cannot be made: {existing} is not a writable folder",
        )
    return f"{name} {cfg.recording}"


def full_check(args: argparse.Namespace, cfg: config.RunConfig) -> str:
    """``--check``: the start's checks and the longer ones (see the module doc); a one-line summary of what was
    checked, or :class:`ConfigError` for the first mistake."""
    start_checks(args, cfg)
    cal = load_calibration(cfg.calibration)
    done = [
        f"calibration {cfg.calibration} ({cal.camera.width}x{cal.camera.height}, {cal.mount.attitude_source})",
        f"video {cfg.video or config.NONE}",
        f"MAVLink {cfg.mavlink}",
        "GPS_INPUT " + ", ".join(u.gps_input or config.NONE for u in cfg.uuvs),
    ]
    credentials = _credentials(args, cfg)
    if credentials:
        done.append(f"credentials {', '.join(credentials)}")
    if cfg.recording:
        done.append(_recording_folder(args, cfg))
    free = []
    for name, value, kind, host, port in _ports(cfg):
        if port == 0:
            continue
        why = _bind(kind, host, port)
        if why:
            raise ConfigError(*origin(args, name), value, f"port {port}: {why}")
        free.append(f"{'tcp' if kind == socket.SOCK_STREAM else 'udp'} {port}")
    if free:
        done.append(f"ports free: {', '.join(free)}")
    return "; ".join(done)

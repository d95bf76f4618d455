"""Options of ``skyfix run``: command-line flags over an optional config TOML.

Every option has one entry in :data:`OPTIONS`; the flag ``--video-latency-ms``
is the config key ``video_latency_ms``. A config file is a flat TOML table of
such keys (see ``deploy/field.toml``); relative paths in it are relative to the
file. A flag given on the command line wins over the file; the file wins over the
defaults. Unknown keys and wrong types are errors naming the key and value.
"""

from __future__ import annotations

import argparse
import tomllib
from dataclasses import dataclass, fields
from pathlib import Path

from localizer.calibration import Calibration, ConfigError, calibration_from_dict
from localizer.tracking import TRACKERS


@dataclass
class RunConfig:
    calibration: str | None = None  # TOML with [camera], [mount], [water], [tracker] of session.toml v1
    mavlink: str = "udpin:0.0.0.0:14550"  # the UAV, a pymavlink connection string
    mavlink_backend: str = "pymavlink"
    video: str | None = None  # anything FFmpeg opens
    video_latency_ms: float | str = 0.0  # glass to first packet, ms, or "auto" (estimated from the image's motion)
    no_request_rates: bool = False  # leave the autopilot's telemetry rates alone
    telemetry_wait_ms: float = 300.0  # how long a frame may wait for attitude telemetry after it
    zenoh_connect: tuple[str, ...] = ()
    zenoh_listen: tuple[str, ...] = ()
    zenoh_config: str | None = None  # a Zenoh JSON5 config file; endpoints above are added to it
    zenoh_multicast: bool = False
    depth_key: str = "uuv/depth"
    depth_source: str = "skyfix"  # "skyfix": {"t", "depth_m"} JSON; "blueos": mavlink-server VFR_HUD
    fix_key: str = "skyfix/uuv/fix"
    status_key: str = "skyfix/status"
    alive_key: str = "skyfix/alive"
    gps_input: str | None = None  # the UUV autopilot: pymavlink string, or "zenoh:mavlink/in" (BlueOS)
    gps_input_hz: float = 10.0
    fix_max_age_ms: float = 500.0  # an ok fix older than this goes out as "no fix"
    tracker: str = "default"
    record: str | None = None
    duration_s: float | None = None  # stop after this many seconds (tests, benchmarks)
    stats: str | None = None  # write final counters and latencies to this JSON file at exit


CHOICES = {"mavlink_backend": ("pymavlink", "mavsdk"), "depth_source": ("skyfix", "blueos")}
_PATHS = ("calibration", "zenoh_config", "record", "stats")
_HELP = {
    "calibration": "TOML with the [camera], [mount], [water], [tracker] tables of session.toml v1",
    "mavlink": "the UAV's MAVLink, e.g. udpin:0.0.0.0:14550, tcp:host:port, /dev/ttyUSB0",
    "mavlink_backend": "library reading the UAV's MAVLink",
    "video": "the UAV's video: udp://127.0.0.1:5600, an .sdp file, rtsp://..., a file",
    "video_latency_ms": "glass to first packet (camera + encoder + network), ms, as skyfix latency measures it; "
                        "'auto': estimated from the image's motion against the camera attitude",
    "no_request_rates": "do not ask the autopilot for the telemetry rates skyfix needs (a shared link)",
    "telemetry_wait_ms": "longest wait of a frame for the attitude sample after it (slow radios need ~300)",
    "zenoh_connect": "Zenoh endpoint to connect to, e.g. tcp/192.168.2.2:7447 (repeatable)",
    "zenoh_listen": "Zenoh endpoint to listen on (repeatable)",
    "zenoh_config": "Zenoh JSON5 config file (deploy/zenoh/*.json5)",
    "zenoh_multicast": "enable Zenoh multicast scouting",
    "depth_key": "Zenoh key of the UUV's depth (default uuv/depth; mavlink/*/*/VFR_HUD with --depth-source blueos)",
    "depth_source": "depth payload: skyfix JSON {t, depth_m} or BlueOS mavlink-server VFR_HUD",
    "fix_key": "Zenoh key the fixes are published on",
    "status_key": "Zenoh key of the 1 Hz health/status JSON",
    "alive_key": "Zenoh liveliness token key",
    "gps_input": "UUV autopilot for GPS_INPUT: pymavlink string (udpout:192.168.2.2:14550) or zenoh:mavlink/in",
    "gps_input_hz": "minimum GPS_INPUT rate (Hz); each new fix is also sent at once",
    "fix_max_age_ms": "a fix older than this is sent to the autopilot as 'no fix'",
    "tracker": "tracker backend name",
    "record": "record the run as a session directory (format v1)",
    "duration_s": "stop after this many seconds",
    "stats": "write final counters and latency percentiles to this JSON file",
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--config`` and one flag per :class:`RunConfig` field (default None: not given)."""
    parser.add_argument("--config", help="TOML file of run options (flags win over it)")
    for f in fields(RunConfig):
        flag = "--" + f.name.replace("_", "-")
        kind = f.type
        kw = {"help": _HELP[f.name], "default": None, "dest": f.name}
        if f.name in CHOICES:
            kw["choices"] = CHOICES[f.name]
        if f.name == "video_latency_ms":
            parser.add_argument(flag, type=_latency_ms, **kw)
        elif kind == "bool":
            parser.add_argument(flag, action="store_true", **kw)
        elif kind.startswith("tuple"):
            parser.add_argument(flag, action="append", metavar="ENDPOINT", **kw)
        elif "float" in kind:
            parser.add_argument(flag, type=float, **kw)
        else:
            parser.add_argument(flag, **kw)


def _latency_ms(text: str) -> float | str:
    """A ``--video-latency-ms`` value: a number of ms, or "auto"."""
    if text == "auto":
        return text
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is neither a number of ms nor auto") from None


def _check(key: str, value, kind: str, source: str):
    if key == "video_latency_ms" and value == "auto":
        return value
    ok = {
        "bool": isinstance(value, bool),
        "float": isinstance(value, (int, float)) and not isinstance(value, bool),
        "tuple": isinstance(value, list) and all(isinstance(v, str) for v in value),
        "str": isinstance(value, str),
    }
    base = "tuple" if kind.startswith("tuple") else "float" if "float" in kind else "bool" if kind == "bool" else "str"
    if not ok[base]:
        raise ConfigError(source, key, value, f"expected {base}")
    if key in CHOICES and value not in CHOICES[key]:
        raise ConfigError(source, key, value, f"expected one of {', '.join(CHOICES[key])}")
    return tuple(value) if base == "tuple" else float(value) if base == "float" else value


def read_config_file(path: str) -> dict:
    """The options a config TOML sets, checked; relative paths resolved against its directory."""
    p = Path(path)
    try:
        data = tomllib.loads(p.read_text())
    except OSError as e:
        raise ConfigError(path, "file", path, e.strerror or str(e)) from None
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(path, "file", path, f"malformed TOML: {e}") from None
    kinds = {f.name: f.type for f in fields(RunConfig)}
    out = {}
    for key, value in data.items():
        if key not in kinds:
            raise ConfigError(path, key, value, f"unknown option (known: {', '.join(kinds)})")
        value = _check(key, value, kinds[key], path)
        if key in _PATHS and not Path(value).is_absolute():
            value = str(p.parent / value)
        out[key] = value
    return out


def run_config(args: argparse.Namespace) -> RunConfig:
    """Defaults, then the config file, then the flags given."""
    values = read_config_file(args.config) if getattr(args, "config", None) else {}
    for f in fields(RunConfig):
        given = getattr(args, f.name, None)
        if given is not None and given is not False:
            values[f.name] = tuple(given) if isinstance(given, list) else given
    cfg = RunConfig(**values)
    if cfg.calibration is None:
        raise ConfigError("options", "--calibration", None, "required (flag or config file)")
    if cfg.tracker not in TRACKERS:
        raise ConfigError("options", "--tracker", cfg.tracker, f"expected one of {', '.join(TRACKERS)}")
    if cfg.record and cfg.mavlink_backend == "mavsdk":
        raise ConfigError("options", "--record", cfg.record, "recording needs --mavlink-backend pymavlink")
    if not cfg.gps_input_hz >= 5.0:
        raise ConfigError("options", "--gps-input-hz", cfg.gps_input_hz, "ArduPilot needs ≥ 5 Hz")
    if cfg.video_latency_ms != "auto" and not 0.0 <= cfg.video_latency_ms <= 2000.0:
        raise ConfigError("options", "--video-latency-ms", cfg.video_latency_ms, "expected 0 … 2000 or auto")
    if not 0.0 <= cfg.telemetry_wait_ms <= 2000.0:
        raise ConfigError("options", "--telemetry-wait-ms", cfg.telemetry_wait_ms, "expected 0 … 2000")
    return cfg


def load_calibration(path: str) -> Calibration:
    """The calibration tables of a TOML file (session.toml or a calibration-only file)."""
    try:
        data = tomllib.loads(Path(path).read_text())
    except OSError as e:
        raise ConfigError(path, "file", path, e.strerror or str(e)) from None
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(path, "file", path, f"malformed TOML: {e}") from None
    return calibration_from_dict(data, source=path)

"""Options of ``skyfix run``: one contract, :class:`RunConfig`, for the flags and the config TOML.

Every option is one field of :class:`RunConfig`: its type (choices are a ``Literal``),
default and description make the flag ``--video-latency-ms``, its ``--help`` line, the
config key ``video_latency_ms`` and the JSON Schema (``groundstation/schemas/run-config.schema.json``).
A config file is a flat TOML table of such keys (see ``deploy/field.toml``); paths in
it (fields typed :data:`FilePath`) are relative to the file. A flag given on the
command line wins over the file; the file wins over the defaults. Unknown keys and
wrong values are one-line errors naming the file (or ``options`` for a flag), the key
and the value.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path
from typing import Annotated, Any, Literal, get_args, get_origin

from annotated_types import Ge, Gt, Le
from pydantic import BeforeValidator, Field, StringConstraints, model_validator
from pydantic.dataclasses import dataclass

from groundstation.config_files import read_toml
from groundstation.live import registry
from groundstation.live.sources.depth_ardusub import autopilot_prefix
from groundstation.live.sources.uuv_position import parse_hint
from groundstation.live.ui.bind import check_token, parse_bind
from groundstation.mavlink.transport import ANY_PEER
from groundstation.runtime.zenoh_session import LOCAL_ENDPOINT
from groundstation.session.read import PRIMARY_UUV
from localizer.contract import (
    CLOSED,
    ConfigError,
    Flag,
    Invalid,
    NonNegative,
    Number,
    Positive,
    Text,
    Vector4,
    Whole,
    validate,
    within,
)
from localizer.depth import BLUEROV2_MAX_VERTICAL_SPEED_MPS
from localizer.fix_gate import MAX_ACCEL_MPS2, MAX_REACH_M, MAX_SPEED_MPS, WATER_ACCEL_MPS2
from localizer.thrusters import DEADBAND_US
from localizer.tracking import TRACKERS, WITHOUT_LOSS_SIGNAL

BLUEOS_PREFIX = "mavlink/1/1"  # ArduSub's system and component under BlueOS


@dataclasses.dataclass(frozen=True)
class _RelativeToFile:
    """Marks a path option: a relative path in a config file is relative to that file."""

    metavar: str


FilePath = Annotated[Text, _RelativeToFile("FILE")]
DirPath = Annotated[Text, _RelativeToFile("DIR")]
#: The word that says "no such input": ``--video none``, ``--gps-input none`` (a run without them is refused)
NONE = "none"
#: An input that must be named, or said to be :data:`NONE` (read as None)
NamedOrNone = Annotated[Text | None, BeforeValidator(lambda v: None if v == NONE else v)]
#: The inputs ``skyfix run`` refuses to start without: a value, or :data:`NONE` (:func:`unnamed_inputs`)
NAMED_INPUTS = ("video", "gps_input")
#: Each UUV's outputs unless its ``outputs`` names others: its fixes on Zenoh and GPS_INPUT (when ``gps_input``
#: names a link)
DEFAULT_OUTPUTS = ("zenoh", "gps_input")
#: The options that are tables of the config file, never flags: ``[[uuv]]``, ``[parts.NAME]``
FILE_ONLY = ("uuv", "parts")


@dataclass(frozen=True, kw_only=True, config=CLOSED)
class UuvOptions:
    """What ``skyfix run`` needs of each UUV: its depth, its own position estimate, its GPS_INPUT link. The flags and
    keys of one UUV, and the keys of each ``[[uuv]]`` table (:class:`UuvConfig`)."""

    depth_source: Literal[registry.choices("depth")] = Field(
        "skyfix",
        description=f"the UUV's depth (a registered depth source): {registry.described('depth')}",
    )
    depth_key: Text = Field(
        "uuv/depth",
        description="Zenoh key of the depth: skyfix JSON's key, or with "
        "--depth-source blueos the autopilot's prefix mavlink/{system}/{component} (default "
        "there: mavlink/1/1)",
    )
    depth_mavlink: Text | None = Field(
        None,
        description="with --depth-source mavlink: ArduSub's MAVLink, a pymavlink "
        "string (tcp:192.168.2.2:5777, udpin:0.0.0.0:14770, /dev/ttyUSB1,115200)",
    )
    gps_input: NamedOrNone = Field(
        None,
        description="the UUV autopilot for GPS_INPUT: a pymavlink string "
        "(udpout:192.168.2.2:14550) or zenoh:mavlink/in (BlueOS); none: no GPS_INPUT "
        "(required: a run that names neither is refused)",
    )
    gps_input_signing_key: FilePath | None = Field(
        None,
        description="sign GPS_INPUT (MAVLink 2) with the key in "
        "this file: 32 bytes, or 64 hex digits",
    )
    outputs: tuple[Literal[registry.choices("output")], ...] = Field(
        DEFAULT_OUTPUTS,
        description="where the UUV's fixes go (registered outputs, each once): "
        f"{registry.described('output')}",
    )
    parts: dict[Text, dict[Text, Any]] = Field(
        default_factory=dict,
        description="settings of the UUV's depth source and outputs, a table each (config file only): "
        "[parts.NAME] (in a [[uuv]] table: [uuv.parts.NAME]), checked by the part NAME",
    )
    uuv_position_key: Text | None = Field(
        None,
        description="Zenoh key of the UUV's own GLOBAL_POSITION_INT as "
        "BlueOS publishes it (mavlink/1/1/GLOBAL_POSITION_INT): acquire the UUV "
        "near it without a selection",
    )
    uuv_hint: Text | None = Field(
        None,
        description="LAT,LON (degrees) where to look for the UUV until its own estimate arrives",
    )

    @model_validator(mode="after")
    def _signing_needs_a_mavlink_link(self):
        if self.gps_input_signing_key and (
            not self.gps_input or self.gps_input.startswith("zenoh:")
        ):
            raise Invalid(
                "gps_input_signing_key",
                self.gps_input_signing_key,
                "signing needs a MAVLink --gps-input link (not zenoh:)",
            )
        return self

    @model_validator(mode="after")
    def _outputs_once_and_gps_input_among_them(self):
        twice = sorted({name for name in self.outputs if self.outputs.count(name) > 1})
        if twice:
            raise Invalid("outputs", list(self.outputs), f"{twice[0]} named twice")
        if self.gps_input and "gps_input" not in self.outputs:
            raise Invalid(
                "outputs",
                list(self.outputs),
                f"gps_input = {self.gps_input!r} names a link, but gps_input is not among the outputs: "
                'add it, or say gps_input = "none"',
            )
        return self

    @model_validator(mode="after")
    def _parts_settings(self):
        if getattr(self, "uuv", ()):  # several UUVs: each [[uuv]] table's own
            return self
        runs = [
            registry.part("depth", self.depth_source),
            *(registry.part("output", name) for name in self.outputs),
        ]
        for name, table in self.parts.items():
            if name not in {part.name for part in runs}:
                raise Invalid(
                    f"parts.{name}",
                    table,
                    f"{name} is not a part this UUV runs (depth_source {self.depth_source!r}, "
                    f"outputs {', '.join(self.outputs)})",
                )
        for part in runs:  # without a table, its defaults
            registry.settings(part, self.parts.get(part.name, {}))
        return self

    @model_validator(mode="after")
    def _depth_input(self):
        if self.depth_source == "blueos" and self.depth_key != BLUEOS_PREFIX:
            try:
                autopilot_prefix(self.depth_key)
            except ValueError as e:
                if self.depth_key != "uuv/depth":  # the skyfix default: BLUEOS_PREFIX is meant
                    raise Invalid("depth_key", self.depth_key, str(e)) from None
        if self.depth_source == "mavlink" and not self.depth_mavlink:
            raise Invalid(
                "depth_mavlink",
                self.depth_mavlink,
                "--depth-source mavlink needs the link: "
                'depth_mavlink = "tcp:HOST:PORT" (or udpin:, a serial device)',
            )
        if self.depth_mavlink and self.depth_source != "mavlink":
            raise Invalid(
                "depth_mavlink",
                self.depth_mavlink,
                f'used only with depth_source = "mavlink" (it is {self.depth_source!r})',
            )
        return self

    @property
    def depth_input_key(self) -> str:
        """The Zenoh key the depth is read from (blueos: the autopilot's prefix)."""
        if self.depth_source == "blueos" and self.depth_key == "uuv/depth":
            return BLUEOS_PREFIX
        return self.depth_key

    @model_validator(mode="after")
    def _hint_is_a_position(self):
        if self.uuv_hint is not None:
            try:
                parse_hint(self.uuv_hint)
            except ValueError as e:
                raise Invalid("uuv_hint", self.uuv_hint, str(e).split(": ", 1)[1]) from None
        return self


@dataclass(frozen=True, kw_only=True, config=CLOSED)
class UuvConfig(UuvOptions):
    """One ``[[uuv]]`` table: a UUV of several in one video (config file only). Its keys default to ones under
    ``skyfix/uuv/{id}/``."""

    id: Annotated[Text, StringConstraints(pattern=r"^[A-Za-z0-9_-]{1,32}$")] = Field(
        description="the UUV's id: letters, digits, - and _ (its keys are skyfix/uuv/{id}/...)"
    )
    fix_key: Text | None = Field(
        None, description="Zenoh key of its fixes (default: skyfix/uuv/{id}/fix)"
    )
    status_key: Text | None = Field(
        None, description="Zenoh key of its 1 Hz status (default: skyfix/uuv/{id}/status)"
    )
    alive_key: Text | None = Field(
        None, description="its liveliness token (default: skyfix/uuv/{id}/alive)"
    )
    control_prefix: Text | None = Field(
        None, description="prefix of its operator commands (default: skyfix/uuv/{id}/cmd)"
    )
    init_bbox: Vector4 | None = Field(
        None,
        description="x, y, w, h (pixels) of this UUV in the first frame; "
        "without it, a selection or its own position estimate",
    )

    def __post_init__(self):
        for name in ("fix", "status", "alive"):
            if getattr(self, f"{name}_key") is None:
                object.__setattr__(self, f"{name}_key", f"skyfix/uuv/{self.id}/{name}")
        if self.control_prefix is None:
            object.__setattr__(self, "control_prefix", f"skyfix/uuv/{self.id}/cmd")


#: A UUV's keys of its own: two UUVs never share one (GPS_INPUT names no vehicle: two UUVs on one link would
#: each take the other's position too).
OWN_KEYS = (
    "depth_input_key",
    "depth_mavlink",
    "gps_input",
    "uuv_position_key",
    "fix_key",
    "status_key",
    "alive_key",
    "control_prefix",
)


@dataclass(frozen=True, kw_only=True, config=CLOSED)
class RunConfig(UuvOptions):
    """The options of ``skyfix run`` (flags and config file keys)."""

    calibration: FilePath = Field(
        description="TOML with the [camera], [mount], [water], [tracker] tables of "
        "session.toml v1 (and optionally [uncertainty], [timing])"
    )
    mavlink: Text = Field(
        "udpin:0.0.0.0:14550",
        description="the UAV's MAVLink: udpin:0.0.0.0:14550, "
        "tcp:host:port, /dev/ttyUSB0 (a pymavlink connection string)",
    )
    mavlink_backend: Literal[registry.choices("uav")] = Field(
        "pymavlink",
        description=f"library reading the UAV's MAVLink (a registered UAV source): {registry.described('uav')}",
    )
    mavlink_peer: Text | None = Field(
        None,
        description="udpin: the UAV's address HOST:PORT, the only sender taken "
        "(default: the first whose datagram holds the UAV's messages; others counted "
        "in foreign_datagrams); any: every sender (a radio channel or router several "
        "systems share: no lock)",
    )
    mavlink_signing_key: FilePath | None = Field(
        None,
        description="require the UAV's MAVLink signed (MAVLink 2) "
        "with the key in this file (32 bytes, or 64 hex digits); skyfix's "
        "messages to it are signed",
    )
    video: NamedOrNone = Field(
        None,
        description="the UAV's video: udp://127.0.0.1:5600, an .sdp file, rtsp://..., "
        "zenoh:video/<source>/stream (BlueOS's camera manager on Zenoh), "
        "a file (anything FFmpeg opens); none: no video (required: a run that names neither "
        "is refused)",
    )
    video_latency_ms: within(0, 2000) | Literal["auto"] = Field(
        0.0,
        description="glass to first packet (camera + encoder + network), ms, as skyfix latency measures it; "
        "'auto': estimated from the image's motion against the camera attitude",
    )
    height_from_size: Literal["auto", "check", "off"] = Field(
        "check",
        description="the camera's height above the water from the UUV's size in the video ([uuv]): check "
        "(estimate it, show it, warn when the configured height disagrees), auto (also hand it to the height's "
        "fusion once sure), off",
    )
    no_request_rates: Flag = Field(
        False,
        description="do not ask the autopilot for the telemetry rates skyfix needs (a shared link)",
    )
    telemetry_wait_ms: within(0, 2000) = Field(
        300.0,
        description="longest wait of a frame for the attitude sample "
        "after it (slow radios need ~300)",
    )
    require_inputs: Flag = Field(
        False,
        description="exit 2 when the UAV's MAVLink, the depth or the video has sent "
        "nothing 10 s after start (default: keep running and keep saying so)",
    )
    zenoh_connect: tuple[Text, ...] = Field(
        (), description="Zenoh endpoint to connect to, e.g. tcp/192.168.2.2:7447 (repeatable)"
    )
    zenoh_listen: tuple[Text, ...] = Field(
        (),
        description="Zenoh endpoint to listen on (repeatable; default: "
        f"{LOCAL_ENDPOINT} unless --zenoh-config, where skyfix status looks)",
    )
    zenoh_config: FilePath | None = Field(
        None,
        description="Zenoh JSON5 config file (deploy/zenoh/*.json5); the "
        "endpoints above are added to it",
    )
    zenoh_multicast: Flag = Field(False, description="enable Zenoh multicast scouting")
    zenoh_insecure: Flag = Field(
        False,
        description="allow Zenoh without TLS, mutual authentication and access "
        "control beyond this machine (a network of the team's own only: anyone on it "
        "can command skyfix and feed it; deploy/zenoh/README.md)",
    )
    uuv_max_vertical_speed_mps: Annotated[Number, Gt(0)] = Field(
        BLUEROV2_MAX_VERTICAL_SPEED_MPS,
        description="the UUV's top vertical speed (a BlueROV2); a depth jumping further is refused",
    )
    fix_key: Text = Field("skyfix/uuv/fix", description="Zenoh key the fixes are published on")
    status_key: Text = Field(
        "skyfix/status", description="Zenoh key of the 1 Hz health/status JSON"
    )
    alive_key: Text = Field("skyfix/alive", description="Zenoh liveliness token key")
    gps_input_hz: Annotated[Number, Ge(5)] = Field(
        10.0,
        description="minimum GPS_INPUT rate (Hz; ArduPilot needs "
        "≥ 5); each new fix is also sent at once",
    )
    fix_max_age_ms: NonNegative = Field(
        500.0, description="an ok fix older than this is sent to the autopilot as 'no fix'"
    )
    tracker: Literal[TRACKERS] = Field(
        "default",
        description="tracker backend: default (telemetry-guided "
        "template matching), kcf, csrt; mil (the paper's, never reports a loss: "
        "refused with --gps-input)",
    )
    uuv_max_speed_mps: Annotated[Number, Gt(0)] = Field(
        MAX_SPEED_MPS["bluerov2"],
        description="safety gate: the "
        "UUV's top speed (a BlueROV2): fixes are judged against a track "
        "of the UUV that cannot move faster",
    )
    uuv_max_accel_mps2: Annotated[Number, Gt(0)] = Field(
        MAX_ACCEL_MPS2["bluerov2"],
        description="safety gate: the "
        "UUV's largest horizontal acceleration (a BlueROV2 at full "
        "thrust from rest, about 3 m/s²): a fix the track's UUV "
        "cannot reach is not sent",
    )
    uuv_water_accel_mps2: Annotated[Number, Ge(0)] = Field(
        WATER_ACCEL_MPS2,
        description="safety gate: the "
        "largest horizontal acceleration the water gives the UUV "
        "while ArduSub's horizontal thrusters are idle (read with "
        "depth_source blueos or mavlink); raise it in waves",
    )
    uuv_max_reach_m: Annotated[Number, Gt(0)] = Field(
        MAX_REACH_M,
        description="safety gate: however long since "
        "the last trusted fix (a loss, a restart, a selection), a new "
        "target further than this (m, and the fixes' shared error) "
        "from it is not the UUV until the operator confirms it",
    )
    thruster_deadband_us: within(0, 400) = Field(
        DEADBAND_US,
        description="pulses within this of 1500 µs do not "
        "turn the UUV's thrusters (its ESCs' deadband)",
    )
    fix_max_h_acc_m: Annotated[Number, Gt(0)] = Field(
        2.5,
        description="safety gate: a fix whose horizontal "
        "accuracy is worse than this (m) is not sent as valid",
    )
    uuv_prior_sigma_m: within(0.01, 1000) = Field(
        3.0, description="1-sigma (m) of the UUV's own estimate or hint (the search covers 3 sigma)"
    )
    select_history_s: within(0, 10) = Field(
        1.0,
        description="seconds of tracked frames held so a selection can "
        "refer to a frame the operator saw",
    )
    control_prefix: Text = Field(
        "skyfix/cmd",
        description="Zenoh key prefix of the operator commands "
        "(<prefix>/select, release, acquire, status)",
    )
    ui: Text = Field(
        "127.0.0.1:8080",
        description="HOST:PORT of the web page (video, target selection, map, "
        "health); beyond localhost (0.0.0.0:8080) it needs the token in the URL skyfix prints; port 0: "
        "any free port",
    )
    no_ui: Flag = Field(False, description="serve no web page")
    realtime_priority: Annotated[Whole, Ge(0), Le(99)] = Field(
        0,
        description="the service's threads under Linux's round-robin realtime policy (SCHED_RR) at this priority "
        "(1: the lowest; deploy/skyfix.service: 1), so a frame's work takes a core from the laptop's other programs "
        "at once; its background work (side jobs' processes, the page's encoder) stays out of it; 0: not "
        "realtime. Without the privilege (LimitRTPRIO in the unit, or root) one log line says so and it runs as "
        "before",
    )
    basemap: FilePath | None = Field(
        None,
        description="the web page's map drawn over a base map of the site, served by skyfix itself (no "
        "internet): a GeoTIFF (skyfix mosaic's mosaic.tif of an earlier flight, an orthophoto), an MBTiles "
        "file or a folder of Z/X/Y.png tiles (skyfix tiles)",
    )
    live_mosaic: Flag = Field(
        False,
        description="the web page's base map: a mosaic of the bottom growing live from the video (a frame every "
        "--live-mosaic-every-s, painted at a low priority, skipped when the painter is behind); needs "
        "--floor-depth-m; not with --basemap",
    )
    floor_depth_m: Positive | None = Field(
        None, description="the floor's depth below the water surface, m (for --live-mosaic)"
    )
    live_mosaic_every_s: Positive = Field(
        1.0, description="seconds of video between the frames the live mosaic paints"
    )
    reference: FilePath | None = Field(
        None,
        description="a reference of known position in view, as skyfix process's reference.toml: a surveyed marker "
        "(lat_deg, lon_deg, depth_m, sigma_m, radius_m) or a buoy reporting its GNSS as GPS_RAW_INT on the UAV's "
        "--mavlink link (system_id, optional component_id: no other system's reports are taken; depth_m, radius_m): "
        "looked for in a frame every --reference-every-s at a low priority, the drone's absolute offset it shows "
        "added to every fix (its sigma in h_acc) while it was seen in at least 4 of the last 10 s",
    )
    reference_every_s: Positive = Field(
        0.2,
        description="seconds of video between the frames the --reference marker is looked for in",
    )
    reference_zenoh_key: Text | None = Field(
        None,
        description="a --reference buoy's GPS_RAW_INT on Zenoh as BlueOS's mavlink-server publishes them, e.g. "
        "mavlink/*/*/GPS_RAW_INT (its JSON header's system and component: only the buoy's are taken, others "
        "refused and counted), besides those on --mavlink",
    )
    pose_from_bottom: Flag = Field(
        False,
        description="the drone's tilt and heading biases and its GNSS's walk estimated from the static bottom in the "
        "video (as skyfix process --pose-from-bottom auto, causally): a frame every --bottom-every-s tracked at a "
        "low priority, the estimate made again every 2 s of video from the last --bottom-window-s; each fix made "
        "again with it where its claim is smaller than the fix's own (the fix's pose_* fields say what was "
        "applied); needs --video",
    )
    bottom_every_s: Positive = Field(
        0.25,
        description="seconds of video between the frames --pose-from-bottom tracks the floor in",
    )
    bottom_window_s: Positive = Field(
        10.0,
        description="seconds of video --pose-from-bottom estimates from (the last ones); its estimate lapses two "
        "windows after its newest frame",
    )
    ui_token: Text | None = Field(
        None,
        description="the web page's token (default: none on localhost, a random one "
        "beyond it); given, every request needs it, on localhost too",
    )
    record: DirPath | None = Field(
        None,
        description="record the run as a session directory (format v1): a new or "
        "empty folder (a start into a recording is refused: see --recordings)",
    )
    recordings: DirPath | None = Field(
        None,
        description="record each start as a session directory of its own in "
        "this folder, named by the start's UTC time YYYYmmdd-HHMMSS (-2, -3, … when "
        "taken): a restart never overwrites nor refuses",
    )
    state_dir: DirPath | None = Field(
        None,
        description="folder where each UUV's last trusted track is kept for the "
        "next start (track-<id>.json; default: 'state' beside the --recordings folder, "
        "none without it)",
    )
    track_max_age_s: NonNegative = Field(
        300.0,
        description="a kept track older than this (s) is not read at the "
        "start: the gates start without the UUV's last track",
    )
    duration_s: NonNegative | None = Field(
        None, description="stop after this many seconds (tests, benchmarks)"
    )
    stats: FilePath | None = Field(
        None, description="write final counters and latency percentiles to this JSON file at exit"
    )
    uuv: tuple[UuvConfig, ...] = Field(
        (),
        description="several UUVs in one video, one [[uuv]] table each (config "
        "file only); the UUV's own options above are then set in each table",
    )

    @model_validator(mode="after")
    def _one_uuv_or_tables(self):
        if not self.uuv:
            return self
        single = {f: v for f, v in _uuv_defaults().items() if getattr(self, f) != v}
        if single:
            name = next(iter(single))
            raise Invalid(
                name,
                getattr(self, name),
                "set per UUV, in each [[uuv]] table, when there are several",
            )
        if self.recording:  # the first UUV's records are the session's own, named uuv1 when read
            for i, u in enumerate(self.uuv[1:], 1):
                if u.id == PRIMARY_UUV:
                    raise Invalid(
                        f"uuv[{i}].id",
                        u.id,
                        f"with --record, {PRIMARY_UUV} is the first [[uuv]]'s name "
                        "in the recording (its records are the session's own): give this UUV another id",
                    )
        for key in ("id", *OWN_KEYS):
            seen = {}
            for i, u in enumerate(self.uuv):
                value = getattr(u, key)
                if value is not None and value in seen:
                    raise Invalid(
                        f"uuv[{i}].{key}",
                        value,
                        f"also uuv[{seen[value]}]'s ({self.uuv[seen[value]].id}): "
                        "each UUV has its own",
                    )
                seen[value] = i
        return self

    @property
    def uuvs(self) -> tuple[UuvConfig, ...]:
        """The UUVs: the ``[[uuv]]`` tables, or the one UUV the flags describe (id ``uuv1``)."""
        if self.uuv:
            return self.uuv
        own = {f: getattr(self, f) for f in _uuv_defaults()}
        return (UuvConfig(id=PRIMARY_UUV, **own),)

    @property
    def zenoh_listen_endpoints(self) -> tuple[str, ...]:
        """The Zenoh endpoints the run listens on: those given, else (without a Zenoh configuration file, whose own
        apply) :data:`~groundstation.runtime.zenoh_session.LOCAL_ENDPOINT`, where the console commands look by default."""
        if self.zenoh_listen or self.zenoh_config:
            return self.zenoh_listen
        return (LOCAL_ENDPOINT,)

    @property
    def state_folder(self) -> Path | None:
        """Where the UUVs' tracks are kept: ``state_dir``, else ``state`` beside ``recordings``; None: not kept."""
        if self.state_dir:
            return Path(self.state_dir)
        return Path(self.recordings).parent / "state" if self.recordings else None

    @property
    def recording(self) -> str | None:
        """The option that records the run (``record`` or ``recordings``, its value); None without."""
        return self.record or self.recordings

    @model_validator(mode="after")
    def _live_mosaic_needs_a_floor(self):
        if self.live_mosaic and self.floor_depth_m is None:
            raise Invalid(
                "live_mosaic",
                True,
                "needs the floor's depth: --floor-depth-m M (m below the surface)",
            )
        if self.live_mosaic and self.basemap is not None:
            raise Invalid(
                "live_mosaic", True, f"--basemap {self.basemap} is given too: one base map"
            )
        return self

    @model_validator(mode="after")
    def _reference_readable(self):
        if self.reference is None and self.reference_zenoh_key is not None:
            raise Invalid(
                "reference_zenoh_key",
                self.reference_zenoh_key,
                "for a buoy's reports: no --reference",
            )
        if self.reference is not None:
            from groundstation.offline.reference import read_file
            from groundstation.session import SessionError

            path = Path(self.reference)
            if self.video is None:
                raise Invalid(
                    "reference", self.reference, "needs the video to find it in (--video)"
                )
            if not path.is_file():
                raise Invalid("reference", self.reference, "no such file")
            from groundstation.live.reference_live import component_id

            try:
                ref, _ = read_file(path)
                component_id(path)
            except SessionError as e:
                raise Invalid(
                    "reference", self.reference, str(e).removeprefix(f"{path}: ")
                ) from None
            except ValueError as e:
                raise Invalid("reference", self.reference, str(e)) from None
            if hasattr(ref, "lat_deg") and self.reference_zenoh_key is not None:
                raise Invalid(
                    "reference_zenoh_key",
                    self.reference_zenoh_key,
                    "for a buoy's reports: --reference names a surveyed marker",
                )
            if not hasattr(ref, "lat_deg") and self.mavlink_backend != "pymavlink":
                raise Invalid(
                    "reference",
                    self.reference,
                    "a buoy's reports are read with --mavlink-backend pymavlink",
                )
        return self

    @model_validator(mode="after")
    def _bottom_needs_video(self):
        if self.pose_from_bottom and self.video is None:
            raise Invalid(
                "pose_from_bottom", True, "needs the video to see the bottom in (--video)"
            )
        return self

    @model_validator(mode="after")
    def _record_needs_pymavlink(self):
        if self.record and self.recordings:
            raise Invalid(
                "recordings",
                self.recordings,
                f"--record {self.record} is given too: one or the other",
            )
        if self.recording and self.mavlink_backend == "mavsdk":
            key = "record" if self.record else "recordings"
            raise Invalid(key, self.recording, "recording needs --mavlink-backend pymavlink")
        return self

    @model_validator(mode="after")
    def _parts_installed(self):
        for kind, key in (
            ("uav", "mavlink_backend"),
            ("depth", "depth_source"),
            ("output", "outputs"),
        ):
            values = [getattr(o, key) for o in (self, *self.uuv) if hasattr(o, key)]
            for name in {n for v in values for n in (v if isinstance(v, tuple) else (v,))}:
                missing = registry.part(kind, name).missing()
                if missing:
                    raise Invalid(key, name, missing)
        return self

    @model_validator(mode="after")
    def _uav_link_locks(self):
        if self.mavlink_peer is not None:
            host, colon, port = self.mavlink_peer.rpartition(":")
            if not (
                self.mavlink.startswith(("udpin:", "udp:")) and self.mavlink_backend == "pymavlink"
            ):
                raise Invalid(
                    "mavlink_peer",
                    self.mavlink_peer,
                    f"for a udpin: link (mavlink is {self.mavlink!r})",
                )
            if self.mavlink_peer != ANY_PEER and not (
                host and colon and port.isdigit() and int(port) < 65536
            ):
                raise Invalid(
                    "mavlink_peer", self.mavlink_peer, f"expected HOST:PORT or {ANY_PEER}"
                )
        if self.mavlink_signing_key and self.mavlink_backend != "pymavlink":
            raise Invalid(
                "mavlink_signing_key",
                self.mavlink_signing_key,
                "signing needs --mavlink-backend pymavlink",
            )
        return self

    @model_validator(mode="after")
    def _gps_input_needs_a_tracker_that_reports_a_loss(self):
        if self.gps_input and self.tracker in WITHOUT_LOSS_SIGNAL:
            raise Invalid(
                "tracker",
                self.tracker,
                "this tracker never reports losing the UUV: not a source for "
                "GPS_INPUT (use default, kcf or csrt; mil is for offline comparisons)",
            )
        return self

    @model_validator(mode="after")
    def _ui_is_an_address(self):
        for key, check in (("ui", parse_bind), ("ui_token", check_token)):
            value = getattr(self, key)
            if value is not None:
                try:
                    check(value)
                except ValueError as e:
                    raise Invalid(key, value, str(e)) from None
        return self


def _uuv_defaults() -> dict:
    """The top-level options a UUV of its own has, with their defaults."""
    fields = RunConfig.__pydantic_fields__
    return {
        name: fields[name].get_default(call_default_factory=True)
        for name in (
            *UuvOptions.__pydantic_fields__,
            "fix_key",
            "status_key",
            "alive_key",
            "control_prefix",
        )
    }


def _base(tp):
    """``(kind, choices)`` of a field type: kind is bool, int, float, str or tuple."""
    if get_origin(tp) is Annotated:
        return _base(get_args(tp)[0])
    if get_origin(tp) is Literal:
        return str, get_args(tp)
    if get_origin(tp) is tuple:
        return tuple, None
    args = [a for a in get_args(tp) if a is not type(None)]
    if args:  # X | None
        return _base(args[0])
    return tp, None


def _path_marker(name: str) -> _RelativeToFile | None:
    """The path marker of a field (FilePath, DirPath, or either | None), None for other fields."""
    info = RunConfig.__pydantic_fields__[name]
    metadata = [
        *info.metadata,
        *(m for a in get_args(info.annotation) for m in getattr(a, "__metadata__", ())),
    ]
    return next((m for m in metadata if isinstance(m, _RelativeToFile)), None)


METAVARS = {
    "ui": "HOST:PORT",
    "ui_token": "TOKEN",
    "outputs": "NAME",
}  # options whose value is neither a path, a key nor a URL


def _metavar(name: str, kind) -> str:
    marker = _path_marker(name)
    if marker:
        return marker.metavar
    if name in METAVARS:
        return METAVARS[name]
    if kind is not str:
        return name.rsplit("_", 1)[-1].upper()  # MS, HZ, S: the unit
    return "KEY" if name.endswith("_key") else "URL"


def _admits_auto(tp) -> bool:
    """Whether a field type takes the word "auto" beside a number."""
    return any(get_origin(a) is Literal and "auto" in get_args(a) for a in get_args(tp))


def _number_or_auto(text: str) -> float | str:
    if text == "auto":
        return text
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is neither a number nor auto") from None


def flag(name: str) -> str:
    return "--" + name.replace("_", "-")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``--config`` and one flag per :class:`RunConfig` field (argparse default None: not given)."""
    required = parser.add_argument_group("required (a flag, or a key in the --config file)")
    options = parser.add_argument_group(
        "optional (a flag wins over the same key in the --config file)"
    )
    options.add_argument(
        "--config",
        metavar="FILE",
        help="TOML file of run options, keys as the flags' names with "
        "underscores (deploy/field.toml); a part's settings in its table [parts.NAME]",
    )
    for name, info in RunConfig.__pydantic_fields__.items():
        if name in FILE_ONLY:
            continue
        kind, choices = _base(info.annotation)
        text = info.description
        if not info.is_required() and info.default not in (None, False, ()):
            text += f" (default: {info.default})"
        kw = {"help": text, "default": None, "dest": name}
        group = required if info.is_required() else options
        if kind is bool:
            group.add_argument(flag(name), action="store_true", **kw)
        elif _admits_auto(info.annotation):
            group.add_argument(flag(name), type=_number_or_auto, metavar="MS|auto", **kw)
        elif kind is tuple:
            group.add_argument(
                flag(name), action="append", metavar=METAVARS.get(name, "ENDPOINT"), **kw
            )
        elif choices:
            group.add_argument(flag(name), choices=choices, **kw)
        else:
            group.add_argument(flag(name), type=kind, metavar=_metavar(name, kind), **kw)


def read_config_file(path: str) -> dict:
    """The options a config TOML sets (checked in :func:`run_config`), relative paths resolved against its folder."""
    data = read_toml(path)
    tables = data.get("uuv") if isinstance(data.get("uuv"), list) else []
    for table in [data, *(t for t in tables if isinstance(t, dict))]:
        for key, value in table.items():
            if (
                key in RunConfig.__pydantic_fields__
                and _path_marker(key)
                and isinstance(value, str)
                and not Path(value).is_absolute()
            ):
                table[key] = str(Path(path).parent / value)
    return data


def _given(args: argparse.Namespace) -> tuple[dict, dict]:
    """The options the config file sets and the flags given."""
    file_values = read_config_file(args.config) if getattr(args, "config", None) else {}
    flags = {}
    for name in RunConfig.__pydantic_fields__:
        given = getattr(args, name, None)
        if given is not None and given is not False:
            flags[name] = tuple(given) if isinstance(given, list) else given
    return file_values, flags


def unnamed_inputs(args: argparse.Namespace) -> None:
    """:class:`ConfigError` for the first of :data:`NAMED_INPUTS` neither the flags nor the config file name (in
    each ``[[uuv]]`` table for ``gps_input`` when there are tables): a run without video or GPS_INPUT must say so
    (``none``), never by forgetting it."""
    file_values, flags = _given(args)
    given = {**file_values, **flags}
    tables = given.get("uuv") if isinstance(given.get("uuv"), list) else []
    for name in NAMED_INPUTS:
        where = (
            [(f"uuv[{i}].{name}", t) for i, t in enumerate(tables) if isinstance(t, dict)]
            if tables and name in UuvOptions.__pydantic_fields__
            else [(flag(name), given)]
        )
        for key, values in where:
            if values.get(name) is None:
                source = args.config if tables and key.startswith("uuv[") else "options"
                raise ConfigError(
                    source,
                    key,
                    None,
                    f"missing: name it, or say {NONE} ({flag(name)} {NONE}, or "
                    f'{name} = "{NONE}" in the config file)',
                )


def run_config(args: argparse.Namespace) -> RunConfig:
    """Defaults, then the config file, then the flags given; a bad value names where it came from."""
    file_values, flags = _given(args)
    try:
        return validate(RunConfig, {**file_values, **flags}, "options")
    except ConfigError as e:
        top = e.key.split(".")[0].split("[")[0]
        if top in file_values and top not in flags or top in FILE_ONLY and args.config:
            raise ConfigError(args.config, e.key, e.value, e.why) from None
        if top in FILE_ONLY:  # a part chosen by a flag: its settings are its table's
            raise ConfigError("options", e.key, e.value, e.why) from None
        why = "required (a flag or the --config file)" if e.why == "missing" else e.why
        raise ConfigError(
            "options", flag(top) if top in RunConfig.__pydantic_fields__ else e.key, e.value, why
        ) from None

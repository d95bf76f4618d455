"""The calibration: ``[camera]``, ``[mount]``, ``[water]``, ``[tracker]`` of session.toml v1, and
skyfix's own ``[uncertainty]`` (:class:`Sigmas`), ``[timing]`` (:class:`Timing`) and ``[uuv]`` (:class:`Uuv`).

One contract (see :mod:`localizer.contract`): these classes validate the parsed TOML,
hold the defaults and document every key; ``groundstation/schemas/calibration.schema.json``
is generated from them. Unknown keys in the spec's tables are warnings (other tools may
add keys; a typo must not pass unnoticed), in skyfix's own tables errors.
"""

from __future__ import annotations

import dataclasses
from typing import Literal

from pydantic import ConfigDict, Field, field_validator, model_validator
from pydantic.dataclasses import dataclass
from pydantic.json_schema import SkipJsonSchema

from .camera import Camera
from .contract import (
    CLOSED,
    OPEN,
    ConfigError,
    Invalid,
    NonNegative,
    Number,
    Positive,
    Vector3,
    Vector4,
    unknown_keys,
    validate,
    within,
)

__all__ = ["Calibration", "ConfigError", "Mount", "Sigmas", "Timing", "Tracker", "Uuv", "Water"]

AttitudeSource = Literal["gimbal_device", "mount_orientation", "fixed"]
RollPitchReference = Literal["auto", "horizon", "body"]


@dataclass(frozen=True, config=OPEN)
class Mount:
    """``[mount]``: where the camera's attitude comes from and where the camera sits."""

    attitude_source: AttitudeSource = Field(
        "gimbal_device",
        description="GIMBAL_DEVICE_ATTITUDE_STATUS, MOUNT_ORIENTATION, or a camera fixed to the airframe",
    )
    fixed_rpy_deg: Vector3 = Field(
        (0.0, -90.0, 0.0),
        description="fixed: the camera's roll, pitch, yaw relative to the body FRD, degrees",
    )
    camera_offset_m: Vector3 = Field(
        (0.0, 0.0, 0.0),
        description="camera in the UAV body frame (FRD, metres) from the point GLOBAL_POSITION_INT reports",
    )
    gimbal_roll_pitch: RollPitchReference = Field(
        "auto",
        description="what the gimbal message's roll and pitch are relative to: 'horizon' (the MAVLink rule), "
        "'body' (ArduPilot's servo mount, MNT1_TYPE 1, reports its servo demands), 'auto': body when the autopilot "
        "says MNT1_TYPE = 1, else horizon",
    )


@dataclass(
    frozen=True,
    config=ConfigDict(
        **OPEN,
        json_schema_extra={
            "oneOf": [
                {"required": ["takeoff_height_above_surface_m"]},
                {"required": ["surface_amsl_m"]},
            ]
        },
    ),
)
class Water:
    """``[water]``: the water surface, by exactly one of two references, and its refractive index."""

    takeoff_height_above_surface_m: within(-1000, 1000) | None = Field(
        None,
        description="the take-off point's height above the water (relative_alt + this = height above water)",
    )
    surface_amsl_m: within(-500, 9000) | None = Field(
        None,
        description="the water surface's altitude above mean sea level (alt - this = height above water)",
    )
    refractive_index: within(1.0, 2.0) = Field(1.34, description="of the water (sea water 1.34)")

    @model_validator(mode="after")
    def _one_reference(self):
        given = [
            k
            for k in ("takeoff_height_above_surface_m", "surface_amsl_m")
            if getattr(self, k) is not None
        ]
        if len(given) != 1:
            raise Invalid(
                "", given, "set exactly one of takeoff_height_above_surface_m and surface_amsl_m"
            )
        return self


@dataclass(frozen=True, config=OPEN)
class Tracker:
    """``[tracker]``: the UUV in the first processed frame."""

    init_bbox: Vector4 | None = Field(
        None, description="x, y, w, h in pixels of the UUV in the first processed frame"
    )
    init_t: Number | None = Field(
        None, description="the UNIX time of the frame init_bbox belongs to (recorded sessions)"
    )

    @field_validator("init_bbox")
    @classmethod
    def _whole_pixels(cls, box):
        return None if box is None else tuple(round(x) for x in box)


@dataclass(frozen=True, config=CLOSED)
class Sigmas:
    """``[uncertainty]``: 1-sigma uncertainties propagated into each fix's accuracy.

    Larger values make the UUV's filter trust the fix less; too small ones make it
    overconfident, which is worse. Defaults suit a hovering multirotor with a
    stabilised gimbal and a barometric altitude reference.
    """

    pixel_px: NonNegative = Field(
        2.0,
        description="tracker error in the image: a template tracker on a vehicle 30-100 px long",
    )
    tilt_deg: NonNegative = Field(
        0.5,
        description="camera roll/pitch, each axis: mostly a bias that does not average "
        "out over a flight, a stabilised gimbal's levelling error (its own IMU), or with a "
        "servo mount or a fixed camera the AHRS's tilt (0.2-0.4 typical), with their wander",
    )
    yaw_deg: NonNegative = Field(
        1.5,
        description="camera heading: the compass's bias (1-2.5 typical; a calibrated "
        "compass away from magnetic interference), which a gimbal's heading carries too",
    )
    height_m: NonNegative = Field(
        0.3,
        description="the EKF's height above the water when its reference was set: "
        "the take-off height's measurement (at arming), or in the amsl reference the EKF "
        "origin's altitude (at boot); it then drifts (baro_drift_10min_m) unless GNSS, a "
        "rangefinder or the UUV's size measure it",
    )
    baro_drift_10min_m: NonNegative = Field(
        0.7,
        description="1-sigma of the barometric height's drift 10 minutes after that reference: a drift at a rate "
        "that wanders over about 10 minutes (in proportion to time at first, with its square root later), the "
        "weather's pressure tendency, 'falling slowly' being up to 1.5 hPa in 3 h, at 8.3 m per hPa near sea level",
    )
    baro_wander_m: NonNegative = Field(
        0.15,
        description="the share of height_m (at most all of it) that wanders back and forth over tens of seconds, "
        "as large at any time: the prop wash, gusts and the air's temperature in the barometer's pressure "
        "(0.1-0.2 typical hovering); GNSS altitudes that can see it follow it over seconds in proportion to their "
        "accuracy; where they show none (an RTK receiver beside a steady barometer) or cannot see it, it is held "
        "(localizer/height.py)",
    )
    baro_wander_s: Positive = Field(
        30.0, description="its correlation time (a first-order Gauss-Markov process)"
    )
    depth_m: NonNegative = Field(
        0.05, description="UUV depth: a pressure sensor with the surface pressure zeroed"
    )
    uav_horizontal_m: NonNegative | None = Field(
        None,
        description="the UAV position's own horizontal accuracy (m, DRMS): the EKF's, e.g. measured hovering "
        "over a surveyed point; unset: GPS_RAW_INT's h_acc (the receiver's own estimate), else its HDOP times its "
        "fix type's typical error, with an RTK fix the EKF's own few centimetres added (localizer/gnss.py), or 1.5 "
        "(plain GNSS) without GPS_RAW_INT",
    )
    time_s: NonNegative = Field(
        0.02,
        description="frames vs telemetry time alignment, turned into metres by the camera's motion",
    )
    surface_amsl_m: NonNegative = Field(
        0.5,
        description="the water surface's altitude reference: the vertical "
        "accuracy, and with [water] surface_amsl_m the height's from GNSS altitudes",
    )
    wind_mps: NonNegative = Field(
        0.0,
        description="the wind over the water (m/s, 10 m up): its waves' slopes (Cox and Munk) bend each ray, "
        "a jitter of about depth x (1 - 1/n) x slope per axis, from the share of the slopes' variance in waves long "
        "enough to move the UUV's whole image (localizer/uncertainty.py); from 2 up the tracker also seeks a lost UUV "
        "by its colour from the first frame (localizer/tracking/session.py); 0: a still surface",
    )


#: The UAV's horizontal accuracy (m, 1-sigma) assumed when neither the calibration nor a GPS_RAW_INT gives it.
UAV_HORIZONTAL_FALLBACK_M = 1.5


@dataclass(frozen=True, config=CLOSED)
class Timing:
    """``[timing]``: time alignment and staleness limits (seconds).

    ``*_gap_s``: the longest interval between two samples that is interpolated;
    ``*_hold_s``: how long after the newest sample it is extrapolated (ATTITUDE with
    its rates, positions with their velocities) or held (the rest), with the fix's
    accuracy grown by the estimated error. Beyond them a frame gets "no fix".
    """

    attitude_gap_s: Positive = Field(
        0.6,
        description="longest ATTITUDE interval interpolated (cubic with the body "
        "rates: still sub-0.1 deg at 4 Hz on a wobbling airframe)",
    )
    attitude_hold_s: Positive = Field(
        0.15, description="ATTITUDE extrapolated this long past the newest sample"
    )
    position_gap_s: Positive = Field(
        1.0, description="longest GLOBAL_POSITION_INT interval interpolated"
    )
    position_hold_s: Positive = Field(
        0.5, description="position extrapolated this long with its velocity"
    )
    gimbal_gap_s: Positive = Field(0.5, description="longest gimbal message interval interpolated")
    gimbal_hold_s: Positive = Field(
        0.3, description="gimbal attitude held this long past the newest sample"
    )
    depth_gap_s: Positive = Field(2.0, description="longest depth interval interpolated")
    depth_hold_s: Positive = Field(1.0, description="depth held this long past the newest sample")
    mavlink_latency_s: NonNegative | None = Field(
        None,
        description="the UAV link's one-way delay; unset: measured with MAVLink TIMESYNC, else estimated from "
        "the video's motion (skyfix process), else unknown: taken as 0 ± unknown_latency_sigma_s",
    )
    unknown_latency_sigma_s: NonNegative = Field(
        0.05,
        description="1-sigma of the UAV link's delay while it is unknown (neither stated, measured nor "
        "estimated), added to [uncertainty] time_s: a telemetry radio's delay is some tens of ms, a wired or WiFi "
        "link's a few",
    )
    depth_latency_s: NonNegative = Field(
        0.05,
        description="the UUV's depth, measurement to arrival, used when its "
        "clock disagrees with the station's",
    )
    depth_clock_tolerance_s: Positive = Field(
        0.1, description="a UUV clock this close to the station's is trusted as it is"
    )
    clock_window_s: Positive = Field(
        30.0, description="sliding window of the least-delay clock alignment"
    )
    # written by `skyfix run --record` (what the live run measured and used), read as a record: processing
    # measures the link delay again from the tlog's TIMESYNC; video_frames.csv's times hold the latency, except
    # those stamped before video_latency_from_t (auto, not yet settled), which reading moves back by video_latency_s
    mavlink_latency_measured_s: NonNegative | None = Field(
        None,
        description="recorded: the UAV link's one-way delay TIMESYNC measured in the live run (the last value)",
    )
    mavlink_latency_measured_from_t: Number | None = Field(
        None,
        description="recorded: station time (UNIX s) of the live run's first TIMESYNC measurement; the fixes "
        "before it had the link delay unknown (unless mavlink_latency_s was set)",
    )
    video_latency_s: Number | None = Field(
        None,
        description="recorded: the video's glass-to-first-packet latency in use (video_frames.csv's t = the "
        "frame's stream slot minus it)",
    )
    video_latency_source: Literal["configured", "motion"] | None = Field(
        None,
        description="recorded: configured (--video-latency-ms) or motion (auto: estimated from the image's "
        "motion against the camera attitude)",
    )
    video_latency_sigma_s: NonNegative | None = Field(
        None, description="recorded: the motion estimate's 1-sigma (video_latency_source = motion)"
    )
    video_latency_from_t: Number | None = Field(
        None,
        description="recorded, auto: station time (UNIX s) of the first frame stamped with the estimate; the "
        "frames before it are stamped with 0 latency and had no valid fix (status latency_unsettled)",
    )


@dataclass(frozen=True, config=CLOSED)
class Uuv:
    """``[uuv]``: the vehicle, as a box around its hull (defaults: a BlueROV2's frame, metres).

    Its size against its size in the image gives the camera's range, so the camera's height
    above the water (:mod:`localizer.size_range`). Measure your vehicle with what it carries:
    a 1 % error in its size is a 1 % error in that height.
    """

    length_m: within(0.05, 20.0) = Field(0.457, description="bow to stern")
    width_m: within(0.05, 20.0) = Field(0.338, description="side to side")
    height_m: within(0.02, 20.0) = Field(
        0.254,
        description="top to bottom (the depth's reference point is the centre of its top face)",
    )


@dataclass(frozen=True, config=ConfigDict(**OPEN, validate_by_name=True))
class Calibration:
    """The calibration tables of session.toml v1 (a session, or a ``--calibration`` file).

    Read as ``cal.camera`` (a :class:`~localizer.camera.Camera`), ``cal.mount``,
    ``cal.water``, ``cal.init_bbox``/``cal.init_t`` (``[tracker]``), ``cal.sigmas``
    (``[uncertainty]``), ``cal.timing``, ``cal.uuv``; ``cal.warnings`` lists the unknown keys.
    """

    camera: Camera = Field(description="pinhole + OpenCV radial-tangential distortion")
    mount: Mount = Field(description="the camera's attitude source and position on the UAV")
    water: Water = Field(description="the water surface reference")
    tracker: Tracker = Field(default_factory=Tracker, description="the UUV in the first frame")
    sigmas: Sigmas = Field(
        default_factory=Sigmas,
        alias="uncertainty",
        description="1-sigma inputs of each fix's accuracy (skyfix's own table)",
    )
    timing: Timing = Field(
        default_factory=Timing,
        description="time alignment and staleness limits (skyfix's own table)",
    )
    uuv: Uuv = Field(default_factory=Uuv, description="the vehicle's size (skyfix's own table)")
    version: Literal[1] | None = Field(
        None, description="session format version (session.toml; absent in a calibration-only file)"
    )
    warnings: SkipJsonSchema[tuple[str, ...]] = dataclasses.field(
        default=(), init=False, compare=False
    )

    @property
    def init_bbox(self) -> tuple[int, int, int, int] | None:
        return self.tracker.init_bbox

    @property
    def init_t(self) -> float | None:
        return self.tracker.init_t

    @model_validator(mode="after")
    def _box_inside_image(self):
        box, cam = self.tracker.init_bbox, self.camera
        if box is not None:
            x, y, w, h = box
            if w < 2 or h < 2 or x < 0 or y < 0 or x + w > cam.width or y + h > cam.height:
                raise Invalid(
                    "tracker.init_bbox",
                    list(box),
                    f"box must lie inside the {cam.width}x{cam.height} image",
                )
        return self

    @classmethod
    def from_dict(cls, data: dict, source: str = "session.toml") -> Calibration:
        """Validate parsed TOML; unknown keys of the spec's tables (and unknown tables) become ``warnings``."""
        cal = validate(cls, data, source)
        warnings = tuple(
            f"{source}: {key} is not a key skyfix knows; ignored (a typo?)"
            for key in unknown_keys(cls, data)
        )
        object.__setattr__(cal, "warnings", warnings)
        return cal

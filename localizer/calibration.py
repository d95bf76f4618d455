"""The calibration: ``[camera]``, ``[mount]``, ``[water]``, ``[tracker]`` of session.toml v1, validated.

Input is the already-parsed TOML (a dict); every problem raises :class:`ConfigError`
naming the file, the key and the offending value. skyfix's own optional tables:

``[uncertainty]`` 1-sigma inputs to the accuracy estimate (see :class:`Sigmas`);
``[timing]`` staleness limits for telemetry (see :class:`Timing`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

from .camera import Camera

ATTITUDE_SOURCES = ("gimbal_device", "mount_orientation", "fixed")
ROLL_PITCH_REFERENCES = ("auto", "horizon", "body")
_KNOWN_KEYS = {
    "camera": {"width", "height", "fx", "fy", "cx", "cy", "distortion"},
    "mount": {"attitude_source", "fixed_rpy_deg", "camera_offset_m", "gimbal_roll_pitch"},
    "water": {"takeoff_height_above_surface_m", "surface_amsl_m", "refractive_index"},
    "tracker": {"init_bbox", "init_t"},
}


class ConfigError(ValueError):
    """A bad calibration or session value; the message is one line naming file, key and value."""

    def __init__(self, source: str, key: str, value, why: str):
        self.source, self.key, self.value, self.why = source, key, value, why
        super().__init__(f"{source}: {key} = {value!r}: {why}")


@dataclass(frozen=True)
class Mount:
    attitude_source: str = "gimbal_device"
    fixed_rpy_deg: tuple[float, float, float] = (0.0, -90.0, 0.0)
    camera_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)  # body FRD, metres
    # what the gimbal message's roll and pitch are relative to: "horizon" (the MAVLink rule),
    # "body" (ArduPilot's servo mount, MNT1_TYPE 1, reports its servo demands), or "auto":
    # "body" when the autopilot says MNT1_TYPE = 1, else "horizon"
    gimbal_roll_pitch: str = "auto"


@dataclass(frozen=True)
class Water:
    takeoff_height_above_surface_m: float | None = None
    surface_amsl_m: float | None = None
    refractive_index: float = 1.34


@dataclass(frozen=True)
class Sigmas:
    """1-sigma uncertainties propagated into each fix's accuracy.

    Larger values make the UUV's filter trust the fix less; too small ones make it
    overconfident, which is worse. Defaults suit a hovering multirotor with a
    stabilised gimbal and a barometric altitude reference.
    """

    pixel_px: float = 2.0  # tracker error in the image: a template tracker on a vehicle 30-100 px long
    tilt_deg: float = 0.5  # camera roll/pitch: a consumer gimbal's IMU with the autopilot's AHRS
    yaw_deg: float = 1.5  # camera heading: a calibrated compass away from magnetic interference
    height_m: float = 0.3  # camera height above the water: barometric altitude over a few minutes
    depth_m: float = 0.05  # UUV depth: a pressure sensor (Bar30) with the surface pressure zeroed
    # the UAV position's own horizontal accuracy (m): None takes GPS_RAW_INT's h_acc, the
    # receiver's own estimate, or UAV_HORIZONTAL_FALLBACK_M (plain GNSS) when it sends none
    uav_horizontal_m: float | None = None
    time_s: float = 0.02  # frames vs telemetry time alignment (video latency and link delay not measured better)
    surface_amsl_m: float = 0.5  # the water surface's altitude reference, for the vertical accuracy


#: The UAV's horizontal accuracy (m, 1-sigma) assumed when neither the calibration nor GPS_RAW_INT gives it.
UAV_HORIZONTAL_FALLBACK_M = 1.5


@dataclass(frozen=True)
class Timing:
    """Time alignment and staleness limits (seconds).

    ``*_gap_s``: the longest interval between two samples that is interpolated;
    ``*_hold_s``: how long after the newest sample it is extrapolated (ATTITUDE with
    its rates, positions with their velocities) or held (the rest), with the fix's
    accuracy grown by the estimated error. Beyond them a frame gets "no fix".
    """

    attitude_gap_s: float = 0.6  # cubic with the body rates: still sub-0.1 deg at 4 Hz on a wobbling airframe
    attitude_hold_s: float = 0.15
    position_gap_s: float = 1.0
    position_hold_s: float = 0.5
    gimbal_gap_s: float = 0.5
    gimbal_hold_s: float = 0.3
    depth_gap_s: float = 2.0
    depth_hold_s: float = 1.0
    # the UAV link's one-way delay; None: measured with MAVLink TIMESYNC, 0 until it is
    mavlink_latency_s: float | None = None
    depth_latency_s: float = 0.05  # the UUV's depth, measurement to arrival, used when its clock disagrees
    depth_clock_tolerance_s: float = 0.1  # a UUV clock this close to the station's is trusted as it is
    clock_window_s: float = 30.0  # sliding window of the least-delay clock alignment


@dataclass(frozen=True)
class Calibration:
    camera: Camera
    mount: Mount
    water: Water
    init_bbox: tuple[int, int, int, int] | None = None
    init_t: float | None = None
    sigmas: Sigmas = field(default_factory=Sigmas)
    timing: Timing = field(default_factory=Timing)
    warnings: tuple[str, ...] = ()  # keys this version does not know (other tools may add keys)


def _number(source, key, value, *, positive=False, nonneg=False, lo=None, hi=None):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(source, key, value, "expected a number")
    if not math.isfinite(value):
        raise ConfigError(source, key, value, "must be finite")
    if positive and value <= 0:
        raise ConfigError(source, key, value, "must be > 0")
    if nonneg and value < 0:
        raise ConfigError(source, key, value, "must be ≥ 0")
    if lo is not None and value < lo or hi is not None and value > hi:
        raise ConfigError(source, key, value, f"must be within [{lo}, {hi}]")
    return float(value)


def _vector(source, key, value, n):
    if not isinstance(value, (list, tuple)) or len(value) != n:
        raise ConfigError(source, key, value, f"expected a list of {n} numbers")
    return tuple(_number(source, f"{key}[{i}]", v) for i, v in enumerate(value))


def _table(source, data, name, required=True):
    t = data.get(name)
    if t is None:
        if required:
            raise ConfigError(source, f"[{name}]", None, "table missing")
        return {}
    if not isinstance(t, dict):
        raise ConfigError(source, f"[{name}]", t, "expected a table")
    return t


def _dataclass_from(cls, source, prefix, table, check):
    kwargs = {}
    names = {f.name for f in fields(cls)}
    for key, value in table.items():
        if key not in names:
            raise ConfigError(source, f"{prefix}.{key}", value, f"unknown key (known: {', '.join(sorted(names))})")
        kwargs[key] = check(source, f"{prefix}.{key}", value)
    return cls(**kwargs)


def calibration_from_dict(data: dict, source: str = "session.toml") -> Calibration:
    """Validate the parsed TOML and build a :class:`Calibration`."""
    cam = _table(source, data, "camera")
    for key in ("width", "height", "fx", "fy", "cx", "cy"):
        if key not in cam:
            raise ConfigError(source, f"camera.{key}", None, "missing")
    width, height = cam["width"], cam["height"]
    for key, value in (("width", width), ("height", height)):
        if isinstance(value, bool) or not isinstance(value, int) or not 16 <= value <= 16384:
            raise ConfigError(source, f"camera.{key}", value, "expected a whole number of pixels in [16, 16384]")
    distortion = _vector(source, "camera.distortion", cam.get("distortion", [0, 0, 0, 0, 0]), 5)
    camera = Camera(
        width=width,
        height=height,
        fx=_number(source, "camera.fx", cam["fx"], positive=True),
        fy=_number(source, "camera.fy", cam["fy"], positive=True),
        cx=_number(source, "camera.cx", cam["cx"], lo=-0.5, hi=width - 0.5),
        cy=_number(source, "camera.cy", cam["cy"], lo=-0.5, hi=height - 0.5),
        distortion=distortion,
    )

    mt = _table(source, data, "mount")
    att = mt.get("attitude_source", "gimbal_device")
    if att not in ATTITUDE_SOURCES:
        raise ConfigError(source, "mount.attitude_source", att, f"expected one of {', '.join(ATTITUDE_SOURCES)}")
    roll_pitch = mt.get("gimbal_roll_pitch", "auto")
    if roll_pitch not in ROLL_PITCH_REFERENCES:
        raise ConfigError(source, "mount.gimbal_roll_pitch", roll_pitch,
                          f"expected one of {', '.join(ROLL_PITCH_REFERENCES)}")
    mount = Mount(
        attitude_source=att,
        fixed_rpy_deg=_vector(source, "mount.fixed_rpy_deg", mt.get("fixed_rpy_deg", [0.0, -90.0, 0.0]), 3),
        camera_offset_m=_vector(source, "mount.camera_offset_m", mt.get("camera_offset_m", [0.0, 0.0, 0.0]), 3),
        gimbal_roll_pitch=roll_pitch,
    )

    wt = _table(source, data, "water")
    has_takeoff = "takeoff_height_above_surface_m" in wt
    has_amsl = "surface_amsl_m" in wt
    if has_takeoff == has_amsl:
        raise ConfigError(
            source, "water", sorted(k for k in wt if k != "refractive_index"),
            "set exactly one of takeoff_height_above_surface_m and surface_amsl_m",
        )
    water = Water(
        takeoff_height_above_surface_m=(
            _number(source, "water.takeoff_height_above_surface_m", wt["takeoff_height_above_surface_m"], lo=-1000, hi=1000)
            if has_takeoff else None
        ),
        surface_amsl_m=_number(source, "water.surface_amsl_m", wt["surface_amsl_m"], lo=-500, hi=9000) if has_amsl else None,
        refractive_index=_number(source, "water.refractive_index", wt.get("refractive_index", 1.34), lo=1.0, hi=2.0),
    )

    tr = _table(source, data, "tracker", required=False)
    init_bbox = None
    if "init_bbox" in tr:
        box = tr["init_bbox"]
        x, y, w, h = _vector(source, "tracker.init_bbox", box, 4)
        if w < 2 or h < 2 or x < 0 or y < 0 or x + w > width or y + h > height:
            raise ConfigError(source, "tracker.init_bbox", box, f"box must lie inside the {width}x{height} image")
        init_bbox = (round(x), round(y), round(w), round(h))
    init_t = _number(source, "tracker.init_t", tr["init_t"]) if "init_t" in tr else None

    sigmas = _dataclass_from(
        Sigmas, source, "uncertainty", _table(source, data, "uncertainty", required=False),
        lambda s, k, v: _number(s, k, v, nonneg=True),
    )
    timing = _dataclass_from(
        Timing, source, "timing", _table(source, data, "timing", required=False),
        lambda s, k, v: _number(s, k, v, nonneg=True) if "latency" in k else _number(s, k, v, positive=True),
    )
    warnings = tuple(
        f"{source}: {name}.{key} is not a key skyfix knows; ignored (a typo?)"
        for name, known in _KNOWN_KEYS.items()
        for key in _table(source, data, name, required=False)
        if key not in known
    )
    return Calibration(camera, mount, water, init_bbox, init_t, sigmas, timing, warnings)

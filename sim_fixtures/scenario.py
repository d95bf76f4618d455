"""A synthetic scenario: what the generator is asked to simulate, read from a small TOML file.

Every table and key is optional except ``name``; unknown keys and wrong types are
refused with a one-line :class:`~localizer.calibration.ConfigError` naming the
file, key and value. Units are in the key names (``_m``, ``_deg``, ``_s``, ``_hz``).
World frame: local North-East-Down with its origin on the water surface at
``[site] lat_deg, lon_deg``; the water surface is the plane ``down = 0``.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field, fields, replace
from itertools import pairwise
from pathlib import Path

from localizer.calibration import ConfigError


@dataclass(frozen=True)
class Site:
    lat_deg: float = 63.4400  # origin of the world frame, on the water surface
    lon_deg: float = 10.4000
    surface_amsl_m: float = 0.40  # the water surface's altitude above mean sea level
    water_reference: str = "takeoff"  # session.toml [water] key written: "takeoff" or "amsl"
    takeoff_height_above_surface_m: float = 1.80  # the take-off point above the water
    refractive_index: float = 1.34
    floor_depth_m: float = 4.0  # flat seafloor below the surface
    geoid_separation_m: float = 40.0  # WGS84 ellipsoid height of mean sea level (GPS_RAW_INT alt_ellipsoid)
    attenuation_bgr_per_m: tuple = (0.05, 0.08, 0.22)  # light attenuation coefficients (1/m)
    water_bgr: tuple = (120.0, 105.0, 50.0)  # colour of deep water (0-255)


@dataclass(frozen=True)
class CameraSpec:
    width: int = 640
    height: int = 360
    hfov_deg: float = 62.0  # horizontal field of view of the undistorted pinhole (fx = fy)
    distortion: tuple = (-0.12, 0.08, 0.0004, -0.0002, -0.01)  # k1, k2, p1, p2, k3


@dataclass(frozen=True)
class MountSpec:
    attitude_source: str = "gimbal_device"  # "gimbal_device", "mount_orientation" or "fixed"
    # "stabilised": the gimbal holds its attitude itself and reports it; "servo" (ArduPilot MNT1_TYPE 1):
    # the autopilot commands servo angles = target - the vehicle's lean and reports those demands
    kind: str = "stabilised"
    # gimbal_device yaw reported "earth" (flags 4|8|64 = 76) or "vehicle" (flags 4|8|32 = 44, as ArduPilot)
    gimbal_frame: str = "earth"
    pitch_deg: float = -90.0  # target pitch relative to the horizon (-90 = straight down)
    yaw_mode: str = "earth"  # yaw_deg held from North ("earth") or from the vehicle's heading ("vehicle", follow)
    yaw_deg: float = 0.0  # target yaw (degrees), from North or from the vehicle's heading as yaw_mode says
    jitter_deg: float = 0.05  # amplitude of the gimbal's residual wobble (0.4 and 0.7 Hz)
    fixed_rpy_deg: tuple = (0.0, -90.0, 0.0)  # "fixed": camera in the body FRD frame
    camera_offset_m: tuple = (0.10, 0.0, 0.20)  # camera in body FRD relative to the reported position


@dataclass(frozen=True)
class UavSpec:
    height_m: float = 10.0  # mean height of the reported position above the water
    height_swing_m: float = 0.3  # amplitude of slow height changes
    standoff: str = "auto"  # "auto": placed so the optical axis meets the UUV's path centre; "given"
    north_m: float = 0.0  # mean position when standoff = "given"
    east_m: float = 0.0
    drift_m: float = 0.4  # amplitude of the hover's horizontal drift
    yaw_deg: float = 20.0  # mean heading
    yaw_swing_deg: float = 10.0  # amplitude of the heading's sinusoidal changes
    yaw_period_s: float = 12.0
    tilt_deg: float = 4.0  # wind tilt: the airframe leans into the wind by this much
    wind_from_deg: float = 250.0
    gust_deg: float = 0.8  # amplitude of the tilt's oscillation
    wobble_deg: float = 0.0  # amplitude of an extra airframe roll and pitch oscillation (a camera fixed to it wobbles)
    wobble_hz: float = 0.0
    gnss_fix_type: int = 3  # GPS_RAW_INT fix_type (3 = 3D, 6 = RTK fixed)
    gnss_h_acc_m: float = 0.02  # GPS_RAW_INT h_acc (v_acc twice that); the simulated position itself is exact


@dataclass(frozen=True)
class UuvSpec:
    north_m: float = 0.0  # centre of the figure-eight path
    east_m: float = 0.0
    path_n_m: float = 0.8  # half extent of the path along North and East
    path_e_m: float = 0.6
    period_s: float = 24.0  # one loop of the figure eight
    depth_m: float = 1.0  # mean depth of the top face (the reference point)
    depth_swing_m: float = 0.25
    depth_period_s: float = 15.0
    # ((t_s, depth_m), ...) keyframes, times from the first frame and increasing: when given, the depth
    # follows them (cosine-eased in between, held outside) instead of depth_m ± depth_swing_m; a dive
    depth_profile: tuple = ()
    size_m: tuple = (0.46, 0.34, 0.25)  # length, width, height (BlueROV2)


@dataclass(frozen=True)
class LinkSpec:
    delay_s: float = 0.045  # telemetry link delay (sample to ground-station receipt)
    jitter_s: float = 0.012  # mean of the exponential extra delay; the link stays in order
    boot_s_at_start: float = 412.0  # autopilot uptime when the scenario starts
    depth_delay_s: float = 0.03  # UUV depth link: measurement to ground-station receipt
    depth_jitter_s: float = 0.005  # mean of its exponential extra delay; arrivals stay in order
    reboot_at_s: float | None = None  # the autopilot reboots at this scenario time (None: never)...
    reboot_down_s: float = 3.0  # ... is silent this long, then talks again with its boot clock restarted


@dataclass(frozen=True)
class ClockSpec:
    station_offset_s: float = 0.0  # ground station (laptop) clock minus true GNSS time: stamps frames, tlog, t_recv
    uuv_offset_s: float = 0.0  # the UUV's clock minus true time: stamps depth.jsonl's t
    video_time_error_s: float = 0.0  # video_frames.csv's times minus the frames' true exposures (a wrong latency)


@dataclass(frozen=True)
class TelemetrySpec:
    attitude_hz: float = 50.0
    position_hz: float = 10.0
    gimbal_hz: float = 20.0
    system_time_hz: float = 1.0  # 0: not sent
    gps_raw_hz: float = 5.0  # 0: not sent
    gps_raw_time: str = "unix"  # GPS_RAW_INT time_usec: true UNIX time ("unix") or boot time ("boot", as ArduPilot)
    timesync_hz: float = 1.0  # the ground station's TIMESYNC requests (each answered by the autopilot); 0: none
    depth_hz: float = 8.0
    lead_s: float = 2.0  # telemetry starts this long before the first frame
    attitude_noise_deg: float = 0.0  # 1-sigma white noise on reported roll, pitch, yaw
    height_noise_m: float = 0.0  # 1-sigma noise on reported altitudes
    depth_noise_m: float = 0.0  # 1-sigma noise on reported UUV depth


@dataclass(frozen=True)
class RenderSpec:
    exposure: float = 1.4  # sunlight just below the surface, relative to the albedo
    caustics: float = 0.5  # strength of the moving caustic pattern (0 = none)
    glint: float = 0.0  # strength of sun glint (0 = none)
    sun_azimuth_deg: float = 140.0
    sun_elevation_deg: float = 55.0
    noise_sigma: float = 2.0  # sensor noise, grey levels
    crf: int = 23  # x264 quality (lower is better)
    supersample: int = 2  # rays per pixel side on the UUV (anti-aliasing)


@dataclass(frozen=True)
class Scenario:
    name: str
    description: str = ""
    seed: int = 1
    duration_s: float = 8.0
    fps: float = 30.0
    start_unix: float = 1763800000.0
    occlusions: tuple = ()  # ((start_s, end_s), ...) relative to the first frame: the UUV is hidden
    site: Site = field(default_factory=Site)
    camera: CameraSpec = field(default_factory=CameraSpec)
    mount: MountSpec = field(default_factory=MountSpec)
    uav: UavSpec = field(default_factory=UavSpec)
    uuv: UuvSpec = field(default_factory=UuvSpec)
    link: LinkSpec = field(default_factory=LinkSpec)
    clock: ClockSpec = field(default_factory=ClockSpec)
    telemetry: TelemetrySpec = field(default_factory=TelemetrySpec)
    render: RenderSpec = field(default_factory=RenderSpec)


_TABLES = {"site": Site, "camera": CameraSpec, "mount": MountSpec, "uav": UavSpec, "uuv": UuvSpec,
           "link": LinkSpec, "clock": ClockSpec, "telemetry": TelemetrySpec, "render": RenderSpec}
_CHOICES = {"site.water_reference": ("takeoff", "amsl"),
            "mount.attitude_source": ("gimbal_device", "mount_orientation", "fixed"),
            "mount.gimbal_frame": ("earth", "vehicle"), "uav.standoff": ("auto", "given"),
            "mount.kind": ("stabilised", "servo"), "mount.yaw_mode": ("earth", "vehicle"),
            "telemetry.gps_raw_time": ("unix", "boot")}


def _checked(source: str, key: str, value, default):
    """``value`` converted to the type of ``default``, or ConfigError."""
    if default is None:  # an optional number
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        value = float(value) if ok else value
        default = 1.0
    elif isinstance(default, bool):
        ok = isinstance(value, bool)
    elif isinstance(default, int):
        ok = isinstance(value, int) and not isinstance(value, bool)
    elif isinstance(default, float):
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        value = float(value) if ok else value
    elif isinstance(default, str):
        ok = isinstance(value, str) and (key not in _CHOICES or value in _CHOICES[key])
    else:  # a tuple of numbers of fixed length
        ok = (isinstance(value, list) and len(value) == len(default)
              and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in value))
        value = tuple(float(x) for x in value) if ok else value
    if not ok:
        want = f"one of {', '.join(_CHOICES[key])}" if key in _CHOICES else f"a value like {default!r}"
        raise ConfigError(source, key, value, f"expected {want}")
    return value


def _build(cls, source: str, prefix: str, table: dict, skip=()):
    known = {f.name: f for f in fields(cls)}
    if not isinstance(table, dict):
        raise ConfigError(source, prefix or "(top level)", table, "expected a table")
    kwargs = {}
    for key, value in table.items():
        if key in skip:
            continue
        full = f"{prefix}.{key}" if prefix else key
        if key not in known:
            raise ConfigError(source, full, value, f"unknown key (known: {', '.join(sorted(known))})")
        default = cls.__dataclass_fields__[key].default
        kwargs[key] = _checked(source, full, value, default)
    return kwargs


def _pairs(value) -> tuple | None:
    """A TOML list of number pairs as a tuple of float pairs, or None if it is not one."""
    if not isinstance(value, list) or not all(
        isinstance(w, list) and len(w) == 2 and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in w)
        for w in value
    ):
        return None
    return tuple((float(a), float(b)) for a, b in value)


def _occlusions(source: str, value) -> tuple:
    pairs = _pairs(value)
    if pairs is None or not all(a < b for a, b in pairs):
        raise ConfigError(source, "occlusions", value, "expected a list of [start_s, end_s] pairs, start < end")
    return pairs


def _depth_profile(source: str, value) -> tuple:
    pairs = _pairs(value)
    if not pairs or not all(t0 < t1 for (t0, _), (t1, _) in pairwise(pairs)):
        raise ConfigError(source, "uuv.depth_profile", value,
                          "expected a non-empty list of [t_s, depth_m] pairs with increasing t_s")
    return pairs


def scenario_from_dict(data: dict, source: str = "scenario.toml") -> Scenario:
    """Validate parsed TOML and build a :class:`Scenario`."""
    if not isinstance(data.get("name"), str) or not data["name"]:
        raise ConfigError(source, "name", data.get("name"), "expected a non-empty string")
    top = _build(Scenario, source, "", data, skip=("name", "occlusions", *_TABLES))
    skip = {"uuv": ("depth_profile",)}  # a list of pairs, checked below
    tables = {k: cls(**_build(cls, source, k, data.get(k, {}), skip.get(k, ()))) for k, cls in _TABLES.items()}
    if "depth_profile" in data.get("uuv", {}):
        tables["uuv"] = replace(tables["uuv"], depth_profile=_depth_profile(source, data["uuv"]["depth_profile"]))
    occl = _occlusions(source, data["occlusions"]) if "occlusions" in data else ()
    sc = Scenario(name=data["name"], occlusions=occl, **top, **tables)
    _check_ranges(sc, source)
    v = sc.uuv
    if v.depth_profile:
        key, value, depths = "uuv.depth_profile", [list(k) for k in v.depth_profile], [d for _, d in v.depth_profile]
    else:
        key, value, depths = "uuv.depth_m", v.depth_m, (v.depth_m - abs(v.depth_swing_m), v.depth_m + abs(v.depth_swing_m))
    if not (min(depths) > 0 and max(depths) + v.size_m[2] < sc.site.floor_depth_m):
        raise ConfigError(source, key, value,
                          "the UUV must stay between the surface and the seafloor (site.floor_depth_m)")
    return sc


def _check_ranges(sc: Scenario, source: str) -> None:
    """Values of the right type but outside what the generator can simulate."""
    tel, link, uav = sc.telemetry, sc.link, sc.uav
    positive = {"duration_s": sc.duration_s, "fps": sc.fps, "telemetry.attitude_hz": tel.attitude_hz,
                "telemetry.position_hz": tel.position_hz, "telemetry.gimbal_hz": tel.gimbal_hz,
                "telemetry.depth_hz": tel.depth_hz, "link.reboot_down_s": link.reboot_down_s}
    for key, value in positive.items():
        if not value > 0:
            raise ConfigError(source, key, value, "must be > 0")
    not_negative = {"telemetry.system_time_hz": tel.system_time_hz, "telemetry.gps_raw_hz": tel.gps_raw_hz,
                    "telemetry.timesync_hz": tel.timesync_hz, "link.delay_s": link.delay_s,
                    "link.jitter_s": link.jitter_s, "link.depth_delay_s": link.depth_delay_s,
                    "link.depth_jitter_s": link.depth_jitter_s, "uav.wobble_deg": uav.wobble_deg,
                    "uav.wobble_hz": uav.wobble_hz, "uav.gnss_h_acc_m": uav.gnss_h_acc_m}
    for key, value in not_negative.items():
        if not value >= 0:
            raise ConfigError(source, key, value, "must be >= 0")
    if not 0 <= uav.gnss_fix_type <= 8:
        raise ConfigError(source, "uav.gnss_fix_type", uav.gnss_fix_type, "expected a GPS_FIX_TYPE, 0 to 8")
    if link.reboot_at_s is not None and not -tel.lead_s <= link.reboot_at_s <= sc.duration_s:
        raise ConfigError(source, "link.reboot_at_s", link.reboot_at_s,
                          f"must lie in the telemetry's span [-{tel.lead_s:g}, {sc.duration_s:g}] s")
    if sc.mount.kind == "servo" and sc.mount.attitude_source == "fixed":
        raise ConfigError(source, "mount.kind", "servo", 'a servo mount needs attitude_source "gimbal_device" '
                          'or "mount_orientation", not "fixed"')


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario TOML file."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except OSError as e:
        raise ConfigError(str(path), "(file)", str(path), f"cannot read: {e.strerror}") from None
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(str(path), "(syntax)", str(path), str(e)) from None
    return scenario_from_dict(data, str(path))


def with_overrides(sc: Scenario, **tables) -> Scenario:
    """A copy of ``sc`` with some fields of its tables replaced, e.g. ``camera={"width": 1280}``."""
    changes = {k: replace(getattr(sc, k), **v) for k, v in tables.items() if k in _TABLES}
    top = {k: v for k, v in tables.items() if k not in _TABLES}
    return replace(sc, **changes, **top)

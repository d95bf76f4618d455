"""A synthetic scenario: what the generator is asked to simulate, read from a small TOML file.

One contract (see :mod:`localizer.contract`): these frozen pydantic dataclasses
validate the parsed TOML, hold the defaults and document every knob;
``sim_fixtures/schemas/scenario.schema.json`` is generated from them. Every table
and key is optional except ``name``; unknown keys and wrong values are refused with
a one-line :class:`~localizer.contract.ConfigError` naming the file, key and value.
Units are in the key names (``_m``, ``_deg``, ``_s``, ``_hz``). World frame: local
North-East-Down with its origin on the water surface at ``[site] lat_deg, lon_deg``;
the water surface is the plane ``down = 0``.
"""

from __future__ import annotations

import dataclasses
import re
from itertools import pairwise
from pathlib import Path
from typing import Annotated, Literal

from annotated_types import Ge, Gt, Le, MinLen
from pydantic import Field, field_validator, model_validator
from pydantic.dataclasses import dataclass

from groundstation.config_files import read_toml
from groundstation.session.read import PRIMARY_UUV
from localizer.contract import (
    CLOSED,
    Flag,
    Invalid,
    NonNegative,
    Number,
    Pair,
    Positive,
    Text,
    Vector3,
    Vector5,
    Whole,
    validate,
)

Rgb = Vector3


@dataclass(frozen=True, config=CLOSED)
class Site:
    """``[site]``: where, and the water."""

    lat_deg: Number = Field(63.4400, description="origin of the world frame, on the water surface")
    lon_deg: Number = Field(10.4000, description="origin of the world frame, on the water surface")
    surface_amsl_m: Number = Field(
        0.40, description="the water surface's altitude above mean sea level"
    )
    water_reference: Literal["takeoff", "amsl"] = Field(
        "takeoff",
        description="session.toml [water] key written: takeoff_height_above_surface_m or surface_amsl_m",
    )
    takeoff_height_above_surface_m: Number = Field(
        1.80, description="the take-off point above the water"
    )
    refractive_index: Annotated[Number, Ge(1.0), Le(2.0)] = Field(1.34, description="of the water")
    floor_depth_m: Positive = Field(4.0, description="flat seafloor below the surface")
    geoid_separation_m: Number = Field(
        40.0,
        description="WGS84 ellipsoid height of mean sea level (GPS_RAW_INT alt_ellipsoid - alt)",
    )
    surface_amsl_sigma_m: NonNegative | None = Field(
        None,
        description="how well the operator knows the water's altitude: written as session.toml's "
        "[uncertainty] surface_amsl_m (the written surface_amsl_m itself is exact); unset: not written",
    )
    attenuation_bgr_per_m: Vector3 = Field(
        (0.05, 0.08, 0.22), description="light attenuation coefficients (1/m)"
    )
    turbidity_per_m: NonNegative = Field(
        0.0,
        description="scattering by suspended particles (1/m, every colour "
        "alike): added to the attenuation along the line of sight, the light it "
        "takes replaced by the water's colour (a veil: contrast falls faster with "
        "depth); 0: clear water",
    )
    water_bgr: Rgb = Field((120.0, 105.0, 50.0), description="colour of deep water (0-255)")


@dataclass(frozen=True, config=CLOSED)
class CameraSpec:
    """``[camera]``: the simulated camera (fx = fy, principal point at the centre)."""

    width: Annotated[Whole, Ge(16)] = Field(640, description="pixels")
    height: Annotated[Whole, Ge(16)] = Field(360, description="pixels")
    hfov_deg: Annotated[Positive, Le(170)] = Field(
        62.0, description="horizontal field of view of the undistorted pinhole"
    )
    distortion: Vector5 = Field(
        (-0.12, 0.08, 0.0004, -0.0002, -0.01), description="k1, k2, p1, p2, k3"
    )


@dataclass(frozen=True, config=CLOSED)
class MountSpec:
    """``[mount]``: how the camera is carried and which message reports its attitude."""

    attitude_source: Literal["gimbal_device", "mount_orientation", "fixed"] = Field(
        "gimbal_device",
        description="the message reporting the camera's attitude, or a camera fixed to the airframe",
    )
    kind: Literal["stabilised", "servo"] = Field(
        "stabilised",
        description="stabilised: the gimbal holds its attitude itself and reports it; servo (ArduPilot "
        "MNT1_TYPE 1): the autopilot commands servo angles = target - the vehicle's lean and reports those demands",
    )
    gimbal_frame: Literal["earth", "vehicle"] = Field(
        "earth",
        description="gimbal_device yaw reported in the earth frame (flags 76) or the vehicle's (flags 44, "
        "as ArduPilot)",
    )
    pitch_deg: Number = Field(
        -90.0, description="target pitch relative to the horizon (-90 = straight down)"
    )
    yaw_mode: Literal["earth", "vehicle"] = Field(
        "earth",
        description="yaw_deg held from North (earth) or from the vehicle's heading (vehicle, follow)",
    )
    yaw_deg: Number = Field(
        0.0, description="target yaw (degrees), from North or from the vehicle's heading"
    )
    jitter_deg: NonNegative = Field(
        0.05, description="amplitude of the gimbal's residual wobble (0.4 and 0.7 Hz)"
    )
    fixed_rpy_deg: Vector3 = Field(
        (0.0, -90.0, 0.0), description="fixed: the camera in the body FRD frame"
    )
    camera_offset_m: Vector3 = Field(
        (0.10, 0.0, 0.20), description="camera in body FRD relative to the reported position"
    )


@dataclass(frozen=True, config=CLOSED)
class UavSpec:
    """``[uav]``: the hover."""

    height_m: Positive = Field(
        10.0, description="mean height of the reported position above the water"
    )
    height_swing_m: NonNegative = Field(0.3, description="amplitude of slow height changes")
    standoff: Literal["auto", "given", "follow"] = Field(
        "auto",
        description="auto: placed so the optical axis meets the UUV's path centre (a cruise: where it starts); "
        "given: north_m, east_m; follow: flies after the UUV, the optical axis on where the UUV was follow_lag_s "
        "earlier (the seafloor slides through the image)",
    )
    follow_lag_s: NonNegative = Field(
        1.0, description="follow: how far behind the UUV the UAV aims, in time"
    )
    north_m: Number = Field(0.0, description="mean position when standoff = given")
    east_m: Number = Field(0.0, description="mean position when standoff = given")
    drift_m: NonNegative = Field(0.4, description="amplitude of the hover's horizontal drift")
    yaw_deg: Number = Field(20.0, description="mean heading")
    yaw_swing_deg: Number = Field(10.0, description="amplitude of the heading's sinusoidal changes")
    yaw_period_s: Positive = Field(12.0, description="period of the heading's changes")
    tilt_deg: Number = Field(
        4.0, description="wind tilt: the airframe leans into the wind by this much"
    )
    wind_from_deg: Number = Field(
        250.0, description="where the wind comes from, degrees from North"
    )
    gust_deg: Number = Field(0.8, description="amplitude of the tilt's oscillation")
    wobble_deg: NonNegative = Field(
        0.0,
        description="amplitude of an extra airframe roll and pitch oscillation "
        "(a camera fixed to it wobbles)",
    )
    wobble_hz: NonNegative = Field(0.0, description="frequency of that oscillation")
    armed_at_s: Number | None = Field(
        None,
        description="scenario time the autopilot arms (HEARTBEAT base_mode "
        "SAFETY_ARMED from then on); unset: armed before the telemetry starts",
    )
    baro_bias_m: Number = Field(
        0.0,
        description="error of the EKF's heights (GLOBAL_POSITION_INT alt and "
        "relative_alt, which follow the barometer with ArduPilot's EK3_SRC1_POSZ = 1) at the "
        "first frame, positive: they read high; GPS_RAW_INT is not affected",
    )
    baro_drift_m: Number = Field(
        0.0,
        description="change of that error from the first frame to the last, linear in "
        "time (it goes on before and after)",
    )
    gnss_fix_type: Annotated[Whole, Ge(0), Le(8)] | None = Field(
        None,
        description="GPS_RAW_INT fix_type (a GPS_FIX_TYPE: 3 = 3D, 6 = RTK fixed); unset: [sensors] gnss_mode's "
        "(exact and plain 3, rtk 6)",
    )
    gnss_h_acc_m: NonNegative | None = Field(
        None,
        description="GPS_RAW_INT h_acc, the receiver's claim (the position's own error is [sensors] gnss_mode's); "
        "unset: gnss_mode's (exact and rtk 0.02, plain 2.0)",
    )
    gnss_v_acc_m: NonNegative | None = Field(
        None, description="GPS_RAW_INT v_acc; unset: twice gnss_h_acc_m"
    )
    gnss_accuracy: Literal["reported", "dop_only"] = Field(
        "reported",
        description="dop_only: h_acc and v_acc are 0 (not reported), only eph and epv, as some receivers",
    )
    gnss_hdop: Positive | None = Field(
        None,
        description="GPS_RAW_INT eph (HDOP x 100); unset: [sensors] gnss_mode's "
        "(exact and rtk 0.7, plain 1.0)",
    )
    gnss_vdop: Positive = Field(1.1, description="GPS_RAW_INT epv (VDOP x 100)")
    gnss_alt_error_m: NonNegative = Field(
        0.0,
        description="RMS of the GNSS altitude's slowly wandering error "
        "(GPS_RAW_INT alt and alt_ellipsoid; not the EKF's heights)",
    )
    gnss_alt_error_period_s: Positive = Field(
        300.0,
        description="its typical period: three sinusoids of this "
        "period, 0.61 and 0.37 of it, random phases",
    )
    gnss_alt_noise_m: NonNegative = Field(
        0.0,
        description="1-sigma white noise of the GNSS altitude, new with each "
        "GPS_RAW_INT (alt and alt_ellipsoid; e.g. 0.02 for an RTK fix)",
    )


@dataclass(frozen=True, config=CLOSED)
class UuvSpec:
    """``[uuv]``: the vehicle's path (a slow figure eight, or a cruise) and depth."""

    path: Literal["figure_eight", "cruise"] = Field(
        "figure_eight",
        description="figure_eight: path_n_m x path_e_m loops of period_s; cruise: speed_mps along "
        "course_deg from north_m, east_m, weaving sideways by weave_m",
    )
    north_m: Number = Field(
        0.0, description="centre of the figure-eight path; cruise: where it is at the first frame"
    )
    east_m: Number = Field(
        0.0, description="centre of the figure-eight path; cruise: where it is at the first frame"
    )
    path_n_m: Number = Field(0.8, description="half extent of the path along North")
    path_e_m: Number = Field(0.6, description="half extent of the path along East")
    period_s: Positive = Field(24.0, description="one loop of the figure eight")
    speed_mps: Positive = Field(
        1.2, description="cruise: speed along the mean course (the weave adds a little)"
    )
    course_deg: Number = Field(0.0, description="cruise: mean course, degrees from North")
    weave_m: NonNegative = Field(
        0.0,
        description="cruise: amplitude of a sideways sinusoid about the mean course "
        "(a gently curving path); 0: a straight line",
    )
    weave_period_s: Positive = Field(20.0, description="cruise: period of the weave")
    depth_m: Number = Field(
        1.0, description="mean depth of the top face (the reference point); 0: at the surface"
    )
    depth_swing_m: Number = Field(0.25, description="amplitude of the depth's slow changes")
    depth_period_s: Positive = Field(15.0, description="period of the depth's changes")
    depth_profile: tuple[Pair, ...] = Field(
        (),
        description="[[t_s, depth_m], ...] keyframes, times from the first frame and increasing: when given, the "
        "depth follows them (cosine-eased in between, held outside) instead of depth_m ± depth_swing_m; a dive",
    )
    size_m: Vector3 = Field((0.46, 0.34, 0.25), description="length, width, height (BlueROV2)")

    @field_validator("depth_profile")
    @classmethod
    def _increasing(cls, profile):
        if not all(t0 < t1 for (t0, _), (t1, _) in pairwise(profile)):
            raise Invalid(
                "", [list(p) for p in profile], "expected [t_s, depth_m] pairs with increasing t_s"
            )
        return profile


@dataclass(frozen=True, config=CLOSED)
class RangefinderSpec:
    """``[rangefinder]``: a downward rangefinder (ArduPilot orientation 25, MAV_SENSOR_ROTATION_PITCH_270) at the
    reported position, sent as DISTANCE_SENSOR and ArduPilot's RANGEFINDER at ``rate_hz``."""

    enabled: Flag = Field(False, description="the UAV has one")
    sees: Literal["water", "nothing", "floor"] = Field(
        "water",
        description="water: the distance along the body's down axis to the surface (a tilted airframe "
        "reads long); nothing: no return from the water, it reports max_m + 1 m (out of range) as ArduPilot's lidar "
        "drivers do; floor: a lidar seeing the seafloor through clear water, approximately (height + n x floor "
        "depth) along the down axis",
    )
    rate_hz: Positive = Field(10.0, description="readings per second")
    noise_m: NonNegative = Field(
        0.03, description="1-sigma white noise of each reading (waves included)"
    )
    min_m: NonNegative = Field(0.2, description="DISTANCE_SENSOR min_distance")
    max_m: Positive = Field(40.0, description="DISTANCE_SENSOR max_distance")
    dropouts: tuple[Pair, ...] = Field(
        (),
        description="[[start_s, end_s], ...] from the first frame: no reading is "
        "sent (ArduPilot sends none while its driver has no data)",
    )

    @field_validator("dropouts")
    @classmethod
    def _start_before_end(cls, spans):
        if not all(a < b for a, b in spans):
            raise Invalid(
                "", [list(w) for w in spans], "expected [start_s, end_s] pairs, start < end"
            )
        return spans


@dataclass(frozen=True, config=CLOSED)
class LinkSpec:
    """``[link]``: the telemetry and depth links."""

    delay_s: NonNegative = Field(
        0.045, description="telemetry link delay (sample to ground-station receipt)"
    )
    jitter_s: NonNegative = Field(
        0.012, description="mean of the exponential extra delay; the link stays in order"
    )
    boot_s_at_start: NonNegative = Field(
        412.0, description="autopilot uptime when the scenario starts"
    )
    depth_delay_s: NonNegative = Field(
        0.03, description="UUV depth link: measurement to ground-station receipt"
    )
    depth_jitter_s: NonNegative = Field(
        0.005, description="mean of its exponential extra delay; arrivals stay in order"
    )
    reboot_at_s: Number | None = Field(
        None, description="the autopilot reboots at this scenario time (unset: never)"
    )
    reboot_down_s: Positive = Field(
        3.0, description="... is silent this long, then talks again with its boot clock restarted"
    )


@dataclass(frozen=True, config=CLOSED)
class ClockSpec:
    """``[clock]``: clocks that disagree with true (GNSS) time."""

    station_offset_s: Number = Field(
        0.0,
        description="ground station (laptop) clock minus true GNSS time: stamps "
        "frames, tlog, t_recv",
    )
    uuv_offset_s: Number = Field(
        0.0, description="the UUV's clock minus true time: stamps depth.jsonl's t"
    )
    video_time_error_s: Number = Field(
        0.0,
        description="video_frames.csv's times minus the frames' true exposures (a wrong latency)",
    )


@dataclass(frozen=True, config=CLOSED)
class TelemetrySpec:
    """``[telemetry]``: message rates (Hz) and noise."""

    attitude_hz: Positive = Field(50.0, description="ATTITUDE rate")
    position_hz: Positive = Field(10.0, description="GLOBAL_POSITION_INT rate")
    gimbal_hz: Positive = Field(20.0, description="gimbal message rate")
    system_time_hz: NonNegative = Field(1.0, description="SYSTEM_TIME rate; 0: not sent")
    gps_raw_hz: NonNegative = Field(5.0, description="GPS_RAW_INT rate; 0: not sent")
    gps_raw_time: Literal["unix", "boot"] = Field(
        "unix",
        description="GPS_RAW_INT time_usec: true UNIX time (unix) or boot time (boot, as ArduPilot)",
    )
    timesync_hz: NonNegative = Field(
        1.0,
        description="the ground station's TIMESYNC requests (each answered by the "
        "autopilot); 0: none",
    )
    depth_hz: Positive = Field(8.0, description="the UUV's depth samples")
    lead_s: NonNegative = Field(
        2.0, description="telemetry starts this long before the first frame"
    )
    attitude_noise_deg: NonNegative = Field(
        0.0, description="1-sigma white noise on reported roll, pitch, yaw"
    )
    height_noise_m: NonNegative = Field(0.0, description="1-sigma noise on reported altitudes")
    depth_noise_m: NonNegative = Field(0.0, description="1-sigma noise on reported UUV depth")


@dataclass(frozen=True)
class GnssMode:
    """What ``[sensors] gnss_mode`` means: the position's errors (horizontal RMS, m; the walk's correlation time, s)
    and the receiver's claims in GPS_RAW_INT where ``[uav]`` does not state them."""

    walk_m: float
    walk_s: float
    white_m: float
    fix_type: int
    h_acc_m: float
    hdop: float


GNSS_MODES = {
    "exact": GnssMode(0.0, 60.0, 0.0, 3, 0.02, 0.7),  # as before [sensors]: an exact position
    "rtk": GnssMode(0.015, 60.0, 0.015, 6, 0.02, 0.7),  # RTK fixed
    "plain": GnssMode(1.2, 120.0, 0.03, 3, 2.0, 1.0),
}  # a single-frequency receiver, no corrections


@dataclass(frozen=True, config=CLOSED)
class SensorsSpec:
    """``[sensors]``: the drone's own sensor errors, what its AHRS, gimbal, EKF position and barometer report minus the
    truth (:mod:`sim_fixtures.sensors` says what a real ArduCopter and gimbal report); all off by default (the
    telemetry states the true attitude and position). The scene (and its video) is the same with them on or off."""

    roll_bias_deg: Number = Field(
        0.0,
        description="AHRS tilt bias: ATTITUDE's roll reads this much high (0.2-0.4 "
        "typical, with pitch_bias_deg)",
    )
    pitch_bias_deg: Number = Field(
        0.0, description="AHRS tilt bias: ATTITUDE's pitch reads this much high"
    )
    yaw_bias_deg: Number = Field(
        0.0,
        description="compass bias: the autopilot's heading (ATTITUDE yaw, "
        "GLOBAL_POSITION_INT hdg, the gimbal's earth yaw) reads this much high (1-2.5 typical)",
    )
    wander_deg: NonNegative = Field(
        0.0,
        description="RMS of the AHRS's slow wander on each of roll, pitch and yaw (a "
        "first-order Gauss-Markov per axis; 0.05-0.1 typical)",
    )
    wander_s: Positive = Field(60.0, description="its correlation time (30-120 typical)")
    gimbal_level_deg: Pair = Field(
        (0.0, 0.0),
        description="a stabilised gimbal's levelling error [roll, pitch]: its "
        "reported roll and pitch read high by this, a tilt about its own heading's forward "
        "and right axes (its own IMU: none of the autopilot's tilt bias)",
    )
    gnss_mode: Literal["exact", "rtk", "plain"] = Field(
        "exact",
        description="the EKF position's error (GLOBAL_POSITION_INT lat, lon; GPS_RAW_INT's follows the same "
        "walk): exact none; rtk a 0.015 m walk of 60 s + 0.015 m white; plain a 1.2 m walk of 120 s + 0.03 m white "
        "(horizontal RMS); also the default of [uav] gnss_fix_type, gnss_h_acc_m, gnss_hdop",
    )
    gnss_walk_m: NonNegative | None = Field(
        None,
        description="horizontal RMS of the position's slow error (a "
        "Gauss-Markov per axis, each 1/sqrt(2) of it); unset: gnss_mode's",
    )
    gnss_walk_s: Positive | None = Field(
        None, description="its correlation time; unset: gnss_mode's"
    )
    gnss_white_m: NonNegative | None = Field(
        None,
        description="horizontal RMS of white noise, new with each "
        "GLOBAL_POSITION_INT and each GPS_RAW_INT; unset: gnss_mode's",
    )
    baro_wander_m: NonNegative = Field(
        0.0,
        description="RMS of the barometer's slow wander (a Gauss-Markov; 0.1-0.2 "
        "typical) in the EKF's heights (GLOBAL_POSITION_INT alt, relative_alt), on top "
        "of [uav] baro_bias_m and baro_drift_m",
    )
    baro_wander_s: Positive = Field(30.0, description="its correlation time")
    baro_noise_m: NonNegative = Field(
        0.0,
        description="1-sigma white noise of the EKF's heights, new with each "
        "GLOBAL_POSITION_INT (alt and relative_alt alike; a few cm typical)",
    )
    video_time_sigma_s: NonNegative = Field(
        0.0,
        description="1-sigma of a constant error of video_frames.csv's times (the frames' stamps minus their "
        "exposures: a latency known to this much), drawn once per flight and added to [clock] video_time_error_s; "
        "stated as [uncertainty] time_s",
    )
    draw: Annotated[Whole, Ge(0)] = Field(
        0,
        description="which draw of the sensors' random errors (the wanders, walks and white noise here, the "
        "frames' time error, [uav]'s GNSS altitude errors): 0 the scenario's own; another number another draw of "
        "the same sizes, the scene and its video the same",
    )

    @model_validator(mode="after")
    def _exact_is_exact(self):
        if self.gnss_mode == "exact":
            for key in ("gnss_walk_m", "gnss_walk_s", "gnss_white_m"):
                if getattr(self, key) is not None:
                    raise Invalid(
                        key,
                        getattr(self, key),
                        'needs gnss_mode = "rtk" or "plain" (exact: no error)',
                    )
        return self


@dataclass(frozen=True, config=CLOSED)
class RenderSpec:
    """``[render]``: the picture."""

    exposure: Positive = Field(
        1.4, description="sunlight just below the surface, relative to the albedo"
    )
    caustics: NonNegative = Field(
        0.5,
        description="strength of the moving caustic pattern (0 = none); under "
        "[waves]: the light's relative flicker (standard deviation over mean) just below "
        "the surface, on the seafloor and the vehicles alike",
    )
    glint: NonNegative = Field(0.0, description="strength of sun glint (0 = none)")
    sun_azimuth_deg: Number = Field(140.0, description="degrees from North")
    sun_elevation_deg: Number = Field(55.0, description="degrees above the horizon")
    noise_sigma: NonNegative = Field(2.0, description="sensor noise, grey levels")
    crf: Annotated[Whole, Ge(0), Le(51)] = Field(23, description="x264 quality (lower is better)")
    supersample: Annotated[Whole, Ge(1)] = Field(
        2, description="rays per pixel side on the UUV (anti-aliasing)"
    )
    shadow: Annotated[Number, Ge(0), Le(1)] = Field(
        0.0,
        description="share of the light under water that comes straight from the sun (the rest is diffuse): the "
        "vehicles and the rock cast shadows of the sunlight refracted at the flat surface (sun_azimuth_deg, "
        "sun_elevation_deg) on the seafloor and on each other, where that share and the caustics are missing; 0: no "
        "shadows",
    )


@dataclass(frozen=True, config=CLOSED)
class WavesSpec:
    """``[waves]``: wind waves on the water surface (:mod:`sim_fixtures.waves`): Elfouhaily's wind-sea spectrum for the
    wind and fetch, its slopes scaled to Cox & Munk's, realised as a sum of random-phase linear waves (from the seed)
    down to the shortest wave the image resolves; every camera ray is refracted through its local facet. 0 wind: the
    flat surface."""

    wind_mps: Annotated[Number, Ge(0), Le(14)] = Field(
        0.0,
        description="wind 10 m above the water (Cox & Munk "
        "measured 1-14 m/s); 0: a flat, still surface",
    )
    fetch_m: Annotated[Number, Ge(100)] = Field(
        3000.0,
        description="the stretch of water the wind has blown over "
        "(the wave age: a short fetch, short young waves)",
    )
    direction_from_deg: Number | None = Field(
        None, description="where the wind comes from, degrees from North; unset: uav.wind_from_deg"
    )
    components: Annotated[Whole, Ge(16), Le(2000)] = Field(
        300, description="how many linear waves realise the spectrum (log-spaced wavenumber bands)"
    )
    shortest_wavelength_m: Positive | None = Field(
        None,
        description="the shortest wave realised; unset: 4 of the floor's pixels (the image's; 2x2 of them from "
        "1200 px wide) at the surface seen straight down from uav.height_m. Shorter ones are left out (their slopes "
        "only widen the sun's glint)",
    )
    caustic_fade_per_m: NonNegative = Field(
        0.4,
        description="the caustics' flicker ([render] caustics just below "
        "the surface) fades as exp(-this x depth) on the seafloor and the "
        "vehicles (c + K_d of the water); they drift downwind with the waves "
        "that focus them",
    )


@dataclass(frozen=True, config=CLOSED)
class DownlinkSpec:
    """``[downlink]``: how the video is encoded. Unset ``bitrate_mbps``: x264 at ``[render] crf`` (the default); set:
    as a drone's downlink does it, a constant bitrate without B-frames."""

    bitrate_mbps: Annotated[Number, Ge(0.2), Le(100)] | None = Field(
        None,
        description="x264 -b:v and -maxrate (Mbit/s; drones send 2-8), -bf 0; unset: [render] crf",
    )
    buffer_s: Annotated[Number, Gt(0), Le(10)] = Field(
        1.0, description="the rate control's buffer (-bufsize), in seconds of the bitrate"
    )
    keyframe_s: Annotated[Number, Gt(0), Le(20)] = Field(
        1.0, description="a keyframe this often (-g, frames rounded)"
    )


@dataclass(frozen=True, config=CLOSED)
class SecondUuvSpec:
    """``[second_uuv]``: another vehicle of the UUV's size and look, on a straight line at a constant depth, that
    passes the UUV: a look-alike crossing (the session's records stay the UUV's), or with ``role = "uuv"`` a second
    tracked UUV whose own records the session holds under ``uuvs/<id>/``."""

    enabled: Flag = Field(False, description="the second vehicle is there")
    role: Literal["lookalike", "uuv"] = Field(
        "lookalike",
        description="lookalike: only drawn (the tracker must not jump to it); uuv: a tracked UUV too, its "
        "truth, depth, track and first box written to uuvs/<id>/ (the session's own files stay the first UUV's)",
    )
    id: Text = Field(
        "uuv2",
        description="role = uuv: its id, the session's folder uuvs/<id>/ (letters, digits, _ "
        "and -; the first UUV is uuv1)",
    )
    pass_at_s: Number = Field(10.0, description="scenario time at which it passes the UUV")
    miss_m: Number = Field(
        0.0,
        description="where it is at pass_at_s: this far from the UUV's reference point, "
        "square to its own course, to its right (negative: its left); 0: right over or under it",
    )
    course_rel_deg: Number = Field(
        90.0,
        description="its course relative to the UUV's heading at pass_at_s "
        "(90: crossing from the UUV's left to its right; 180: head on)",
    )
    speed_mps: Positive = Field(1.0, description="its speed")
    depth_m: NonNegative = Field(0.5, description="depth of its top face")

    @field_validator("id")
    @classmethod
    def _folder_name(cls, uuv_id):
        if not re.fullmatch(r"[A-Za-z0-9_-]+", uuv_id) or uuv_id == PRIMARY_UUV:
            raise Invalid(
                "",
                uuv_id,
                f"expected letters, digits, _ and - (a folder name), not {PRIMARY_UUV!r}",
            )
        return uuv_id


@dataclass(frozen=True, config=CLOSED)
class MarkerSpec:
    """``[marker]``: a surveyed marker lying on the seafloor, a reference of known position: a white disc with a black
    centre (a bullseye), painted into the floor; its position and depth are written to the session's
    ``reference.toml`` (as a team that surveyed it would state them) and its pixel per frame to
    ``reference_track.csv`` (the simulator's truth, as track.csv is the UUV's)."""

    enabled: Flag = Field(False, description="the marker is there")
    north_m: Number = Field(
        1.5, description="where it lies, from the UUV's path centre (uuv.north_m)"
    )
    east_m: Number = Field(-1.0, description="... and (uuv.east_m)")
    radius_m: Annotated[Number, Gt(0.05), Le(2.0)] = Field(
        0.25, description="the white disc's radius; the black centre's is half of it"
    )


@dataclass(frozen=True, config=CLOSED)
class BuoySpec:
    """``[buoy]``: a buoy drifting on the surface that reports its RTK GNSS over MAVLink, a moving reference of known
    position (:mod:`sim_fixtures.buoy`): a square hull whose top is painted as the marker (a white disc, a black
    centre of half its radius); its GPS_RAW_INT from its own system id in ``uav.tlog``, as a ground station records
    what it hears; ``reference.toml`` names that system id (as a team would configure it)."""

    enabled: Flag = Field(False, description="the buoy is there")
    north_m: Number = Field(1.5, description="where it starts, from the UUV's path centre (north)")
    east_m: Number = Field(-1.5, description="... and east")
    drift_mps: Pair = Field((0.005, 0.01), description="its drift (north, east; m/s)")
    swing_m: NonNegative = Field(
        0.5, description="amplitude of its swing on the mooring (each axis, m)"
    )
    swing_period_s: Positive = Field(
        60.0, description="period of the swing (north; east 1.6 of it)"
    )
    radius_m: Annotated[Number, Gt(0.05), Le(2.0)] = Field(
        0.25, description="the white disc's radius on its top; the hull is 2.6 of it across"
    )
    depth_m: NonNegative = Field(
        0.0, description="its marked top's depth below the still surface (0: at the surface)"
    )
    draft_m: Positive = Field(0.3, description="the hull's height below its top")
    system_id: Annotated[Whole, Ge(2), Le(255)] = Field(
        42, description="its MAVLink system id (the UAV is 1)"
    )
    gnss_hz: Positive = Field(5.0, description="its GPS_RAW_INT rate")
    gnss_sigma_m: NonNegative = Field(
        0.015, description="its GNSS's error, 1-sigma per horizontal axis (RTK)"
    )
    gnss_correlation_s: Positive = Field(
        10.0, description="the error's correlation time (first-order Gauss-Markov)"
    )
    link_delay_s: NonNegative = Field(0.25, description="its radio link's delay to the station")
    link_jitter_s: NonNegative = Field(0.05, description="mean exponential jitter on it")


@dataclass(frozen=True, config=CLOSED)
class RockSpec:
    """``[rock]``: a dark rock, a box of about the UUV's size lying still on the seafloor, placed by the UUV's
    path (a look-alike the UUV passes close by or over)."""

    enabled: Flag = Field(False, description="the rock is there")
    at_s: Number = Field(
        10.0, description="the rock lies below where the UUV is at this scenario time ..."
    )
    offset_m: Pair = Field((0.5, 0.0), description="... shifted by this (north, east)")
    heading_deg: Number = Field(0.0, description="direction of its long side from North")
    size_m: Vector3 = Field((0.46, 0.34, 0.25), description="length, width, height")

    @field_validator("size_m")
    @classmethod
    def _positive(cls, size):
        if not all(x > 0 for x in size):
            raise Invalid("", list(size), "expected three lengths > 0")
        return size


@dataclass(frozen=True, config=CLOSED)
class Scenario:
    """A synthetic scenario (``sim_fixtures/scenarios/*.toml``): top-level keys and one table per part."""

    name: Annotated[Text, MinLen(1)] = Field(
        description="the scenario's name (the bundled session's folder)"
    )
    description: Text = Field("", description="what the scenario is for")
    seed: Whole = Field(1, description="random seed: the same seed gives the same session")
    duration_s: Positive = Field(8.0, description="video length")
    fps: Positive = Field(30.0, description="frame rate")
    start_unix: Number = Field(1763800000.0, description="true UNIX time of the first frame")
    occlusions: tuple[Pair, ...] = Field(
        (), description="[[start_s, end_s], ...] from the first frame: the UUV is hidden"
    )
    site: Site = Field(default_factory=Site)
    camera: CameraSpec = Field(default_factory=CameraSpec)
    mount: MountSpec = Field(default_factory=MountSpec)
    uav: UavSpec = Field(default_factory=UavSpec)
    uuv: UuvSpec = Field(default_factory=UuvSpec)
    link: LinkSpec = Field(default_factory=LinkSpec)
    clock: ClockSpec = Field(default_factory=ClockSpec)
    rangefinder: RangefinderSpec = Field(default_factory=RangefinderSpec)
    telemetry: TelemetrySpec = Field(default_factory=TelemetrySpec)
    render: RenderSpec = Field(default_factory=RenderSpec)
    second_uuv: SecondUuvSpec = Field(default_factory=SecondUuvSpec)
    third_uuv: SecondUuvSpec = Field(
        default_factory=lambda: SecondUuvSpec(id="uuv3"),
        description="a third vehicle, as [second_uuv] (which it needs enabled) on a line of its own",
    )
    rock: RockSpec = Field(default_factory=RockSpec)
    marker: MarkerSpec = Field(default_factory=MarkerSpec)
    buoy: BuoySpec = Field(default_factory=BuoySpec)
    waves: WavesSpec = Field(default_factory=WavesSpec)
    downlink: DownlinkSpec = Field(default_factory=DownlinkSpec)
    sensors: SensorsSpec = Field(default_factory=SensorsSpec)

    @field_validator("occlusions")
    @classmethod
    def _start_before_end(cls, spans):
        if not all(a < b for a, b in spans):
            raise Invalid(
                "", [list(w) for w in spans], "expected [start_s, end_s] pairs, start < end"
            )
        return spans

    @model_validator(mode="after")
    def _simulable(self):
        """Values of the right type but outside what the generator can simulate."""
        tel, link, v = self.telemetry, self.link, self.uuv
        if link.reboot_at_s is not None and not -tel.lead_s <= link.reboot_at_s <= self.duration_s:
            raise Invalid(
                "link.reboot_at_s",
                link.reboot_at_s,
                f"must lie in the telemetry's span [-{tel.lead_s:g}, {self.duration_s:g}] s",
            )
        if not self.rangefinder.min_m < self.rangefinder.max_m:
            raise Invalid(
                "rangefinder.min_m",
                self.rangefinder.min_m,
                f"must be < rangefinder.max_m ({self.rangefinder.max_m:g})",
            )
        if self.mount.kind == "servo" and self.mount.attitude_source == "fixed":
            raise Invalid(
                "mount.kind",
                "servo",
                'a servo mount needs attitude_source "gimbal_device" or '
                '"mount_orientation", not "fixed"',
            )
        if v.depth_profile:
            key, value, depths = (
                "uuv.depth_profile",
                [list(k) for k in v.depth_profile],
                [d for _, d in v.depth_profile],
            )
        else:
            key, value = "uuv.depth_m", v.depth_m
            depths = (v.depth_m - abs(v.depth_swing_m), v.depth_m + abs(v.depth_swing_m))
        if not (min(depths) >= 0 and max(depths) + v.size_m[2] < self.site.floor_depth_m):
            raise Invalid(
                key,
                value,
                "the UUV must stay between the surface (its top face at depth 0 or below) and "
                "the seafloor (site.floor_depth_m)",
            )
        if self.buoy.enabled and self.marker.enabled:
            raise Invalid("buoy.enabled", True, "one reference a session: [marker] is enabled too")
        if self.second_uuv.role == "uuv" and not self.second_uuv.enabled:
            raise Invalid("second_uuv.role", "uuv", "a second UUV needs second_uuv.enabled = true")
        if self.third_uuv.enabled and not self.second_uuv.enabled:
            raise Invalid(
                "third_uuv.enabled", True, "a third vehicle needs second_uuv.enabled = true"
            )
        if self.third_uuv.role == "uuv" and not self.third_uuv.enabled:
            raise Invalid("third_uuv.role", "uuv", "a third UUV needs third_uuv.enabled = true")
        if self.third_uuv.role == "uuv" and self.third_uuv.id == self.second_uuv.id:
            raise Invalid("third_uuv.id", self.third_uuv.id, "already second_uuv.id")
        floor = self.site.floor_depth_m
        for key in ("second_uuv", "third_uuv"):
            spec = getattr(self, key)
            if spec.enabled and not spec.depth_m + v.size_m[2] < floor:
                raise Invalid(
                    f"{key}.depth_m",
                    spec.depth_m,
                    f"its bottom must stay above the seafloor (site.floor_depth_m = {floor:g})",
                )
        if self.rock.enabled and not self.rock.size_m[2] < floor:
            raise Invalid(
                "rock.size_m",
                list(self.rock.size_m),
                f"taller than the water (site.floor_depth_m = {floor:g})",
            )
        if self.second_uuv.enabled or self.rock.enabled:
            from .motion import Motion, first_contact  # the paths are the motion's

            motion = Motion(self)
            for key, value, other in (
                ("second_uuv.miss_m", self.second_uuv.miss_m, "the second vehicle"),
                ("third_uuv.miss_m", self.third_uuv.miss_m, "the third vehicle"),
                ("rock.offset_m", list(self.rock.offset_m), "the rock"),
            ):
                hit_s = first_contact(self, motion, other)
                if hit_s is not None:
                    raise Invalid(
                        key,
                        value,
                        f"{other} and the UUV would touch at {hit_s:.2f} s: pass them further "
                        "apart or at other depths",
                    )
        return self


def scenario_from_dict(data: dict, source: str = "scenario.toml") -> Scenario:
    """Validate parsed TOML and build a :class:`Scenario`."""
    return validate(Scenario, data, source)


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario TOML file."""
    return scenario_from_dict(read_toml(path), str(path))


def with_overrides(sc: Scenario, **tables) -> Scenario:
    """A copy of ``sc`` with some fields of its tables replaced, e.g. ``camera={"width": 1280}``."""
    changes = {
        k: dataclasses.replace(getattr(sc, k), **v) if isinstance(v, dict) else v
        for k, v in tables.items()
    }
    return dataclasses.replace(sc, **changes)

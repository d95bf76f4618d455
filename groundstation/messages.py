"""The two Zenoh messages skyfix publishes, as contracts: the fix and the status.

Each is a pydantic model; ``groundstation/schemas/fix.schema.json`` and
``status.schema.json`` are generated from them (``python -m groundstation.contracts``)
and a test fails when the checked-in files are stale. Both carry ``schema``, the
message's name and major version: it changes only when a key is removed or changes
meaning; new keys may appear within a version, so consumers ignore keys they do not
know. JSON has no NaN: every number that is not available is ``null``.

The fix (one per processed frame, on ``--fix-key``) is built here from the
:class:`~localizer.fix.Fix`. The status (once a second, on ``--status-key``) is
assembled by the service from its workers' ``status()`` dicts; the model describes
it and the end-to-end test validates every status the service publishes against it,
so a key added to a worker's status needs its line here.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Annotated, Any, Literal

from annotated_types import Ge, Le
from pydantic import BaseModel, ConfigDict, Field, model_validator

from groundstation.runtime.no_fix import NO_FIX_WHY
from localizer.fix import WORDS, Fix
from localizer.fix_gate import STATES as GATE_STATES
from localizer.status import STATUSES, Status
from localizer.telemetry import LATENCY_SOURCES

FIX_SCHEMA = "skyfix.fix/1"
STATUS_SCHEMA = "skyfix.status/1"

Metres = float | None
Seconds = float | None
NonNegative = Annotated[float, Ge(0)] | None


def _status_doc() -> str:
    return "ok, or why there is no position: " + "; ".join(f"{k}: {v}" for k, v in STATUSES.items())


class Message(BaseModel):
    """A published message: closed (a key not described here is a contract change), keys by alias."""

    model_config = ConfigDict(
        extra="forbid", frozen=True, populate_by_name=True, allow_inf_nan=False
    )


class FixMessage(Message):
    """One processed video frame: the UUV's position, or why there is none."""

    model_config = ConfigDict(
        json_schema_extra={
            # a valid fix has a position and its accuracy; any other status has no position
            "if": {"properties": {"status": {"const": "ok"}}},
            "then": {
                "properties": {
                    k: {"type": "number"}
                    for k in ("lat", "lon", "h_acc_m", "sigma_n_m", "sigma_e_m")
                }
            },
            "else": {"properties": {"lat": {"type": "null"}, "lon": {"type": "null"}}},
        }
    )

    schema_: Literal[FIX_SCHEMA] = Field(
        alias="schema", description="message name and major version"
    )
    t: float = Field(description="the frame's exposure time on the station clock, UNIX seconds")
    t_gnss: Seconds = Field(
        description="the exposure as GNSS (UNIX) time: t minus the station clock's measured "
        "offset from the UAV's GNSS clock (SYSTEM_TIME); null until it is measured"
    )
    frame: int = Field(description="running frame number of this run")
    status: Status = Field(description=_status_doc())
    lat: Annotated[float, Ge(-90), Le(90)] | None = Field(
        description="WGS84 latitude of the UUV, degrees (null unless status is ok)"
    )
    lon: Annotated[float, Ge(-180), Le(180)] | None = Field(
        description="WGS84 longitude of the UUV, degrees (null unless status is ok)"
    )
    alt_amsl_m: Metres = Field(
        description="the UUV's height above mean sea level, metres (the UAV autopilot's "
        "GLOBAL_POSITION_INT alt minus the UAV's height above the water and the depth)"
    )
    alt_ellipsoid_m: Metres = Field(
        description="the UUV's height above the WGS84 ellipsoid, metres: alt_amsl_m plus "
        "the geoid separation GPS_RAW_INT gives (alt_ellipsoid - alt); null when the "
        "autopilot sends no alt_ellipsoid (then only alt_amsl_m is known)"
    )
    depth_m: Metres = Field(
        description="the UUV depth used, metres below the surface (positive down)"
    )
    h_acc_m: NonNegative = Field(
        description="horizontal accuracy, metres: half the radius of the circle holding 95 % of a normal "
        "error of (sigma_n, sigma_e, cov_ne), so 2·h_acc holds 95 % whatever its shape (1.2239 sigma for a "
        "round error, 0.98 sigma along one axis); ArduPilot's EKF3 takes it as each axis's 1-sigma"
    )
    v_acc_m: NonNegative = Field(description="vertical 1-sigma accuracy, metres")
    sigma_n_m: NonNegative = Field(description="1-sigma of the north coordinate, metres")
    sigma_e_m: NonNegative = Field(description="1-sigma of the east coordinate, metres")
    cov_ne_m2: float | None = Field(
        description="north-east covariance, m² (the off-diagonal of the 2×2 "
        "horizontal covariance [[sigma_n², cov_ne], [cov_ne, sigma_e²]])"
    )
    u: float | None = Field(
        description="the UUV's pixel, right (distorted, OpenCV: the top-left pixel's centre is 0)"
    )
    v: float | None = Field(description="the UUV's pixel, down")
    north_m: Metres = Field(description="the UUV north of the UAV's reported position, metres")
    east_m: Metres = Field(description="the UUV east of the UAV's reported position, metres")
    confidence: Annotated[float, Ge(0), Le(1)] | None = Field(
        description="the tracker's confidence, 0..1, when it has one"
    )
    height_m: Metres = Field(None, description="the camera's height above the water used, metres")
    sigma_height_m: NonNegative = Field(
        None, description="1-sigma of that height as it went into h_acc_m, metres"
    )
    sigma_depth_m: NonNegative = Field(
        None,
        description="1-sigma of depth_m as it went into h_acc_m, metres: the "
        "source's, a disagreement of ArduSub's two readings, and the depth's age "
        "times the vertical speed",
    )
    sigma_time_s: NonNegative = Field(
        None,
        description="1-sigma of the frame's time against the telemetry's as it "
        "went into h_acc_m, seconds",
    )
    sigma_pixel_px: NonNegative = Field(
        None,
        description="1-sigma of each of u and v as it went into h_acc_m, "
        "pixels: the tracker's own (its match, the window it searched, the frames "
        "since its last match and since it (re)acquired the UUV; docs: explanation/tracking, "
        "'How sure the pixel is')",
    )
    sigma_uav_m: NonNegative = Field(
        None,
        description="the UAV position's horizontal 1-sigma (DRMS, its GNSS receiver's or the configured) as it "
        "went into h_acc_m, metres: an error drones under one sky (or one RTK base) share, which skyfix fuse "
        "does not average away",
    )
    height_source: str | None = Field(
        None,
        description="what measured the height within the last 30 s (docs: "
        "explanation/height): takeoff or amsl (nothing: the EKF's height), "
        "gnss_rtk, gnss, baro+gnss_rtk, baro+gnss, rangefinder, size, joined by +",
    )
    depth_source: str | None = Field(
        None,
        description="where the depth came from: skyfix (skyfix's JSON on Zenoh), "
        "session (a recording's depth.jsonl naming none), ardusub_pressure (ArduSub's "
        "depth sensor), ardusub_ekf (ArduSub's EKF, until the sensor's parameters are "
        "known), or a registered depth source's name",
    )
    time_source: str | None = Field(None, description="where the UAV link's delay came from")
    pose_source: Literal["bottom"] | None = Field(
        None,
        description="the camera's pose beyond the telemetry: bottom, its attitude and position corrected by what "
        "the static seafloor in the video told (skyfix process --pose-from-bottom); null: the telemetry's as "
        "reported, and the fields below null",
    )
    cam_err_n_deg: float | None = Field(
        None,
        description="the camera attitude error taken off the reported attitude, degrees: reported minus true "
        "as a rotation vector in NED (north and east: the tilt; down: the heading)",
    )
    cam_err_e_deg: float | None = Field(None, description="see cam_err_n_deg")
    cam_err_d_deg: float | None = Field(None, description="see cam_err_n_deg")
    sigma_tilt_deg: NonNegative = Field(
        None,
        description="the estimated tilt's 1-sigma, degrees (with the recording's thirds' spread); null: not "
        "estimated, the calibration's in h_acc_m",
    )
    sigma_yaw_deg: NonNegative = Field(
        None, description="the estimated heading's 1-sigma, degrees; null: not estimated"
    )
    walk_n_m: float | None = Field(
        None,
        description="the UAV position's correction applied, metres north (true = reported + it): the GNSS's "
        "walk about its mean over the recording (the mean itself needs a reference of known position)",
    )
    walk_e_m: float | None = Field(None, description="see walk_n_m, metres east")
    sigma_walk_m: NonNegative = Field(
        None, description="the correction's horizontal 1-sigma about the GNSS's mean, metres"
    )
    ref_offset_n_m: float | None = Field(
        None,
        description="a reference of known position's correction applied (skyfix run --reference, skyfix process "
        "--reference): the drone's absolute offset (the reference's known minus located position) added to the "
        "position, metres north; null: no correction applied (none estimated yet, or it lapsed)",
    )
    ref_offset_e_m: float | None = Field(None, description="see ref_offset_n_m, metres east")
    ref_sigma_n_m: NonNegative = Field(
        None, description="the offset's 1-sigma north, metres (in h_acc_m)"
    )
    ref_sigma_e_m: NonNegative = Field(None, description="the offset's 1-sigma east, metres")
    ref_sightings: Annotated[int, Ge(0)] | None = Field(
        None, description="the reference's sightings in the offset's window"
    )
    ref_age_s: NonNegative = Field(
        None, description="the age of the reference's last sighting at the fix's time, seconds"
    )

    @model_validator(mode="after")
    def _position_iff_ok(self):
        if (self.status == "ok") != (self.lat is not None and self.lon is not None):
            raise ValueError(f"status {self.status!r} with lat {self.lat}, lon {self.lon}")
        return self

    @classmethod
    def of(cls, fix: Fix) -> FixMessage:
        """The message of a fix (NaN → null; no position unless the status is ok)."""

        def num(name):
            x = float(getattr(fix, name))
            return x if math.isfinite(x) else None

        values = {
            name: num(name)
            for name in cls.model_fields
            if name not in ("schema_", "t", "frame", "status", "pose_source", *WORDS)
        }
        values |= {name: getattr(fix, name) or None for name in (*WORDS, "pose_source")}
        if not fix.ok:
            values["lat"] = values["lon"] = None
        return cls(schema_=FIX_SCHEMA, t=fix.t_unix, frame=fix.frame, status=fix.status, **values)

    def to_json(self) -> dict:
        return self.model_dump(mode="json", by_alias=True)

    def to_fix(self) -> Fix:
        """The fix this message carries (null → NaN, or "" for words; the inverse of :meth:`of`)."""
        nan = float("nan")
        kept = {f.name for f in dataclasses.fields(Fix)} - {"t_unix", "status", "frame"}
        values = {
            k: (v if v is not None else ("" if k in (*WORDS, "pose_source") else nan))
            for k, v in self.model_dump(include=kept).items()
        }
        return Fix(t_unix=self.t, status=self.status, frame=self.frame, **values)


# --- the status -----------------------------------------------------------------------------------

Age = NonNegative
LatencySource = Literal[tuple(LATENCY_SOURCES)]


class Section(BaseModel):
    """A part of the status: closed, so that a key added without its description fails the e2e test."""

    model_config = ConfigDict(extra="forbid", frozen=True)


class Clocks(Section):
    station_minus_gnss_s: float | None = Field(
        description="the station clock minus GNSS time (SYSTEM_TIME)"
    )
    gnss_clock_steps: int = Field(
        0,
        description="steps of the station clock seen against GNSS time (SYSTEM_TIME): the offset started "
        "again from the new samples",
    )
    uav_link_latency_ms: float = Field(description="the UAV link's one-way delay in use")
    uav_link_latency_source: LatencySource = Field(
        description="where it comes from: configured ([timing] mavlink_latency_s), timesync (measured), or unknown "
        "(neither: taken as 0)"
    )
    uav_link_latency_sigma_ms: float = Field(
        description="its 1-sigma in each fix's h_acc beyond [uncertainty] time_s: 0 when configured or measured, "
        "[timing] unknown_latency_sigma_s when unknown"
    )
    uav_link_latency_measured_ms: float | None = Field(
        description="what TIMESYNC measured, used or not"
    )
    uav_reboots: int = Field(
        description="autopilot reboots seen (its time_boot_ms went back; a step of the station clock is not one)"
    )
    uuv_clock_minus_station_s: float | None = Field(
        description="the UUV's clock minus the station's"
    )
    depth_aligned_by: Literal["uuv_clock", "arrival", "autopilot_clock"] | None = Field(
        description="uuv_clock: depth stamps used as they are; arrival: arrival minus depth_latency_s; "
        "autopilot_clock: ArduSub's time_boot_ms mapped by least delay, minus depth_latency_s"
    )


class HandoffStatus(Section):
    """What a reader thread handed to the event loop through its bounded queue."""

    handed: int = Field(description="items taken by the event loop")
    dropped: int = Field(
        description="items dropped, oldest first, because the event loop fell behind"
    )


class LinkStatus(Section):
    """A MAVLink link's own thread, or the Zenoh route of GPS_INPUT through BlueOS (mavlink/in)."""

    url: str
    state: Literal["up", "waiting", "down", "closed"] = Field(
        description="up: connected (or a subscriber reachable)"
    )
    state_for_s: NonNegative = Field(description="seconds in that state")
    error: str | None = Field(description="why it is not up")
    written: int = Field(description="messages written")
    heartbeats: int = Field(description="HEARTBEATs sent on it")
    peer_age_s: Age = Field(description="seconds since the other end was last heard")
    signed: bool | None = Field(None, description="MAVLink 2 signing on (MAVLink links)")
    connects: int | None = Field(None, description="connections made (MAVLink links)")
    disconnects: int | None = None
    dropped_while_down: int | None = Field(
        None, description="messages dropped while the link was down"
    )
    superseded: int | None = Field(
        None, description="messages replaced by a newer one before they were written"
    )
    outbox_dropped: int | None = None
    write_errors: int | None = None
    reads: int | None = None
    unfinished_frames: int | None = Field(None, description="datagrams ending inside a frame")
    foreign_datagrams: int | None = Field(
        None, description="udpin: datagrams from another address than the peer's, dropped unread"
    )
    peer: str | None = Field(
        None, description="udpin: the address HOST:PORT the link takes datagrams from"
    )
    relocks: int | None = Field(
        None, description="udpin: times the lock moved to a new sender (the peer silent 5 s)"
    )
    zenoh_routers: int | None = Field(
        None, description="Zenoh routers connected (zenoh:mavlink/in)"
    )
    zenoh_peers: int | None = Field(None, description="Zenoh peers connected (zenoh:mavlink/in)")
    sent_unmatched: int | None = Field(
        None, description="messages published with no subscriber reachable"
    )
    restarts: int | None = Field(
        None, description="times the link's thread failed (a bug) and started over"
    )
    failure: str | None = Field(None, description="the last such failure: its kind and message")


class GateTrackStatus(Section):
    """The gates' track of the UUV (localizer/uuv_track.py): its fixes filtered, at its last accepted fix."""

    t: float = Field(description="the last accepted fix's exposure, station clock")
    age_s: NonNegative = Field(description="seconds since then")
    lat: float = Field(
        description="the track's position, WGS84 degrees: shown, never sent (GPS_INPUT carries the "
        "measured fix)"
    )
    lon: float
    vn_mps: float = Field(description="its velocity north, m/s")
    ve_mps: float = Field(description="its velocity east, m/s")
    sigma_n_m: NonNegative = Field(
        description="1-sigma of the position north against the truth: the track's own and "
        "the error the fixes share (attitude, height, GNSS), which no filtering removes"
    )
    sigma_e_m: NonNegative = Field(description="the same, east")
    cov_ne_m2: float = Field(description="their covariance, m²")
    sigma_own_m: NonNegative = Field(
        description="how well the track knows where the fixes are (DRMS, m): what a new "
        "fix is compared with, besides its own frame-to-frame error"
    )
    sigma_vn_mps: NonNegative = Field(description="1-sigma of the velocity north")
    sigma_ve_mps: NonNegative = Field(description="1-sigma of the velocity east")


class GateChainStatus(Section):
    """A new or re-acquired target's fixes being confirmed."""

    fixes: int = Field(description="consistent fixes so far")
    span_s: NonNegative = Field(description="seconds they span")
    needed_s: float = Field(description="seconds needed (and at least 10 fixes)")


class GateExchangeStatus(Section):
    """Several UUVs: this UUV's target came near another's, and which vehicle it is has not been told yet
    (localizer/exchange.py)."""

    other: str = Field(description="the other UUV's id")
    since_t: float = Field(description="when the target came near it (exposure, station clock)")
    fixes: int = Field(description="fixes of the tracker's lock weighed since")
    evidence: float = Field(
        description="their log-likelihood ratio (nats): this UUV's own track at its own depth against the other's "
        "at the other's depth"
    )
    needed: float = Field(description="the evidence needed for a valid fix (nats)")


class GateStatus(Section):
    """The safety gates on what goes out as a valid fix (localizer/fix_gate.py): a track of the UUV."""

    max_speed_mps: float = Field(description="the UUV's top speed (--uuv-max-speed-mps)")
    max_accel_mps2: float = Field(
        description="the UUV's largest acceleration (--uuv-max-accel-mps2)"
    )
    max_h_acc_m: float
    max_age_s: float
    state: Literal[tuple(GATE_STATES)] = Field(
        description="acquiring: a new or re-acquired target's fixes are being confirmed (none valid yet); tracking: "
        "each fix is judged against the track; diverged: the fixes left the track (a jump the UUV cannot make): none "
        "is valid for 5 s, or until the target is lost or released; or a target was found where the UUV cannot be "
        "(after a loss, a selection, a restart): none of its fixes is valid until it is lost or released, or the "
        "operator confirms it"
    )
    state_since_t: float | None = Field(
        description="the fix (exposure, station clock) the state began at"
    )
    accepted: int
    rejected: dict[str, int] = Field(
        description="fixes not sent as valid, by reason: h_acc, age, out_of_order, "
        "clock (the frame's exposure moved against its arrival: a clock stepped), "
        "prediction (outside the window the telemetry predicted), innovation (off the "
        "track), diverged, reach (where the UUV cannot be since the last good fix), "
        "unconfirmed (a target not confirmed yet), exchanged (the target came near another UUV's: not told apart "
        "yet)"
    )
    last_refusal: str | None = Field(
        description="the latest refusal that says more than its reason, one line"
    )
    white_share: NonNegative = Field(
        description="the share of the fixes' claimed covariance that changes from frame "
        "to frame, measured on the fixes (null before); the rest is an error they share"
    )
    diverged_until_t: float | None = Field(description="while diverged: until when (station clock)")
    chain: GateChainStatus | None = Field(description="while acquiring: the fixes being confirmed")
    track: GateTrackStatus | None = Field(
        description="the last confirmed track (while acquiring: where the UUV was)"
    )
    reach_m: NonNegative = Field(
        description="while acquiring or diverged: how far from the track's position the UUV "
        "can be by now (top speed × the time since the last good fix)"
    )
    thrusters: Literal["idle", "pushing", "unknown"] | None = Field(
        description="whether the UUV's horizontal thrusters push now, as its autopilot's outputs say (null: not read: "
        "the depth is not ArduSub's)"
    )
    accel_bound_mps2: NonNegative = Field(
        description="the acceleration bound of the last fix judged: the UUV's, or "
        "while its thrusters were idle what the water and the drag can do"
    )
    max_reach_m: NonNegative = Field(
        None,
        description="however long since the last trusted fix, a new target further "
        "than this from it is not the UUV (--uuv-max-reach-m)",
    )
    operator_confirmed: bool = Field(
        False,
        description="the operator confirmed the target tracked now (skyfix "
        "confirm, the page's button): no reach test until it is lost or released",
    )
    clock_steps: int = Field(
        0,
        description="steps of the station clock against the monotonic clock seen between "
        "frames (the gates keep to the monotonic clock)",
    )
    last_clock_step_s: float | None = Field(None, description="the last such step (s)")
    exchange: GateExchangeStatus | None = Field(
        None,
        description="several UUVs: the target came near another UUV's and is not told apart yet (null: it is not)",
    )


class GnssStatus(Section):
    """The UAV's GNSS receiver as its newest GPS_RAW_INT says (localizer/gnss.py)."""

    fix_type: int = Field(description="GPS_FIX_TYPE: 3 3D, 4 DGPS, 5 RTK float, 6 RTK fixed")
    h_acc_m: NonNegative = Field(
        description="the receiver's horizontal accuracy, null when it gives none"
    )
    v_acc_m: NonNegative = Field(
        description="the receiver's vertical accuracy, null when it gives none"
    )
    hdop: NonNegative = Field(description="HDOP (eph / 100), null when unknown")
    vdop: NonNegative = Field(description="VDOP (epv / 100), null when unknown")
    sigma_horizontal_m: NonNegative = Field(
        description="the UAV position's 1-sigma skyfix takes from it: h_acc, else "
        "HDOP times the fix type's typical error"
    )
    sigma_vertical_m: NonNegative = Field(
        description="the GNSS altitude's 1-sigma: v_acc, else VDOP times the fix "
        "type's typical error; null without a 3D fix"
    )


class HeightSourceStatus(Section):
    """One source of the height estimate, over the history kept."""

    used: int = Field(description="measurements used")
    refused: int = Field(
        description="measurements not used: beyond 5 sigma of the estimate, or 3 after one refused"
    )
    age_s: Age = Field(description="seconds since its newest measurement")
    disagrees_m: Metres = Field(
        description="while it disagrees (3 or more refused in a row, the last within 10 s): by "
        "how much, metres; the height's sigma covers it"
    )


class HeightStatus(Section):
    """The UAV's height above the water (localizer/height.py), at the newest GLOBAL_POSITION_INT."""

    height_m: Metres = Field(
        description="the reported position's height above the water: the EKF's, corrected"
    )
    sigma_m: NonNegative = Field(description="its 1-sigma, as it goes into h_acc")
    source: str = Field(
        description="what measured it within the last 30 s (takeoff or amsl: nothing, the EKF's "
        "height by the calibration's reference; gnss_rtk, gnss, baro+gnss, rangefinder, size, joined "
        "by +)"
    )
    ekf_height_m: Metres = Field(
        description="the EKF's height by the calibration's [water] reference"
    )
    bias_m: Metres = Field(description="the EKF height's estimated error (EKF height minus true)")
    reference: Literal["takeoff", "amsl"] = Field(description="the calibration's [water] reference")
    reference_set_at: Literal["arming", "boot"] = Field(
        description="when the EKF height's reference was set: "
        "an arming seen, else the autopilot's boot"
    )
    armed: bool | None = Field(
        description="the autopilot's HEARTBEAT armed flag, null before one came"
    )
    since_reference_s: NonNegative = Field(
        description="seconds since then: the barometer's drift grows with it"
    )
    rangefinder_out_of_range: int = Field(
        description="rangefinder readings outside its range (no return from the water)"
    )
    sources: dict[str, HeightSourceStatus] = Field(description="per source word: its measurements")


class UavStatus(Section):
    """The UAV's MAVLink link."""

    url: str
    backend: Literal["mavsdk"] | None = Field(
        None, description="present with --mavlink-backend mavsdk"
    )
    sysid: int | None = Field(description="the UAV's MAVLink system id, once heard")
    clocks: Clocks
    gnss: GnssStatus | None = Field(
        None, description="the UAV's GNSS receiver, once GPS_RAW_INT came"
    )
    rate_requests: dict[str, str] | None = Field(
        None,
        description="per message: what skyfix asked for and the "
        "autopilot's answer (pymavlink backend)",
    )
    received: int = Field(description="messages received")
    bad_data: int = Field(description="undecodable frames")
    other_systems: int = Field(description="messages from other systems, ignored")
    refused: int = Field(description="samples refused (out of range, out of order)")
    age_s: dict[str, Age] = Field(description="per message type: seconds since the newest")
    rates_hz: dict[str, NonNegative] = Field(description="per message type: measured rate")
    link: LinkStatus | None = Field(None, description="the link's own state (pymavlink backend)")
    handoff: HandoffStatus | None = Field(
        None, description="messages from the link's thread (pymavlink backend)"
    )


class ArduSubParams(Section):
    """The ArduSub parameters its depth is computed with."""

    BARO_PRIMARY: int | None = Field(description="the depth sensor's barometer instance (0-based)")
    BARO_SPEC_GRAV: float | None = Field(
        description="the water's specific gravity (1.0 fresh, 1.024 sea)"
    )
    ground_pressure_pa: float | None = Field(
        description="BARO{n}_GND_PRESS of the depth sensor in use: depth zero"
    )
    pressure_message: str | None = Field(
        description="the message carrying the depth sensor's pressure"
    )
    missing: list[str] = Field(
        description="parameters not received yet (since the autopilot's boot)"
    )


class ArduSubDepthStatus(Section):
    """ArduSub's two depth readings (localizer/depth.py)."""

    params: ArduSubParams
    pressure_depth_m: float | None = Field(
        description="the newest depth from the depth sensor's pressure"
    )
    ekf_depth_m: float | None = Field(
        description="the newest depth of ArduSub's EKF (GLOBAL_POSITION_INT)"
    )
    disagreement_m: float | None = Field(
        description="pressure depth - EKF depth at the newest cross-check"
    )
    vertical_speed_mps: float | None = Field(description="GLOBAL_POSITION_INT vz, positive down")
    ekf_origin_amsl_m: float | None = Field(
        description="the EKF origin's altitude (GPS_GLOBAL_ORIGIN)"
    )
    ekf_has_origin: bool | None = Field(
        description="GLOBAL_POSITION_INT alt is not 0: the EKF has an origin"
    )
    zero_not_followed_pa: float | None = Field(
        description="a ground pressure ArduSub took under water, which skyfix "
        "does not follow (nor compare the EKF's depth while it lasts)"
    )
    autopilot_reboots: int


class ThrustersStatus(Section):
    """The UUV's horizontal thrusters from ArduSub's SERVO_OUTPUT_RAW (localizer/thrusters.py)."""

    state: Literal["idle", "pushing", "unknown"] = Field(
        description="idle: every horizontal motor's pulse within the "
        "deadband of 1500 µs; unknown: see why_unknown, or no fresh "
        "outputs"
    )
    why_unknown: str | None = Field(description="why the horizontal motors' channels are not known")
    frame: int | None = Field(description="FRAME_CONFIG (1: vectored, 2: vectored 6DOF)")
    channels: list[int] | None = Field(
        description="the output channels of the horizontal motors (SERVOn_FUNCTION)"
    )
    deadband_us: NonNegative = Field(
        description="pulses within this of 1500 µs do not turn a thruster"
    )
    pulses_us: list[int] | None = Field(description="the horizontal motors' newest pulses")
    received: int = Field(description="SERVO_OUTPUT_RAW messages received")
    unusable: int = Field(
        description="of them, with a horizontal motor's channel not output (0 µs)"
    )


class DepthStatus(Section):
    """The UUV's depth: skyfix JSON on Zenoh, or ArduSub's over BlueOS's Zenoh or MAVLink."""

    key: str | None = Field(
        description="the Zenoh key (blueos: the autopilot's prefix); null over MAVLink"
    )
    url: str | None = Field(description="the MAVLink link (mavlink); null over Zenoh")
    shape: str = Field(
        description="the depth source's name (depth_source): skyfix: JSON {t, depth_m}; blueos: ArduSub's MAVLink "
        "as BlueOS's mavlink-server publishes it; mavlink: ArduSub's MAVLink on a link of skyfix's own; or a "
        "registered source's own"
    )
    received: int = Field(description="payloads or messages received (of those used)")
    bad: int = Field(description="payloads or messages that could not be read")
    refused: int = Field(description="samples refused (out of range or order, clock, or a jump)")
    jumps: int = Field(description="samples refused as faster than the vehicle can dive")
    other: int = Field(description="messages of other systems or components (mavlink)")
    age_s: Age = Field(description="seconds since the newest accepted sample arrived")
    t: float | None = Field(
        description="the newest sample's time (station clock: when it was measured)"
    )
    depth_m: float | None = Field(description="the newest depth")
    sigma_m: NonNegative = Field(
        description="its 1-sigma (null: the calibration's [uncertainty] depth_m)"
    )
    source: str | None = Field(
        description="where it came from: skyfix, ardusub_pressure, ardusub_ekf, or a registered depth "
        "source's name"
    )
    vertical_speed_mps: float | None = Field(
        description="the vehicle's vertical speed, positive down (ArduSub)"
    )
    rates_hz: dict[str, NonNegative] | None = Field(
        description="per message type used: measured rate (ArduSub)"
    )
    rate_requests: dict[str, str] | None = Field(
        description="per message: what skyfix asked for, the answer"
    )
    ardusub: ArduSubDepthStatus | None = Field(description="ArduSub's readings (blueos, mavlink)")
    thrusters: ThrustersStatus | None = Field(
        None, description="ArduSub's horizontal thrusters (blueos, mavlink)"
    )
    link: LinkStatus | None = Field(description="the MAVLink link's own state (mavlink)")
    handoff: HandoffStatus | None = Field(
        None, description="samples from Zenoh's or the link's thread"
    )


class PipelineStatus(Section):
    """Frames through tracker and geometry."""

    processed: int
    dropped: int = Field(description="frames dropped because the tracker fell behind")
    queued: int
    waiting_for_telemetry: int
    held_for_telemetry: int = Field(
        description="frames that waited for attitude telemetry after them"
    )
    waited_s: NonNegative = Field(description="total time frames waited for telemetry")
    held_frames: int = Field(
        description="recent frames held so a selection can name one the operator saw"
    )
    last_status: Status | None
    statuses: dict[Status, int] = Field(description="frames per status word")


class Percentiles(Section):
    p50: float | None
    p99: float | None


class MotionLatencyStatus(Section):
    """The video's latency estimated from the image's motion against the camera attitude."""

    configured_ms: float | None = Field(description="--video-latency-ms, unless auto")
    applied_ms: float | None = Field(
        description="with auto: the estimate in use, once settled; null before (no "
        "valid fix: status latency_unsettled)"
    )
    applied_sigma_ms: float | None = Field(
        description="with auto: the 1-sigma of the settled estimate in use"
    )
    state: Literal["none", "unsettled", "settled"] = Field(
        description="none: no estimate yet; settled: the last 3 estimates (one a second) each 1-sigma ≤ 5 ms from "
        "≥ 60 frame pairs and within 5 ms of each other; unsettled: not (yet)"
    )
    frames_skipped: int = Field(description="frames not measured (the measuring thread was busy)")
    estimate_ms: float | None = Field(
        None, description="glass-to-first-packet latency the motion says"
    )
    sigma_ms: float | None = Field(None, description="its 1-sigma")
    pairs: int | None = Field(None, description="frame pairs measured")
    rms_mrad: float | None = Field(None, description="residual of the fit")
    restarts: int = Field(
        0, description="times the measuring thread failed (a bug) and started over"
    )
    failure: str | None = Field(None, description="the last such failure: its kind and message")


class LiveMosaicStatus(Section):
    """The mosaic of the bottom growing live, the page's base map (--live-mosaic)."""

    painted: int = Field(description="frames painted into the mosaic")
    skipped: int = Field(
        description="frames due while the painter was still busy with the one before"
    )
    no_pose: int = Field(description="frames due without a camera pose (no telemetry yet)")
    every_s: float = Field(
        description="seconds of video between the frames painted (--live-mosaic-every-s)"
    )
    floor_depth_m: float = Field(
        description="the floor's depth below the surface it is painted at, m"
    )
    gsd_m: float | None = Field(
        description="the mosaic's cell size, m (None before the first frame)"
    )


class BuoyStatus(Section):
    """A buoy's (or boat's) GNSS reports on the UAV's MAVLink link (--reference naming a system_id)."""

    system_id: int = Field(description="its MAVLink system id (reference.toml's system_id)")
    component_id: int | None = Field(
        description="its component id (reference.toml's component_id; null: any component)"
    )
    reports: int = Field(description="its GPS_RAW_INT taken")
    last_report_age_s: float | None = Field(
        description="seconds since the last one taken came (null: none yet)"
    )
    no_fix: int = Field(description="its reports without a 3D fix")
    refused: int = Field(
        description="its reports refused as no position (lat/lon out of range, NaN, 0/0) or with a time far "
        "from their receipt"
    )
    foreign: dict[str, int] = Field(
        description="GPS_RAW_INT of other systems (not the UAV's) refused, by 'system:component'"
    )


class ReferenceStatus(Section):
    """A reference of known position in view (--reference): a surveyed marker or a buoy reporting its GNSS; the
    drone's absolute offset it shows, added to every fix while it was seen within the window
    (groundstation/live/reference_live.py)."""

    file: str = Field(description="the reference.toml")
    kind: Literal["marker", "buoy"] = Field(
        description="marker: surveyed (lat_deg, lon_deg); buoy: its position from its GNSS reports (system_id)"
    )
    buoy: BuoyStatus | None = Field(description="the buoy's reports (null: a marker)")
    no_report: int = Field(
        description="frames due that the buoy's reports did not cover (none within 2 s around the frame)"
    )
    state: Literal["searching", "applied", "lapsed"] = Field(
        description="searching: no offset yet; applied: the offset is added to every fix now; lapsed: there was one, "
        "but too few sightings in the last window_s (the fixes are the telemetry's again)"
    )
    offset_n_m: float | None = Field(
        description="the offset now (known minus located), metres north; null unless applied"
    )
    offset_e_m: float | None = Field(description="the offset now, metres east")
    sigma_n_m: float | None = Field(description="its 1-sigma north, metres (in the fixes' h_acc)")
    sigma_e_m: float | None = Field(description="its 1-sigma east, metres")
    sightings: int = Field(description="the marker's sightings in the last window_s")
    age_s: float | None = Field(
        description="the age of the last sighting, seconds (null: never seen)"
    )
    window_s: float = Field(description="the offset's window, seconds")
    searched: int = Field(description="frames searched for the marker")
    seen: int = Field(description="frames it was found in")
    skipped: int = Field(
        description="frames due while the search was still busy with the one before"
    )
    no_pose: int = Field(
        description="frames due without a camera pose (no telemetry yet); frames stamped before the video's "
        "latency settled are not due"
    )
    every_s: float = Field(description="seconds of video between the frames searched")
    corrected: int = Field(description="fixes the offset was added to")
    kept_own: int = Field(
        0,
        description="fixes kept as they were: their own claim (h_acc) was smaller than the corrected one's "
        "(a drone whose pose is already better than the reference's offset)",
    )


class BottomStatus(Section):
    """The drone's pose biases estimated from the static bottom, live (--pose-from-bottom;
    groundstation/live/bottom_live.py): what was estimated, how sure, and whether the fixes take it."""

    state: Literal["estimating", "applied", "lapsed"] = Field(
        description="estimating: no estimate yet; applied: the latest estimate is within its hold and each fix is "
        "made again with it where its claim is smaller; lapsed: there was one, its newest frame is now older than "
        "two windows (the fixes are the telemetry's again)"
    )
    every_s: float = Field(description="seconds of video between the frames tracked")
    window_s: float = Field(description="the seconds of video the estimate is made from")
    frames: int = Field(description="frames in the window now")
    taken: int = Field(description="frames tracked")
    skipped: int = Field(description="frames due while the tracker was busy with the one before")
    no_pose: int = Field(description="frames due without a camera pose")
    fits: int = Field(description="estimates made")
    refused: int = Field(
        description="estimates that gave none (too few features, a floor that moves, ...)"
    )
    last_refusal: str | None = Field(
        description="why the last estimate gave none (null: it gave one)"
    )
    age_s: float | None = Field(
        description="seconds from the latest estimate's newest frame to now (null: none yet)"
    )
    corrected: int = Field(description="fixes made again with the estimate")
    kept_own: int = Field(
        description="fixes kept as they were: their own claim (h_acc) was smaller than the corrected one's"
    )
    tilt_frame: Literal["camera", "body"] | None = Field(
        description="the tilt's bias frame: a stabilised gimbal's heading, or the airframe's"
    )
    tilt_applied: bool | None = Field(
        description="the tilt taken off the fixes (the bottom told it better than [uncertainty] tilt_deg)"
    )
    heading_applied: bool | None = Field(
        description="the heading taken off (told better than [uncertainty] yaw_deg)"
    )
    tilt_fwd_deg: float | None = Field(
        description="the camera's tilt error (reported minus true) about the bias frame's forward axis"
    )
    tilt_right_deg: float | None = Field(description="... about its right axis")
    sigma_tilt_deg: float | None = Field(
        description="the tilt's 1-sigma (with the window's thirds' spread)"
    )
    heading_deg: float | None = Field(description="the heading error (a compass reading high: +)")
    sigma_heading_deg: float | None = Field(description="its 1-sigma")
    per_height_deg_per_m: list[float] | None = Field(
        description="how the tilt forward, right and the heading move per metre the camera's height reads high "
        "(the floor does not tell the height: the fit takes part of a height error as tilt); the claim carries it"
    )
    walk_n_m: float | None = Field(
        description="the position correction at the window's end, north (true = reported + it), about the "
        "window's GNSS mean"
    )
    walk_e_m: float | None = Field(description="... east")
    sigma_walk_m: float | None = Field(description="its horizontal 1-sigma")
    floor_depth_m: float | None = Field(description="the floor's depth the estimate found")
    features: int | None = Field(description="floor features in the estimate")
    observations: int | None = Field(description="their observations")
    rms_px: float | None = Field(description="the fit's RMS residual, pixels")


class HeightFromSizeStatus(Section):
    """The camera's height above the water from the UUV's size in the video (--height-from-size)."""

    mode: Literal["auto", "check"]
    measured: int = Field(description="frames measured")
    rejected: dict[str, int] = Field(
        description="frames without a measurement, by why (localizer/tracking/"
        "silhouette.py REJECTIONS, no_pose)"
    )
    applied: int = Field(description="measurements handed to the height's fusion (auto)")
    bias_m: float | None = Field(
        description="the configured height minus the measured one, over the window"
    )
    sigma_m: float | None = Field(description="its 1-sigma")
    sigma_common_m: float | None = Field(
        description="... of which the error every measurement shares (the "
        "vehicle's size, the edges' bias, the depth): no average goes below it"
    )
    frames: int = Field(description="measurements in the window's estimate")
    outliers: int = Field(
        description="measurements in the window left out (more than 3 sigmas off)"
    )
    seconds: int = Field(description="seconds of the window with measurements")
    sure: bool = Field(
        description="enough measurements, agreeing, with a 1-sigma of at most 0.25 m"
    )
    at_surface_share: float | None = Field(
        description="share of the window's measurements with the UUV at the "
        "surface (top face at most 0.3 m deep: the most precise)"
    )
    last_t: float | None = Field(description="the latest measurement's frame, station clock")
    last_height_m: float | None = Field(
        description="the latest measured height of the UAV's reported position above the water"
    )
    last_sigma_m: float | None = Field(description="its 1-sigma")
    frames_skipped: int = Field(description="frames not measured: the measuring thread was busy")
    restarts: int = Field(
        0, description="times the measuring thread failed (a bug) and started over"
    )
    failure: str | None = Field(None, description="the last such failure: its kind and message")


class DatagramStatus(Section):
    """An ``rtp://`` or ``udp://`` (MPEG-TS) input, depacketized by skyfix: what the network lost, since the start."""

    lost_packets: int = Field(
        description="RTP sequence numbers never received; MPEG-TS packets missing (continuity "
        "counter gaps) or marked in error; zenoh: messages dropped while the reader was behind"
    )
    dropped_frames: int = Field(
        description="frames not decoded: damaged by a loss, or depending on one that was "
        "(until the next keyframe)"
    )
    bad_packets: int = Field(
        description="datagrams that are not RTP of the configured payload type, or not MPEG-TS; "
        "zenoh: payloads that are not foxglove.CompressedVideo in CDR"
    )


class SenderStatus(Section):
    """An ``rtp://`` or ``udp://`` input's sender lock (groundstation.runtime.sender_lock)."""

    peer: str | None = Field(
        description="the address HOST:PORT datagrams are taken from, or (zenoh:) the Zenoh ID that "
        "time-stamps the messages taken (null: none yet, or every sender)"
    )
    locked: bool = Field(description="false: peer=any, every sender's datagrams are read")
    foreign_datagrams: int = Field(description="datagrams from other senders, refused unread")
    relocks: int = Field(
        description="times the lock moved to a new sender (the peer silent for the read timeout)"
    )


class VideoStatus(Section):
    """The UAV's video stream."""

    url: str
    kind: str = Field(
        description="the input kind: udp (MPEG-TS), rtp, zenoh, sdp, rtsp, v4l2, file"
    )
    state: str = Field(description="starting, open, receiving, waiting, ended, stopped")
    frames: int
    connects: int
    age_s: Age
    decode_errors: int
    backlog: int = Field(description="packets read but not yet decoded")
    skipped_behind: int = Field(
        description="frames decoded but not used: the decoder was behind (CPU)"
    )
    latency_ms: float | None = Field(
        description="glass to first packet in use (configured, or from motion with "
        "auto); null with auto until its estimate has settled"
    )
    arrival_after_slot_ms: Percentiles = Field(
        description="how late frames arrive after their stream slot"
    )
    decode_ms: Percentiles = Field(description="decoding time per frame")
    stream_offset_s: float | None = Field(
        description="the stream clock's offset on the station clock"
    )
    error: str | None = Field(
        description="the last problem (FFmpeg's words), null once frames flow again"
    )
    latency_from_motion: MotionLatencyStatus | None = None
    restarts: int = Field(0, description="times the reader thread failed (a bug) and started over")
    failure: str | None = Field(None, description="the last such failure: its kind and message")
    handoff: HandoffStatus | None = Field(None, description="frames from the reader thread")
    rtp: DatagramStatus | None = Field(None, description="rtp:// inputs only")
    mpegts: DatagramStatus | None = Field(None, description="udp:// (MPEG-TS) inputs only")
    zenoh: DatagramStatus | None = Field(
        None, description="zenoh: inputs only (BlueOS's camera manager's messages)"
    )
    sender: SenderStatus | None = Field(None, description="rtp://, udp:// and zenoh: inputs only")


class GpsInputStatus(Section):
    """GPS_INPUT to the UUV's autopilot."""

    url: str
    sent: int
    sent_valid: int = Field(description="messages with fix_type 3")
    not_delivered: int = Field(description="messages the link could not take (down)")
    last_fix_type: int | None = Field(
        None, description="fix_type of the last message sent: 3 a fix, 1 no fix"
    )
    last_sent_t: float | None = Field(
        None, description="when the last message was sent, station clock, UNIX seconds"
    )
    no_fix_reason: Literal[tuple(NO_FIX_WHY)] | None = Field(
        None,
        description="why the last message said no fix (null when it carried a fix): a fix status word (the "
        "newest frame's), gate_<refusal> (the safety gates held the newest fix back), no_frames, no_new_fix (the "
        "last valid fix aged out and no frame came after it), stopped (groundstation/runtime/no_fix.py)",
    )
    no_fix_why: str | None = Field(None, description="the same in the operator's words")
    sent_h_acc_m: NonNegative = Field(
        None, description="h_acc_m of the fix the last message carried"
    )
    sent_fix_t: float | None = Field(
        None,
        description="exposure time of the fix the last message carried, station "
        "clock, UNIX seconds",
    )
    keep_alive_restarts: int = Field(
        0,
        description="times the keep-alive thread (the latest state again at the "
        "configured rate) failed (a bug) and started over",
    )
    keep_alive_failure: str | None = Field(
        None, description="the last such failure: its kind and message"
    )
    link: LinkStatus
    gates: GateStatus


class LatencyStatus(Section):
    """Frame arrival → GPS_INPUT sent, over the last 1000 new fixes, ms."""

    n: int
    p50_ms: NonNegative
    p99_ms: NonNegative
    max_ms: NonNegative


class RecordStatus(Section):
    """``--record``: what was written."""

    dir: str
    mavlink_frames: int
    depth_samples: int
    fixes: int
    dropped: int = Field(
        0,
        description="records left out because the writer fell behind, or fixes not later than "
        "the one before (auto applying its latency moves the frames' times back)",
    )
    error: str | None = Field(
        None, description="why the recording stopped (a full disk): nothing more is written"
    )
    video_frames: int | None = Field(None, description="frames encoded")
    video_dropped: int | None = Field(
        None, description="frames left out: the encoder fell behind, or out of order"
    )


class TrackMemoryStatus(Section):
    """The UUV's last trusted track kept on disk for the next start (groundstation/live/track_memory.py)."""

    path: str = Field(description="the file (in --state-dir)")
    written: int = Field(description="times it was written")
    read: dict | None = Field(
        description="what the start read: the track's age_s, lat, lon; null: none (or too old)"
    )
    failure: str | None = Field(description="why the last write failed; null once one succeeded")


class TargetStatus(Section):
    """The tracking session: the target's life."""

    state: Literal["awaiting_target", "tracking", "lost", "confirming", "released"]
    tracker: str = Field(description="the tracker backend")
    origin: Literal["box", "click", "prior"] | None = Field(description="how the target was chosen")
    since_t: float | None = Field(description="when the state began, station clock")
    frames_in_state: int
    status: str = Field(description="the latest frame's tracking status")
    u: float | None = Field(description="the latest pixel of the UUV (distorted)")
    v: float | None
    box: list[int] | None = Field(description="x, y, w, h of the latest match")
    confidence: float | None
    seen_t: float | None = Field(description="when the UUV was last seen, station clock")
    init_bbox: str | None = Field(
        None,
        description="how [tracker] init_bbox was taken on the first frame, checked as an operator's box: kept, "
        "snapped (off the vehicle: its outline taken), refused (no vehicle in it), unchecked (no camera pose on "
        "the first frame: checked on the first frame tracked with one, then kept, snapped or refused 'on frame N'); "
        "null: none configured, or no frame yet",
    )


class UuvPositionStatus(Section):
    """The UUV's own position estimate, where acquisition looks for it."""

    key: str | None = Field(
        description="the Zenoh key of its GLOBAL_POSITION_INT (--uuv-position-key)"
    )
    received: int
    bad: int
    unknown: int = Field(description="messages without a position (lat/lon 0/0)")
    age_s: Age
    lat: float | None
    lon: float | None
    hint: bool = Field(
        description="whether --uuv-hint gives the position until the UUV's own arrives"
    )
    sigma_m: float = Field(description="1-sigma of that position (m)")


class ControlStatus(Section):
    """The operator commands over Zenoh."""

    prefix: str
    answered: int
    refused: int


class ZenohLinkStatus(Section):
    """The Zenoh session."""

    peers: int = Field(description="peers and routers connected")


class ProcessStatus(Section):
    """The service's own use of the machine."""

    cpu_pct: NonNegative = Field(
        description="CPU, % of one core (all threads), over the last 5 s; null at first"
    )
    rss_mb: NonNegative = Field(description="resident memory, MB")


class UiStatus(Section):
    """The web page (``--ui``)."""

    url: str | None = Field(description="where it is served (without its token)")
    token: bool = Field(description="whether requests need the token")
    viewers: int = Field(description="pages open now")
    refused: int = Field(description="requests refused (no or wrong token, another site)")
    frames_encoded: int = Field(description="video frames sent to pages as JPEG")
    encode_ms: NonNegative = Field(
        description="mean CPU time to encode one, ms (the encoding thread's, last 100)"
    )


class InputsStatus(Section):
    """The inputs' sections of the status, as the watchdog judges them (groundstation/live/watchdog.py)."""

    uav: UavStatus
    depth: DepthStatus
    video: VideoStatus | None = None
    record: RecordStatus | None = None


class StatusMessage(Message):
    """The service's health, once a second; sections for optional parts only when they run."""

    schema_: Literal[STATUS_SCHEMA] = Field(
        alias="schema", description="message name and major version"
    )
    t: float = Field(description="when the status was taken, station clock, UNIX seconds")
    uav: UavStatus
    depth: DepthStatus
    height: HeightStatus | None = Field(
        None, description="the UAV's height above the water, once GLOBAL_POSITION_INT came"
    )
    pipeline: PipelineStatus
    fixes_published: int
    problems: dict[str, str] = Field(
        description="what is wrong with each input now, one line per input (uav, "
        "depth, video, zenoh; record once the recording stopped); empty when all is well"
    )
    target: TargetStatus
    uuv_position: UuvPositionStatus
    fix: FixMessage | None = Field(
        description="the latest fix message (also answered to late joiners on the fix key)"
    )
    control: ControlStatus
    zenoh: ZenohLinkStatus
    process: ProcessStatus
    video: VideoStatus | None = Field(None, description="with --video")
    height_from_size: HeightFromSizeStatus | None = Field(
        None, description="with --video, unless --height-from-size off"
    )
    live_mosaic: LiveMosaicStatus | None = Field(None, description="with --live-mosaic")
    reference: ReferenceStatus | None = Field(None, description="with --reference and --video")
    bottom: BottomStatus | None = Field(None, description="with --pose-from-bottom and --video")
    gps_input: GpsInputStatus | None = Field(None, description="with --gps-input")
    outputs: dict[str, dict[str, Any]] | None = Field(
        None,
        description="each of the UUV's outputs (outputs) by name, its own state (zenoh: key, published), "
        "but GPS_INPUT's, which is gps_input",
    )
    latency: LatencyStatus | None = Field(None, description="with --gps-input")
    record: RecordStatus | None = Field(None, description="with --record")
    track_memory: TrackMemoryStatus | None = Field(
        None, description="with --gps-input and a state folder (--state-dir, or --recordings)"
    )
    ui: UiStatus | None = Field(None, description="while the web page is served (not with --no-ui)")


# --- skyfix fuse's status ---------------------------------------------------------------------------

FUSE_STATUS_SCHEMA = "skyfix.fuse-status/1"


class FuseSourceStatus(Section):
    """One drone's fixes as the fuser takes them (groundstation/fuse/fuser.py)."""

    received: int = Field(description="fix messages received from it")
    used: int = Field(description="fusions it took part in")
    rejected: int = Field(description="fusions it was left out of: it disagreed beyond the sigmas")
    in_use: bool = Field(description="it took part in the last fusion")
    refused: dict[str, int] = Field(
        description="its ok fixes its own gates refused, by reason (as gates.rejected), "
        "and 'future': stamped ahead of the fuser's clock beyond --clock-tolerance-ms"
    )
    gate_state: Literal[tuple(GATE_STATES)] = Field(description="its own gates' state")
    last_status: Status | None = Field(description="the status of its last fix")
    age_s: Age = Field(description="seconds since its last fix arrived")
    delay_s: float | None = Field(
        description="its last fix's arrival on the fuser's clock minus the fix's time (GNSS "
        "time where it has one): the drone's latency, plus the clocks' offset without GNSS "
        "time"
    )
    time_base: Literal["gnss", "station"] | None = Field(
        description="the time its fixes are aligned by"
    )
    h_acc_m: NonNegative = Field(description="its last ok fix's h_acc_m")
    h_acc_used_m: NonNegative = Field(
        None,
        description="its claim as the last fusion weighed it, metres, as an h_acc_m: with "
        "what its fixes showed beyond it (floor_m)",
    )
    floor_m: NonNegative = Field(
        None,
        description="DRMS of what its fixes show beyond its claim, added at the last "
        "fusion: their frame-to-frame scatter beyond the whole claim, their disagreement with "
        "the other drones over the last 10 s beyond both claims",
    )


class FusionStatus(Section):
    """What the fuser did."""

    published: int = Field(description="fused messages published (ok and disagree)")
    disagreements: int = Field(
        description="fusions with no fix: the sources disagreed and nothing decided"
    )
    off_track: int = Field(
        0,
        description="fused positions beyond where the UUV can be by the fused fixes' own "
        "track: sent as off_track, no position",
    )
    output_restarts: int = Field(
        0,
        description="times the fused fixes' own track started again elsewhere: more than half of the "
        "configured drones agreed there for a second, beyond the track's reach",
    )
    configured: list[str] = Field(
        [], description="the fix keys whose fixes may be fused (--source)"
    )
    unconfigured: dict[str, int] = Field(
        {},
        description="fixes from any other key, by key (32 keys, the rest as "
        "'(others)'): counted, never fused",
    )
    last_sources: list[str] = Field(description="the sources (their fix keys) of the last fusion")
    sources: dict[str, FuseSourceStatus] = Field(description="per source, by its fix key")


class FuseInputStatus(Section):
    """The fix messages subscribed to."""

    key: str = Field(description="the key expression of the drones' fixes")
    received: int
    bad: int = Field(
        description="payloads that are not a skyfix.fix/1 message (logged, one line each kind)"
    )
    handoff: HandoffStatus | None = None


class FuseStatusMessage(Message):
    """``skyfix fuse``'s health, once a second."""

    schema_: Literal[FUSE_STATUS_SCHEMA] = Field(
        alias="schema", description="message name and major version"
    )
    t: float = Field(description="when the status was taken, the fuser's clock, UNIX seconds")
    uuv: str = Field(description="the UUV's id")
    input: FuseInputStatus
    fusion: FusionStatus
    fix: FixMessage | None = Field(
        description="the latest fused fix message (also answered to late joiners)"
    )
    gps_input: GpsInputStatus | None = Field(None, description="with --gps-input")
    control: ControlStatus
    zenoh: ZenohLinkStatus
    process: ProcessStatus

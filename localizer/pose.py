"""Everything about the camera at a frame's time: attitude, position, height, the UUV's depth, and
how sure each is.

:func:`camera_pose` aligns the telemetry to frames' station times (see
:mod:`localizer.telemetry`) and composes the camera attitude from the source the
calibration names, as rotations. A frame whose inputs are missing or too old gets
a status word and NaNs; one just past the newest sample gets an extrapolated
value with its estimated error in ``sigma_*``. The camera's angular and linear
velocity come along, so a time-alignment error can be turned into metres. The
height above the water is the EKF's corrected by :mod:`localizer.height` (the
barometer's drift, from GNSS altitudes, a rangefinder, the UUV's size), with its
sigma and source word; the UAV's horizontal sigma follows GPS_RAW_INT and the EKF's own
(:func:`localizer.gnss.position_sigma_m`).
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np

from . import attitude as att
from .calibration import UAV_HORIZONTAL_FALLBACK_M, Calibration
from .depth import frame_sigma_m
from .gnss import position_sigma_m
from .height import ekf_height_error
from .surface import height_above_surface_m
from .telemetry import DEG_PER_M, DepthSeries, Telemetry
from .timeline import BEFORE_FIRST, OK

#: Time step (s) over which the camera's angular velocity is measured.
RATE_STEP_S = 0.02
SERVO_MOUNT = 1  # ArduPilot MNT1_TYPE: servo gimbal stabilised by the autopilot


@dataclass
class CameraPose:
    """Camera state for N frames (arrays of length N)."""

    t_unix: np.ndarray  # station clock
    status: np.ndarray  # "ok" or why there is no pose (object array of str)
    R_ned_from_cv: np.ndarray  # (N, 3, 3)
    lat_deg: np.ndarray  # the UAV's reported position
    lon_deg: np.ndarray
    alt_amsl_m: np.ndarray
    cam_offset_ned_m: np.ndarray  # (N, 3) camera relative to the reported position
    uav_height_m: np.ndarray  # reported position above the water
    height_m: np.ndarray  # camera above the water
    depth_m: np.ndarray  # UUV below the water
    sigma_tilt_rad: np.ndarray  # extra 1-sigma of the camera's tilt from extrapolation or hold
    sigma_yaw_rad: np.ndarray  # ... and of its heading
    sigma_uav_m: np.ndarray  # the UAV position's horizontal 1-sigma (GNSS receiver, or configured)
    omega_ned: np.ndarray  # (N, 3) the camera's angular velocity in NED, rad/s
    velocity_ned_mps: np.ndarray  # (N, 3) the UAV's velocity in NED, m/s
    t_gnss: np.ndarray  # the frame's time as GNSS (UNIX) time; NaN without SYSTEM_TIME
    # ellipsoid minus mean sea level at the UAV (GPS_RAW_INT); NaN if unknown
    geoid_separation_m: np.ndarray
    # each input's 1-sigma as it goes into the fix's accuracy, and where the input came from (a word per frame)
    sigma_height_m: np.ndarray  # the camera's height above the water
    sigma_depth_m: np.ndarray  # the UUV's depth
    sigma_time_s: np.ndarray  # the frame's time against the telemetry's
    # object array of str: what measured the height (localizer.height), e.g. "gnss_rtk"
    height_source: np.ndarray
    depth_source: np.ndarray
    # how the frame is aligned to the telemetry: configured, timesync, motion or unknown
    time_source: np.ndarray
    # (N, 3) the attitude's error that comes with each metre the height reads high (a NED rotation vector per metre:
    # a pose from the bottom's tilt and heading take up part of a height error, groundstation.offline.bottom); 0: none
    rotation_per_height_ned: np.ndarray


def take(pose: CameraPose, idx) -> CameraPose:
    """The poses of some frames (index array or slice)."""
    return CameraPose(**{f.name: getattr(pose, f.name)[idx] for f in fields(CameraPose)})


def _mark(status, series_status, name):
    """Record the first failing input per frame as "no_<name>" or "stale_<name>"."""
    fresh = status == "ok"
    status[fresh & (series_status == BEFORE_FIRST)] = f"no_{name}"
    status[fresh & (series_status != BEFORE_FIRST) & (series_status != OK)] = f"stale_{name}"


def servo_mount(cal: Calibration, tel: Telemetry) -> bool:
    """Whether the gimbal message's roll and pitch are relative to the airframe (see ``[mount] gimbal_roll_pitch``)."""
    ref = cal.mount.gimbal_roll_pitch
    return ref == "body" or (ref == "auto" and tel.mount_type == SERVO_MOUNT)


def _rotations(cal: Calibration, tel: Telemetry, tq, status=None):
    """``(R_ned_from_gimbal, R_ned_from_body, sigma_tilt, sigma_yaw)`` at UAV-scale times ``tq``.

    ``status`` given: failing inputs at the first ``len(status)`` times are marked in it.
    """
    a, sa, ea = tel.attitude.sample(tq)
    if status is not None:
        _mark(status, sa[: len(status)], "attitude")
    R_body = att.euler_to_R(a[:, 0], a[:, 1], a[:, 2])
    sig_tilt, sig_yaw = np.hypot(ea[:, 0], ea[:, 1]), ea[:, 2].copy()
    src = cal.mount.attitude_source
    if src == "fixed":
        return (
            att.R_ned_from_fixed_mount(R_body, cal.mount.fixed_rpy_deg),
            R_body,
            sig_tilt,
            sig_yaw,
        )
    body = R_body if servo_mount(cal, tel) else None
    if src == "gimbal_device":
        g, sg, eg = tel.gimbal.sample(tq)
        R_gimbal = att.R_ned_from_gimbal_device(g[:, :4], np.nan_to_num(g[:, 4]), a[:, 2], body)
        g_tilt = g_yaw = eg[:, 0]
    else:
        g, sg, eg = tel.mount.sample(tq)
        R_gimbal = att.R_ned_from_mount_orientation(*np.degrees(g.T), a[:, 2], body)
        g_tilt, g_yaw = np.hypot(eg[:, 0], eg[:, 1]), eg[:, 2]
    if status is not None:
        _mark(status, sg[: len(status)], "gimbal")
    return R_gimbal, R_body, np.hypot(sig_tilt, g_tilt), np.hypot(sig_yaw, g_yaw)


def camera_pose(
    cal: Calibration,
    tel: Telemetry,
    t_unix,
    alignment: tuple[str, float] | None = None,
    depth: DepthSeries | None = None,
) -> CameraPose:
    """The camera at station time(s) ``t_unix`` (see the module doc), with the UUV's depth from ``depth``
    (:attr:`Telemetry.depth <localizer.telemetry.Telemetry.depth>` of one UUV's telemetry; default ``tel``'s own:
    one video over several UUVs shares the UAV's telemetry and reads each UUV's depth from its own).

    The frames' alignment to the telemetry is the UAV link delay's (its source word and 1-sigma,
    :attr:`~localizer.telemetry.Telemetry.latency_source` and ``latency_sigma_s``) unless
    ``alignment`` = (word, 1-sigma s) says the frames' times were aligned otherwise (live: the video latency
    estimated from the image's motion). Either sigma adds to ``[uncertainty] time_s``.
    """
    return with_depth(
        cal, uav_pose(cal, tel, t_unix, alignment), tel.depth if depth is None else depth
    )


def uav_pose(
    cal: Calibration, tel: Telemetry, t_unix, alignment: tuple[str, float] | None = None
) -> CameraPose:
    """:func:`camera_pose` without the UUV's depth: what the UAV's telemetry says, the same for every UUV in the
    frame (computed once per frame, each UUV's depth added by :func:`with_depth`). Its depth fields are NaN and its
    status is not yet checked for the depth nor for a camera below the surface."""
    t = np.atleast_1d(np.asarray(t_unix, dtype=float))
    n = len(t)
    status = np.full(n, "ok", dtype=object)
    status[~np.isfinite(t)] = "bad_time"
    tq = tel.uav_time(t)

    # at the frames' times and RATE_STEP_S before them (the angular velocity), sampled at once
    R_gimbal, R_body, sig_tilt, sig_yaw = _rotations(
        cal, tel, np.concatenate([tq, tq - RATE_STEP_S]), status
    )
    R_body, sig_tilt, sig_yaw = R_body[:n], sig_tilt[:n], sig_yaw[:n]
    p, sp, ep = tel.position.sample(tq)
    _mark(status, sp, "position")

    R_cv, R_before = np.split(att.R_ned_from_cv(R_gimbal), 2)
    omega = np.nan_to_num(att.rotvec(R_cv @ np.swapaxes(R_before, -1, -2)) / RATE_STEP_S)
    cos_lat = np.cos(np.radians(p[:, 0]))
    velocity = np.nan_to_num(
        np.stack([p[:, 4] / DEG_PER_M, p[:, 5] * cos_lat / DEG_PER_M, -p[:, 6]], axis=-1)
    )

    gnss, _, _ = tel.gnss.sample(tq)  # h_acc, geoid separation, fix type, alt, v_acc, HDOP, VDOP
    if cal.sigmas.uav_horizontal_m is not None:
        sigma_uav = np.full(n, cal.sigmas.uav_horizontal_m)
    else:
        sigma_uav = position_sigma_m(gnss[:, 2], gnss[:, 0], gnss[:, 5])
        sigma_uav = np.where(np.isfinite(sigma_uav), sigma_uav, UAV_HORIZONTAL_FALLBACK_M)
    drift_m = np.hypot(ep[:, 0], ep[:, 1] * cos_lat) / DEG_PER_M  # extrapolated or held position
    sigma_uav = np.hypot(sigma_uav, np.nan_to_num(drift_m))
    offset_gnss = tel.station_minus_gnss_s

    offset_ned = np.einsum("nij,j->ni", R_body, np.asarray(cal.mount.camera_offset_m))
    # the barometer's drift, from GNSS, a rangefinder, ...
    height = ekf_height_error(cal.water, cal.sigmas, tel, tq)
    uav_h = (
        height_above_surface_m(
            p[:, 2], p[:, 3], cal.water.takeoff_height_above_surface_m, cal.water.surface_amsl_m
        )
        - height.bias_m
    )
    cam_h = uav_h - offset_ned[:, 2]
    sig = cal.sigmas
    time_source, sigma_alignment_s = alignment or (tel.latency_source, tel.latency_sigma_s)
    return CameraPose(
        t_unix=t,
        status=status,
        R_ned_from_cv=R_cv,
        lat_deg=p[:, 0],
        lon_deg=p[:, 1],
        alt_amsl_m=p[:, 2],
        cam_offset_ned_m=offset_ned,
        uav_height_m=uav_h,
        height_m=cam_h,
        depth_m=np.full(n, np.nan),
        sigma_tilt_rad=sig_tilt,
        sigma_yaw_rad=sig_yaw,
        sigma_uav_m=sigma_uav,
        omega_ned=omega,
        velocity_ned_mps=velocity,
        t_gnss=t - offset_gnss if offset_gnss is not None else np.full(n, np.nan),
        geoid_separation_m=gnss[:, 1],
        sigma_height_m=height.sigma_m,
        sigma_depth_m=np.full(n, np.nan),
        sigma_time_s=np.full(n, np.hypot(sig.time_s, sigma_alignment_s)),
        height_source=height.source,
        depth_source=np.full(n, "", dtype=object),
        time_source=np.full(n, time_source, dtype=object),
        rotation_per_height_ned=np.zeros((n, 3)),
    )


def with_depth(cal: Calibration, pose: CameraPose, depth: DepthSeries) -> CameraPose:
    """A :func:`uav_pose` with the UUV's depth from ``depth`` at its times: its depth fields, and its status
    checked for the depth, then for the camera below the surface (as :func:`camera_pose` says)."""
    t = pose.t_unix
    status = pose.status.copy()
    dep, sd, ed = depth.sample(t)
    _mark(status, sd, "depth")
    depth_age_s = np.maximum(0.0, t - depth.last_t) if len(depth) else np.zeros(len(t))
    sigma_depth = frame_sigma_m(dep[:, 1], dep[:, 2], ed[:, 0], depth_age_s, cal.sigmas.depth_m)
    words = np.array((*depth.words, ""), dtype=object)  # "": no depth at that frame
    depth_source = words[np.where(np.isfinite(dep[:, 3]), dep[:, 3], len(depth.words)).astype(int)]
    status[(status == "ok") & ~(pose.height_m > 0)] = "below_surface"
    return replace(
        pose, status=status, depth_m=dep[:, 0], sigma_depth_m=sigma_depth, depth_source=depth_source
    )

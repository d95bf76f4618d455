"""The fix: one typed result per frame, from tracker to every sink.

:func:`locate` turns tracked pixels and aligned camera poses into fixes. Status
words (:data:`localizer.status.STATUSES`): ``ok``; ``no_track``/``lost`` (tracker);
``bad_pixel`` (outside the image or outside the lens model);
``no_<input>``/``stale_<input>`` for attitude, position, gimbal, depth;
``below_surface``; ``no_water`` (the ray never reaches the water); ``bad_time``.

Heights: ``alt_amsl_m`` is above mean sea level as the UAV's GLOBAL_POSITION_INT
``alt`` is (the autopilot's geoid); ``alt_ellipsoid_m`` above the WGS84 ellipsoid,
from the geoid separation GPS_RAW_INT gives (``alt_ellipsoid − alt``), NaN when the
autopilot sends no ``alt_ellipsoid``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields

import numpy as np

from .calibration import Calibration
from .geodesy import ned_to_geodetic
from .pose import CameraPose
from .ray import pixel_to_offset
from .uncertainty import accuracy


@dataclass
class Fix:
    """One frame's result. Positions WGS84 degrees; altitudes metres AMSL; NaN when no fix."""

    t_unix: float  # the frame's exposure, station clock
    status: str
    u: float = float("nan")  # distorted pixel of the UUV
    v: float = float("nan")
    lat: float = float("nan")
    lon: float = float("nan")
    alt_amsl_m: float = float("nan")
    alt_ellipsoid_m: float = float("nan")  # NaN without GPS_RAW_INT alt_ellipsoid
    depth_m: float = float("nan")
    h_acc_m: float = float("nan")
    v_acc_m: float = float("nan")
    north_m: float = float("nan")  # UUV relative to the UAV's reported position
    east_m: float = float("nan")
    sigma_n_m: float = float("nan")  # 1-sigma north and east, and their covariance (m²)
    sigma_e_m: float = float("nan")
    cov_ne_m2: float = float("nan")
    t_gnss: float = float("nan")  # the exposure as GNSS (UNIX) time; NaN without SYSTEM_TIME
    height_m: float = float("nan")  # the camera's height above the water used
    # 1-sigma of the inputs as they went into h_acc_m: the height ...
    sigma_height_m: float = float("nan")
    sigma_depth_m: float = float("nan")  # ... the depth ...
    sigma_time_s: float = float("nan")  # ... and the frame's time against the telemetry
    # the tracker's 1-sigma of each of u and v as it went into h_acc_m (pixels)
    sigma_pixel_px: float = float("nan")
    # the UAV position's horizontal 1-sigma (GNSS) as it went into h_acc_m
    sigma_uav_m: float = float("nan")
    height_source: str = ""  # where each input came from (see localizer.pose.CameraPose)
    depth_source: str = ""
    time_source: str = ""
    frame: int = -1
    confidence: float = float("nan")  # tracker's, 0..1
    # the pose as estimated beyond the telemetry (groundstation.offline.bottom); "" and NaN: the telemetry's as reported
    # "bottom": the attitude and position corrected by what the static floor told
    pose_source: str = ""
    # the camera attitude error taken off (reported − true, NED rotation vector)
    cam_err_n_deg: float = float("nan")
    cam_err_e_deg: float = float("nan")
    cam_err_d_deg: float = float("nan")
    # its 1-sigmas (NaN: not estimated, the calibration's in h_acc)
    sigma_tilt_deg: float = float("nan")
    sigma_yaw_deg: float = float("nan")
    # the position correction applied (true = reported + it), about the GNSS's mean
    walk_n_m: float = float("nan")
    walk_e_m: float = float("nan")
    sigma_walk_m: float = float("nan")  # its horizontal 1-sigma
    # a reference of known position's correction applied (localizer.reference, live: groundstation.live.reference_live):
    # the drone's absolute offset (known − located) added north and east, its 1-sigma per axis (in h_acc_m), the
    # reference's sightings in its window and the age of the last one (s); NaN: no correction applied
    ref_offset_n_m: float = float("nan")
    ref_offset_e_m: float = float("nan")
    ref_sigma_n_m: float = float("nan")
    ref_sigma_e_m: float = float("nan")
    ref_sightings: float = float("nan")
    ref_age_s: float = float("nan")

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    def as_dict(self) -> dict:
        return asdict(self)


#: The columns of :class:`Fixes` that hold words, not numbers.
WORDS = ("height_source", "depth_source", "time_source")
#: The pose estimated beyond the telemetry (:class:`Fix`'s last fields; positions.csv has them only when estimated)
POSE_COLUMNS = (
    "pose_source",
    "cam_err_n_deg",
    "cam_err_e_deg",
    "cam_err_d_deg",
    "sigma_tilt_deg",
    "sigma_yaw_deg",
    "walk_n_m",
    "walk_e_m",
    "sigma_walk_m",
)
_WORD_FIELDS = ("status", "pose_source", *WORDS)  # the fields of :class:`Fix` that are words


@dataclass
class Fixes:
    """Fixes for N frames as arrays (the batched form of :class:`Fix`)."""

    t_unix: np.ndarray
    status: np.ndarray
    u: np.ndarray
    v: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    alt_amsl_m: np.ndarray
    alt_ellipsoid_m: np.ndarray
    depth_m: np.ndarray
    h_acc_m: np.ndarray
    v_acc_m: np.ndarray
    north_m: np.ndarray
    east_m: np.ndarray
    sigma_n_m: np.ndarray
    sigma_e_m: np.ndarray
    cov_ne_m2: np.ndarray
    t_gnss: np.ndarray
    height_m: np.ndarray
    sigma_height_m: np.ndarray
    sigma_depth_m: np.ndarray
    sigma_time_s: np.ndarray
    sigma_pixel_px: np.ndarray
    sigma_uav_m: np.ndarray
    height_source: np.ndarray  # object arrays of str
    depth_source: np.ndarray
    time_source: np.ndarray
    #: :data:`POSE_COLUMNS` (None: "" and NaN, nothing estimated)
    pose_source: np.ndarray | None = None
    cam_err_n_deg: np.ndarray | None = None
    cam_err_e_deg: np.ndarray | None = None
    cam_err_d_deg: np.ndarray | None = None
    sigma_tilt_deg: np.ndarray | None = None
    sigma_yaw_deg: np.ndarray | None = None
    walk_n_m: np.ndarray | None = None
    walk_e_m: np.ndarray | None = None
    sigma_walk_m: np.ndarray | None = None

    def __post_init__(self):
        n = len(self.t_unix)
        for name in POSE_COLUMNS:
            if getattr(self, name) is None:
                word = name == "pose_source"
                setattr(
                    self, name, np.full(n, "" if word else np.nan, dtype=object if word else float)
                )

    @classmethod
    def of(cls, t_unix, status, **columns) -> Fixes:
        """Fixes from some columns; the others NaN, or "" for words (a positions.csv from another tool, a test)."""
        t = np.asarray(t_unix, dtype=float)
        out = {}
        for f in fields(cls):
            if f.name in ("t_unix", "status"):
                continue
            word = f.name in (*WORDS, "pose_source")
            default = np.full(len(t), "" if word else np.nan, dtype=object if word else float)
            out[f.name] = (
                np.asarray(columns[f.name], dtype=object if word else float)
                if f.name in columns
                else default
            )
        return cls(t_unix=t, status=np.asarray(status, dtype=object), **out)

    def __len__(self) -> int:
        return len(self.t_unix)

    def __getitem__(self, i: int) -> Fix:
        return Fix(
            **{k: (str(v[i]) if k in _WORD_FIELDS else float(v[i])) for k, v in vars(self).items()}
        )

    def each(self, indices) -> list[Fix]:
        """The :class:`Fix` of each frame of ``indices`` (``fixes[i]`` for many at once: each column converted
        once)."""
        idx = np.asarray(indices, dtype=int)
        columns = {
            k: [str(x) for x in v[idx]]
            if k in _WORD_FIELDS
            else np.asarray(v[idx], dtype=float).tolist()
            for k, v in vars(self).items()
        }
        return [Fix(**dict(zip(columns, row))) for row in zip(*columns.values())]


def locate(
    cal: Calibration,
    pose: CameraPose,
    u,
    v,
    refraction: bool = True,
    sigma_px=None,
    target_velocity_ne_mps=None,
) -> Fixes:
    """Fixes for pixels (u, v) seen at the poses' times; ``refraction=False`` is the paper's straight ray.

    Pixels that are NaN mean the tracker had nothing (status ``no_track``) unless
    the pose already failed. ``sigma_px``: the tracker's 1-sigma of each of u and v per
    pixel (scalar or shaped as ``u``); None or NaN: the calibration's ``[uncertainty] pixel_px``.
    ``target_velocity_ne_mps`` ((N, 2) m/s, or None): the UUV's own velocity per frame, which the accuracy's time
    term takes the camera's motion relative to (:func:`localizer.uncertainty.accuracy`).
    """
    u = np.atleast_1d(np.asarray(u, dtype=float))
    v = np.atleast_1d(np.asarray(v, dtype=float))
    sig_px = np.broadcast_to(
        np.asarray(cal.sigmas.pixel_px if sigma_px is None else sigma_px, dtype=float), u.shape
    )
    sig_px = np.where(np.isfinite(sig_px), sig_px, cal.sigmas.pixel_px)
    sig_px[~(np.isfinite(u) & np.isfinite(v))] = np.nan  # no pixel, no pixel error
    status = pose.status.copy()
    ok = status == "ok"
    status[ok & ~(np.isfinite(u) & np.isfinite(v))] = "no_track"
    status[
        (status == "ok")
        & ~cal.camera.contains(np.nan_to_num(u, nan=-1e9), np.nan_to_num(v, nan=-1e9))
    ] = "bad_pixel"
    n_water = cal.water.refractive_index if refraction else None

    nan = np.full(len(u), np.nan)
    lat, lon, alt, alt_ellipsoid, north, east, h_acc, v_acc, sig_n, sig_e, cov_ne = (
        nan.copy() for _ in range(11)
    )
    idx = np.flatnonzero(status == "ok")
    if len(idx):
        R = pose.R_ned_from_cv[idx]
        h = pose.height_m[idx]
        d = pose.depth_m[idx]
        off, reaches = pixel_to_offset(cal.camera, R, u[idx], v[idx], h, d, n_water)
        bad_lens = ~np.all(np.isfinite(off), axis=-1) & reaches
        status[idx[~reaches]] = "no_water"
        status[idx[bad_lens]] = "bad_pixel"
        good = reaches & ~bad_lens
        idx, off, R, h, d = idx[good], off[good], R[good], h[good], d[good]
        cam = pose.cam_offset_ned_m[idx]
        north[idx] = cam[:, 0] + off[:, 0]
        east[idx] = cam[:, 1] + off[:, 1]
        down = pose.uav_height_m[idx] + d
        lat[idx], lon[idx], _ = ned_to_geodetic(
            north[idx], east[idx], down, pose.lat_deg[idx], pose.lon_deg[idx], pose.alt_amsl_m[idx]
        )
        alt[idx] = pose.alt_amsl_m[idx] - down
        alt_ellipsoid[idx] = alt[idx] + pose.geoid_separation_m[idx]
        h_acc[idx], v_acc[idx], cov = accuracy(
            cal.camera,
            R,
            u[idx],
            v[idx],
            h,
            d,
            n_water,
            cal.sigmas,
            sigma_tilt_rad=pose.sigma_tilt_rad[idx],
            sigma_yaw_rad=pose.sigma_yaw_rad[idx],
            sigma_uav_m=pose.sigma_uav_m[idx],
            omega_ned=pose.omega_ned[idx],
            velocity_ned_mps=pose.velocity_ned_mps[idx],
            sigma_height_m=pose.sigma_height_m[idx],
            sigma_depth_m=pose.sigma_depth_m[idx],
            sigma_time_s=pose.sigma_time_s[idx],
            sigma_pixel_px=sig_px[idx],
            rotation_per_height_ned=pose.rotation_per_height_ned[idx],
            target_velocity_ne_mps=None
            if target_velocity_ne_mps is None
            else np.asarray(target_velocity_ne_mps, dtype=float)[idx],
        )
        sig_n[idx], sig_e[idx], cov_ne[idx] = (
            np.sqrt(cov[:, 0, 0]),
            np.sqrt(cov[:, 1, 1]),
            cov[:, 0, 1],
        )
    return Fixes(
        t_unix=pose.t_unix,
        status=status,
        u=u,
        v=v,
        lat=lat,
        lon=lon,
        alt_amsl_m=alt,
        alt_ellipsoid_m=alt_ellipsoid,
        depth_m=pose.depth_m.copy(),
        h_acc_m=h_acc,
        v_acc_m=v_acc,
        north_m=north,
        east_m=east,
        sigma_n_m=sig_n,
        sigma_e_m=sig_e,
        cov_ne_m2=cov_ne,
        t_gnss=pose.t_gnss.copy(),
        height_m=pose.height_m.copy(),
        sigma_height_m=pose.sigma_height_m.copy(),
        sigma_depth_m=pose.sigma_depth_m.copy(),
        sigma_time_s=pose.sigma_time_s.copy(),
        sigma_pixel_px=sig_px.copy(),
        sigma_uav_m=np.broadcast_to(np.asarray(pose.sigma_uav_m, dtype=float), u.shape).copy(),
        height_source=pose.height_source.copy(),
        depth_source=pose.depth_source.copy(),
        time_source=pose.time_source.copy(),
    )

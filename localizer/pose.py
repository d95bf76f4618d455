"""Everything about the camera at a frame's time: attitude, position, height, and the UUV's depth.

:func:`camera_pose` aligns the telemetry to frame times and composes the camera
attitude from the source the calibration names. A frame whose inputs are
missing or stale gets a status word and NaNs, never an extrapolated value.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import attitude as att
from .calibration import Calibration
from .surface import height_above_surface_m
from .telemetry import Telemetry
from .timeline import BEFORE_FIRST, OK


@dataclass
class CameraPose:
    """Camera state for N frames (arrays of length N)."""

    t_unix: np.ndarray
    status: np.ndarray  # "ok" or why there is no pose (object array of str)
    R_ned_from_cv: np.ndarray  # (N, 3, 3)
    lat_deg: np.ndarray  # the UAV's reported position
    lon_deg: np.ndarray
    alt_amsl_m: np.ndarray
    cam_offset_ned_m: np.ndarray  # (N, 3) camera relative to the reported position
    uav_height_m: np.ndarray  # reported position above the water
    height_m: np.ndarray  # camera above the water
    depth_m: np.ndarray  # UUV below the water


def _mark(status, series_status, name):
    """Record the first failing input per frame as "no_<name>" or "stale_<name>"."""
    fresh = status == "ok"
    status[fresh & (series_status == BEFORE_FIRST)] = f"no_{name}"
    status[fresh & (series_status != BEFORE_FIRST) & (series_status != OK)] = f"stale_{name}"


def camera_pose(cal: Calibration, tel: Telemetry, t_unix) -> CameraPose:
    t = np.atleast_1d(np.asarray(t_unix, dtype=float))
    n = len(t)
    status = np.full(n, "ok", dtype=object)
    status[~np.isfinite(t)] = "bad_time"
    try:
        boot = tel.clock.to_boot_s(t)
    except LookupError:
        boot = np.full(n, np.nan)
        status[status == "ok"] = "no_clock"

    a, sa = tel.attitude.sample(boot)
    _mark(status, sa, "attitude")
    p, sp = tel.position.sample(boot)
    _mark(status, sp, "position")
    dep, sd = tel.depth.sample(t)
    _mark(status, sd, "depth")

    R_body = att.euler_to_R(a[:, 0], a[:, 1], a[:, 2])
    src = cal.mount.attitude_source
    if src == "gimbal_device":
        g, sg = tel.gimbal.sample(boot)
        _mark(status, sg, "gimbal")
        R_gimbal = att.R_ned_from_gimbal_device(g[:, :4], np.nan_to_num(g[:, 4]), a[:, 2])
    elif src == "mount_orientation":
        m, sm = tel.mount.sample(boot)
        _mark(status, sm, "gimbal")
        R_gimbal = att.R_ned_from_mount_orientation(*np.degrees(m.T), a[:, 2])
    else:
        R_gimbal = att.R_ned_from_fixed_mount(R_body, cal.mount.fixed_rpy_deg)

    offset_ned = np.einsum("nij,j->ni", R_body, np.asarray(cal.mount.camera_offset_m))
    uav_h = height_above_surface_m(
        p[:, 2], p[:, 3], cal.water.takeoff_height_above_surface_m, cal.water.surface_amsl_m
    )
    cam_h = uav_h - offset_ned[:, 2]
    status[(status == "ok") & ~(cam_h > 0)] = "below_surface"
    return CameraPose(
        t_unix=t,
        status=status,
        R_ned_from_cv=att.R_ned_from_cv(R_gimbal),
        lat_deg=p[:, 0],
        lon_deg=p[:, 1],
        alt_amsl_m=p[:, 2],
        cam_offset_ned_m=offset_ned,
        uav_height_m=uav_h,
        height_m=cam_h,
        depth_m=dep[:, 0],
    )

"""ArduSub's own DataFlash log (the UUV's ``.BIN``, from its SD card or BlueOS's log folder) as the UUV's depth.

What ArduSub logs, read in ArduPilot's source (``AP_Baro::update``, ``AP_Baro::Write_Baro_instance``,
``Sub::Log_Write_Control_Tuning``) and checked on the ArduSub SITL:

- ``BARO``, one record per barometer (``I``) at 10 Hz: ``Alt`` is ArduSub's depth sensor's *altitude*,
  (ground pressure − pressure) / 9800 / ``BARO_SPEC_GRAV`` + the active altitude offset (logged as
  ``Offset``): minus the depth, metres. The depth is that of ``BARO_PRIMARY`` (the sensor ArduSub's depth
  hold and EKF use): −(``Alt`` − ``Offset``), measured at ``SMS`` (the boot ms of its sample). ``CRt``
  (m/s, up) is the primary's climb rate: the depth's vertical speed is −``CRt``. A record whose health
  (``H``) is 0 is skipped (counted in a warning).
- ``CTUN.Alt``, the inertial navigation's altitude (its EKF, metres up), is the second source: a depth further
  than :data:`~localizer.depth.DISAGREE_M` from −``CTUN.Alt`` of the same instant carries the difference in its
  sigma (:func:`~localizer.depth.crosscheck_sigma_m`, as live), counted in one warning with the largest.
- ``GPS``/``GPA`` put the log's clock on UNIX time as for the drone's log
  (:func:`~groundstation.session.dataflash.log_clock`). Under water ArduSub's only GPS is skyfix's GPS_INPUT
  (``GPS1_TYPE`` 14), whose week and ms are the fix's frame exposure: it reaches ArduSub ``GPS1_DELAY_MS`` later
  (the age the field checklist sets from the measured latency), so for a MAV GPS the clock is that much later
  than the fixes' times say. A log without GPS time has no UNIX clock: an error (give the depth as a CSV).
- ``PARM``: ``BARO_PRIMARY``, ``GPS1_TYPE``, ``GPS1_DELAY_MS``; a change of the primary's ``BARO{n}_GND_PRESS``
  after the first (a recalibration: the depths jump by it) is a warning with its time and size.

A SITL log also carries the simulator's truth (``SIM``, ``SIM2``): never read.
"""

from __future__ import annotations

from itertools import pairwise
from pathlib import Path

import numpy as np

from groundstation.session import SessionError
from groundstation.session.dataflash import first_instance, log_clock, read_records
from localizer.depth import (
    ARDUSUB_PA_PER_M,
    DEPTH_RANGE_M,
    crosscheck_sigma_m,
    ground_pressure_param,
)

COLUMNS = {
    "BARO": ("TimeUS", "I", "Alt", "CRt", "SMS", "Offset"),
    "CTUN": ("TimeUS", "Alt"),
    "GPS": ("TimeUS", "Status", "GMS", "GWk", "NSats", "HDop", "Lat", "Lng", "Alt"),
    "GPA": ("TimeUS", "SMS"),
    "PARM": ("TimeUS", "Name", "Value"),
}
GPS_TYPE_MAV = 14  # AP_GPS::GPS_TYPE_MAV: positions from GPS_INPUT


def healthy(m) -> bool:
    return bool(getattr(m, "H", getattr(m, "Health", 1)))


def read_ardusub_depth(path: Path, sigma_m: float, warnings: list[str]) -> tuple[list[dict], dict]:
    """The log's depths as ``depth.jsonl`` records (``t`` UNIX s, ``depth_m``, ``source`` ``ardusub_pressure``,
    ``vspeed_mps``, ``sigma_m`` where the EKF disagreed, ``sigma_m`` being the sensor's own 1-sigma) and what was
    found (the clock, the primary, the cross-check); warnings appended."""
    rows = read_records(path, COLUMNS)
    params: dict[str, list[tuple[float, float]]] = {}
    for m in rows["PARM"]:
        params.setdefault(m.Name, []).append((m.TimeUS / 1e6, float(m.Value)))
    primary = int(params.get("BARO_PRIMARY", [(0.0, 0.0)])[-1][1])
    baro = [m for m in rows["BARO"] if m.I == primary]
    if not baro:
        raise SessionError(
            f"{path}: no BARO records of BARO_PRIMARY = {primary}: not ArduSub's log of its depth"
        )
    sick = [m for m in baro if not healthy(m)]
    if sick:
        warnings.append(f"{path}: {len(sick)} BARO records of sensor {primary} unhealthy, skipped")
    baro = [m for m in baro if healthy(m)]
    gps_rows = first_instance(rows["GPS"])
    if not gps_rows:
        raise SessionError(
            f"{path}: no GPS records: ArduSub's clock cannot be put on UNIX time (give the depth as a "
            "CSV of UNIX times)"
        )
    _, offset_s, clock_sigma_s = log_clock(path, gps_rows, first_instance(rows["GPA"]))
    gps_type = params.get("GPS1_TYPE", params.get("GPS_TYPE", [(0.0, 0.0)]))[-1][1]
    delay_s = params.get("GPS1_DELAY_MS", params.get("GPS_DELAY_MS", [(0.0, 0.0)]))[-1][1] / 1000.0
    if gps_type == GPS_TYPE_MAV:
        offset_s += delay_s
        warnings.append(
            f"{path}: ArduSub's clock on UNIX time takes its GPS_INPUT to have arrived GPS1_DELAY_MS = "
            f"{delay_s * 1000:.0f} ms after the fixes' times (the configured delay, not measured here)"
        )
    boot_s = np.array([m.SMS / 1000.0 if m.SMS else m.TimeUS / 1e6 for m in baro])
    depth_m = -np.array([m.Alt - m.Offset for m in baro])
    vspeed_mps = -np.array([m.CRt for m in baro])
    keep = (
        np.r_[True, np.diff(boot_s) > 0]
        & (depth_m >= DEPTH_RANGE_M[0])
        & (depth_m <= DEPTH_RANGE_M[1])
    )
    if not keep.all():
        warnings.append(
            f"{path}: {int((~keep).sum())} BARO records repeat a sample time or lie out of "
            f"{DEPTH_RANGE_M}: skipped"
        )
    boot_s, depth_m, vspeed_mps = boot_s[keep], depth_m[keep], vspeed_mps[keep]
    sigma = np.full(len(depth_m), np.nan)
    crosschecked = 0
    if rows["CTUN"]:
        ctun_s = np.array([m.TimeUS / 1e6 for m in rows["CTUN"]])
        ekf_m = np.interp(boot_s, ctun_s, [-m.Alt for m in rows["CTUN"]])
        inside = (boot_s >= ctun_s[0]) & (boot_s <= ctun_s[-1])
        diff = np.where(inside, depth_m - ekf_m, 0.0)
        sigma = np.where(inside, crosscheck_sigma_m(sigma_m, diff), np.nan)
        crosschecked = int(inside.sum())
        disagree = sigma > sigma_m
        if disagree.any():
            worst = int(np.argmax(np.abs(diff)))
            warnings.append(
                f"{path}: ArduSub's pressure depth and its EKF's disagree in {int(disagree.sum())} of "
                f"{crosschecked} records (at most {diff[worst]:+.2f} m, boot {boot_s[worst]:.1f} s): the "
                "difference is in those depths' sigma"
            )
        sigma = np.where(disagree, sigma, np.nan)
    ground = params.get(ground_pressure_param(primary), [])
    for (_, before), (t, after) in pairwise(ground):
        if after != before:
            warnings.append(
                f"{path}: {ground_pressure_param(primary)} {before:.1f} → {after:.1f} Pa at boot {t:.1f} s "
                f"(recalibrated): ArduSub's depths jump by {(before - after) / ARDUSUB_PA_PER_M:+.2f} m "
                "(fresh-water metres) there"
            )
    records = [
        {
            "t": round(float(b + offset_s), 6),
            "depth_m": round(float(d), 4),
            "source": "ardusub_pressure",
            "vspeed_mps": round(float(v), 4),
        }
        | ({"sigma_m": round(float(s), 4)} if np.isfinite(s) else {})
        for b, d, v, s in zip(boot_s, depth_m, vspeed_mps, sigma, strict=True)
    ]
    found = {
        "dataflash": str(path),
        "baro_primary": primary,
        "unix_minus_boot_s": round(offset_s, 6),
        "unix_minus_boot_sigma_s": round(clock_sigma_s, 6),
        "gps_delay_s_added": round(delay_s, 3) if gps_type == GPS_TYPE_MAV else 0.0,
        "records": len(records),
        "crosschecked": crosschecked,
    }
    return records, found

"""An ArduPilot DataFlash log (``.bin`` from the SD card): what a flight's own log holds of the camera's pose.

Read through pymavlink's DataFlash reader, by each record's FMT columns (they change between
firmware versions; a missing column is an error naming it). Times are the autopilot's
``TimeUS`` (µs since boot). Used (units as ArduPilot's ``LogStructure.h`` files give them):

- ``ATT``: ``Roll``, ``Pitch``, ``Yaw`` (degrees; the body FRD against local NED: MAVLink's
  ATTITUDE in degrees);
- ``IMU`` (instance 0): ``GyrX/Y/Z``, body rates (rad/s) — ATTITUDE's rates, at each ATT
  record the nearest (a log without IMU records: the rates from the attitude's own
  differences, :func:`attitude_rates`; zero rates would bend the interpolation between
  samples and shift a video's start found from its motion by 20 ms, measured);
- ``POS``: ``Lat``, ``Lng`` (degrees), ``Alt`` (m AMSL), ``RelHomeAlt`` (m above home) —
  GLOBAL_POSITION_INT's;
- ``GPS`` (instance 0) and ``GPA``: ``GWk``/``GMS`` (GPS week and ms of week) of each fix,
  ``GPA.SMS`` the boot ms it arrived at (ArduPilot's real-time clock takes a fix's time as the
  time it arrived, as SYSTEM_TIME then says): the log's clock to UNIX time
  (:attr:`FlightLog.unix_minus_boot_s`, the median over 3D fixes, its spread as its
  sigma); ``Status``, ``NSats``, ``HDop``, ``Alt``, ``GPA.HAcc``/``VAcc``;
- ``MNT`` (instance 0, ``AP_Mount``'s ``Write_MountStatus``): ``Roll`` and ``Pitch`` the
  camera's earth-frame angles, ``YawB`` its yaw relative to the vehicle, ``YawE`` from North
  (degrees) — MOUNT_ORIENTATION's roll, pitch, yaw and yaw_absolute;
- ``RFND``: ``Dist`` (m) of the downward rangefinder (``Orient`` 25), when logged;
- ``CAM`` and ``TRIG``: the boot times the camera was triggered;
- ``ARM`` (``ArmState``), or on older firmware ``EV`` 10/11: when it armed and disarmed;
  ``PARM``: the parameters (``MNT1_TYPE`` says what the gimbal reports).

A SITL log also carries the simulator's own truth (``SIM``, ``SIM2``, ``SITL``): never read.
"""

from __future__ import annotations

import contextlib
import io
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from groundstation.mavlink.ingest import mavutil
from groundstation.session import SessionError

GPS_EPOCH_UNIX = 315964800.0  # 1980-01-06T00:00:00Z
LEAP_S = 18.0  # GPS − UTC since 2017-01-01
MIN_3D_STATUS = 3  # AP_GPS GPS_OK_FIX_3D and better
WHOLE_MS_SIGMA_S = 0.001 * math.sqrt(2.0 / 12.0)  # the difference of two times rounded to whole ms
DOWNWARD = 25  # MAV_SENSOR_ROTATION_PITCH_270
EV_ARMED, EV_DISARMED = 10, 11  # AP_Logger's LogEvent
# a binary log's first record: its header and FMT's own type (128)
BINARY_START = bytes((0xA3, 0x95, 0x80))
COLUMNS = {
    "ATT": ("TimeUS", "Roll", "Pitch", "Yaw"),
    "IMU": ("TimeUS", "GyrX", "GyrY", "GyrZ"),
    "POS": ("TimeUS", "Lat", "Lng", "Alt", "RelHomeAlt"),
    "GPS": ("TimeUS", "Status", "GMS", "GWk", "NSats", "HDop", "Lat", "Lng", "Alt"),
    "GPA": ("TimeUS", "SMS"),
    "MNT": ("TimeUS", "Roll", "Pitch", "YawB", "YawE"),
    "RFND": ("TimeUS", "Dist"),
    "CAM": ("TimeUS",),
    "TRIG": ("TimeUS",),
    "ARM": ("TimeUS", "ArmState"),
    "EV": ("TimeUS", "Id"),
    "PARM": ("TimeUS", "Name", "Value"),
}


def gps_to_unix(week: float, week_ms: float) -> float:
    """UNIX seconds of a GPS week and milliseconds of week (UTC: the 18 leap seconds taken off)."""
    return GPS_EPOCH_UNIX + week * 604800.0 + week_ms / 1000.0 - LEAP_S


@dataclass
class FlightLog:
    """The records of the module doc as arrays (times ``*_s`` in seconds since the autopilot's boot)."""

    path: Path
    att: np.ndarray  # (n, 7): t_s, roll, pitch, yaw (rad), and the body rates (rad/s)
    pos: np.ndarray  # (n, 5): t_s, lat, lon (deg), alt (m AMSL), relative alt (m)
    # (n, 10): t_s (arrival), unix_s, status, sats, hdop, alt (m), h_acc, v_acc (m; nan unknown),
    # lat, lon (deg)
    gps: np.ndarray
    # (n, 5): t_s, roll, pitch (earth frame), yaw relative to the vehicle, yaw from North (deg)
    mnt: np.ndarray
    rangefinder: np.ndarray  # (n, 2): t_s, distance (m)
    triggers_s: np.ndarray  # boot seconds of CAM / TRIG records
    armed: list[tuple[float, bool]]  # (boot s, armed) at each arming and disarming
    params: dict[str, float]
    unix_minus_boot_s: float
    unix_minus_boot_sigma_s: float
    warnings: list[str] = field(default_factory=list)

    def unix(self, boot_s):
        """UNIX seconds of boot seconds (scalar or array)."""
        return np.asarray(boot_s, dtype=float) + self.unix_minus_boot_s

    @property
    def span_unix(self) -> tuple[float, float]:
        """The UNIX times of the first and last attitude record."""
        return float(self.unix(self.att[0, 0])), float(self.unix(self.att[-1, 0]))


def attitude_rates(t_s: np.ndarray, rpy_rad: np.ndarray) -> np.ndarray:
    """Body rates (rad/s, FRD) from attitude samples alone: the rotation from each sample's neighbour before to its
    neighbour after, over the time between (one-sided at the ends)."""
    if len(t_s) < 2:
        return np.zeros((len(t_s), 3))
    R = Rotation.from_euler("ZYX", rpy_rad[:, ::-1])
    before = np.r_[0, np.arange(len(t_s) - 1)]
    after = np.r_[np.arange(1, len(t_s)), len(t_s) - 1]
    turn = (R[before].inv() * R[after]).as_rotvec()
    return turn / (t_s[after] - t_s[before])[:, None]


def _columns(reader, name: str, columns: tuple[str, ...]) -> None:
    fmt = next((f for f in reader.formats.values() if f.name == name), None)
    if fmt is None:
        return
    missing = [c for c in columns if c not in fmt.columns]
    if missing:
        raise SessionError(
            f"{name} records without {', '.join(missing)} (columns {','.join(fmt.columns)}): "
            "not a layout skyfix reads"
        )


def read_records(
    path: Path, columns: dict[str, tuple[str, ...]], warnings: list[str] | None = None
) -> dict[str, list]:
    """Every record of the kinds ``columns`` names, by kind in log order; each kind's FMT must hold the named columns.
    :class:`SessionError` (one line) for a file that is not a readable DataFlash log: one that does not begin with
    its first FMT record (:data:`BINARY_START`) is refused before pymavlink reads it. What pymavlink says of bytes it
    skips (a line per byte on stderr) becomes one line in ``warnings``."""
    if not path.is_file():
        raise SessionError(f"{path}: no such DataFlash log")
    with open(path, "rb") as f:
        start = f.read(len(BINARY_START))
    if start != BINARY_START:
        raise SessionError(
            f"{path}: not a DataFlash log (it begins {start.hex(' ') or 'empty'}, a binary log "
            f"{BINARY_START.hex(' ')})"
        )
    said = io.StringIO()
    with contextlib.redirect_stderr(said):
        try:
            reader = mavutil().mavlink_connection(str(path), zero_time_base=True)
        except Exception as e:  # noqa: BLE001 - pymavlink raises assorted errors on files it cannot read
            raise SessionError(f"{path}: not a DataFlash log ({e})") from None
        if not hasattr(reader, "formats"):
            raise SessionError(f"{path}: not a DataFlash log")
        rows: dict[str, list] = {k: [] for k in columns}
        try:
            for name, needed in columns.items():
                _columns(reader, name, needed)
            while (m := reader.recv_match(type=list(columns))) is not None:
                rows[m.get_type()].append(m)
        finally:
            reader.close()
    lines = said.getvalue().splitlines()
    if lines and warnings is not None:
        warnings.append(
            f"{path}: pymavlink skipped damaged parts of the log ({len(lines)} complaints, the first: "
            f"{lines[0]})"
        )
    return rows


def log_clock(path: Path, gps_rows: list, gpa_rows: list) -> tuple[np.ndarray, float, float]:
    """The GPS fixes as :attr:`FlightLog.gps` rows, and the log's clock to UNIX time (s) with its sigma: the median
    over 3D fixes of (the fix's GPS time − the boot time it arrived at), its spread as the sigma (at least the two
    stamps' whole milliseconds')."""
    arrival = {m.TimeUS: m.SMS / 1000.0 for m in gpa_rows}  # GPA is written with its GPS record
    acc = {m.TimeUS: (getattr(m, "HAcc", math.nan), getattr(m, "VAcc", math.nan)) for m in gpa_rows}
    gps = np.array(
        [
            [
                arrival.get(m.TimeUS, m.TimeUS / 1e6),
                gps_to_unix(m.GWk, m.GMS) if m.GWk else math.nan,
                m.Status,
                m.NSats,
                m.HDop,
                m.Alt,
                *acc.get(m.TimeUS, (math.nan, math.nan)),
                m.Lat,
                m.Lng,
            ]
            for m in gps_rows
        ]
    ).reshape(-1, 10)
    good = (gps[:, 2] >= MIN_3D_STATUS) & np.isfinite(gps[:, 1])
    if good.sum() < 2:
        raise SessionError(
            f"{path}: no GPS time (GWk/GMS of a 3D fix) in the log: its clock cannot be put on UNIX "
            "time"
        )
    offsets = gps[good, 1] - gps[good, 0]
    offset = float(np.median(offsets))
    return gps, offset, max(float(1.4826 * np.median(np.abs(offsets - offset))), WHOLE_MS_SIGMA_S)


def first_instance(rows: list) -> list:
    """The records of instance 0 (``I``) of a kind logged per instance."""
    return [m for m in rows if getattr(m, "I", 0) == 0]


def read_dataflash(path: str | Path) -> FlightLog:
    """The flight's records; :class:`SessionError` (one line) for a file that is not a usable DataFlash log."""
    path = Path(path)
    warnings: list[str] = []
    rows = read_records(path, COLUMNS, warnings)
    for kind in ("IMU", "GPS", "GPA", "MNT"):
        rows[kind] = first_instance(rows[kind])
    rows["RFND"] = [m for m in rows["RFND"] if getattr(m, "Orient", DOWNWARD) == DOWNWARD]
    for kind in ("ATT", "POS", "GPS"):
        if not rows[kind]:
            raise SessionError(f"{path}: no {kind} records: not a flight log skyfix can use")

    def t(ms) -> np.ndarray:
        return np.array([m.TimeUS for m in ms], dtype=float) / 1e6

    att_t = t(rows["ATT"])
    att = np.column_stack([att_t, np.radians([[m.Roll, m.Pitch, m.Yaw] for m in rows["ATT"]])])
    if rows["IMU"]:
        imu_t = t(rows["IMU"])
        gyro = np.array([[m.GyrX, m.GyrY, m.GyrZ] for m in rows["IMU"]])
        nearest = np.clip(np.searchsorted(imu_t, att_t), 1, len(imu_t) - 1)
        nearest -= (att_t - imu_t[nearest - 1]) < (imu_t[nearest] - att_t)
        rates = gyro[nearest]
    else:
        warnings.append(
            f"{path}: no IMU records: the attitude's body rates are taken from its own differences"
        )
        rates = attitude_rates(att_t, att[:, 1:4])
    pos = np.array([[m.TimeUS / 1e6, m.Lat, m.Lng, m.Alt, m.RelHomeAlt] for m in rows["POS"]])
    gps, offset, sigma = log_clock(path, rows["GPS"], rows["GPA"])
    mnt = np.array(
        [[m.TimeUS / 1e6, m.Roll, m.Pitch, m.YawB, m.YawE] for m in rows["MNT"]]
    ).reshape(-1, 5)
    rangefinder = np.array([[m.TimeUS / 1e6, m.Dist] for m in rows["RFND"]]).reshape(-1, 2)
    triggers = np.sort(np.concatenate([t(rows["CAM"]), t(rows["TRIG"])]))
    armed = sorted(
        [(m.TimeUS / 1e6, bool(m.ArmState)) for m in rows["ARM"]]
        or [
            (m.TimeUS / 1e6, m.Id == EV_ARMED)
            for m in rows["EV"]
            if m.Id in (EV_ARMED, EV_DISARMED)
        ]
    )
    params = {m.Name: float(m.Value) for m in rows["PARM"]}
    return FlightLog(
        path,
        np.column_stack([att, rates]),
        pos,
        gps,
        mnt,
        rangefinder,
        triggers,
        armed,
        params,
        offset,
        sigma,
        warnings,
    )

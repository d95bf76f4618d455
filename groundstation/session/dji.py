"""A DJI drone's own records: the flight record exported as CSV, and the camera's ``.SRT`` subtitles.

**The flight record CSV.** DJI's ``DJIFlightRecord_*.txt`` is encrypted; exporters write it as
CSV, one row per OSD record (10 Hz). Three header styles are read:

- dji-log-parser's (github.com/lvauvillier/dji-log-parser, ``dji-log-cli/src/exporters/csv.rs``;
  the values from ``dji-log-parser/src/frame/mod.rs`` and ``record/{osd,gimbal,custom}.rs``):
  ``CUSTOM.dateTime`` (the record's UTC time, chrono's RFC 3339 with ``Z``, millisecond
  resolution), ``OSD.latitude``, ``OSD.longitude`` (degrees; its older releases spelt the
  first ``OSD.lalitude``, also read), ``OSD.height`` (m above the take-off point),
  ``OSD.altitude`` (m: the exporter adds the home point's altitude to the height, so it is
  no GNSS altitude of its own), ``OSD.roll``, ``OSD.pitch``, ``OSD.yaw`` (degrees; the record
  stores tenths), ``GIMBAL.roll``, ``GIMBAL.pitch``, ``GIMBAL.yaw`` (degrees, tenths). Units are
  not in the header: metres and degrees, as that source says.
- PhantomHelp's (and the tools that copy it), units in the header: ``OSD.height [ft]``,
  ``OSD.altitude [ft]`` (or ``[m]``), ``OSD.yaw [360]`` (the same yaw on 0..360), and local
  times ``CUSTOM.date [local]`` (``6/11/2026``) + ``CUSTOM.updateTime [local]``
  (``1:00:00.00 PM``), after a first line ``sep=,``. A local time's zone is not in the file:
  it is given (``utc_offset_h``). In a file whose headers carry units, a length column
  without one is an error, as is a unit skyfix does not know (one line naming the column).
- Airdata's "CSV export" (told by its ``time(millisecond)`` and ``datetime(utc)`` columns). Its
  column list: Airdata's help page "Downloadable Flight Data CSV"
  (app.airdata.com/wiki/Help/Downloadable+Flight+Data+CSV, which defines the fields in words and
  gives no signs), and as exported, units in parentheses: ``(feet)``/``(mph)`` or
  ``(meters)``/``(m/s)`` by the account's setting (the whole header quoted in
  github.com/verri/m30ttools's README, in meters, and in a comment of Mick West's Sitrec next to
  its ``parseAirdataCSV``, in feet; the AirDataUAV package's README lists the same; some names
  carry a leading space, `` compass_heading(degrees)``, `` pitch(degrees)``, `` roll(degrees)``,
  as m30ttools's header and other readers' column keys show — headers are stripped here). Read:
  ``latitude``, ``longitude`` (degrees), ``height_above_takeoff(feet|meters)``,
  ``altitude_above_seaLevel(feet|meters)`` (Airdata: "altitude above sea level"; how Airdata
  obtains it is not stated), `` compass_heading(degrees)`` (Airdata: "compass direction of
  aircraft"; 0..360 or ±180 alike, wrapped to ±180), `` pitch(degrees)``, `` roll(degrees)``,
  ``gimbal_heading(degrees)`` (the camera's compass direction, 0 = North: egemose/
  DroneVideoMeasure's ``docs/source/references/drone_logfile_input_format_AirData.md``,
  example 190.9), ``gimbal_pitch(degrees)`` (0 the
  horizon, −90 straight down, same source), ``gimbal_roll(degrees)``. A length column without a
  unit in parentheses, or with one skyfix does not know, is an error naming it; an angle's unit
  must be degrees. Times: ``datetime(utc)`` is UTC in whole seconds (``%Y-%m-%d %H:%M:%S``,
  ``2023-03-02 10:10:59``: DroneVideoMeasure's reference, whose reader leaves "take into account
  the time(millisecond) column" as a TODO; an ISO-8601 zone or a fraction of a second is read
  too); ``time(millisecond)`` counts from the start of the record (Airdata:
  "total time duration of flight"; DroneVideoMeasure: since the aircraft was turned on — only
  its differences are used). A row's time is ``time(millisecond)`` on UTC: the whole seconds
  taken as truncated, every row's ``datetime − time`` bounds that offset from both sides (at
  10 Hz to 0.1 s; its half-width is the clock's sigma); a row outside the bounds is an error
  (a clock jump). If Airdata rounds the seconds instead, the record's UTC is 0.5 s late:
  its rounding is not documented. The angles are taken as DJI's own (below): compass_heading
  wrapped to ±180 is the yaw; Airdata does not say its pitch and roll signs (its help gives
  "rotation around y-axis", "around x-axis"), and no source found states them: they are
  passed as DJI's OSD.pitch/roll (FRD: nose up, right wing down positive), unconfirmed.

Frames: ``OSD.roll/pitch/yaw`` are the aircraft body (FRD) against North-East-Down, Z-Y-X
Euler angles, yaw from North, −180..180 (DJI's SDK: North 0, East 90, West −90) — MAVLink's
ATTITUDE in degrees. ``GIMBAL.roll/pitch/yaw`` are the camera's attitude against the earth:
pitch −90 looks straight down, roll and pitch against the horizon, and the yaw from North,
not from the aircraft's nose (the flight record stores the gimbal's own attitude report;
DJI's SDK support: "the yaw angle reported by the gimbal is in an absolute (Earth-fixed)
frame", dji-sdk/Onboard-SDK-ROS issue 137, and Mobile-SDK-Android-V5 issue 259:
``KeyGimbalAttitude`` yaw from true North). skyfix's MOUNT_ORIENTATION wants both yaws: the
one relative to the aircraft is ``GIMBAL.yaw − OSD.yaw`` (wrapped to ±180) at the same row —
Airdata's ``gimbal_heading − compass_heading``.

The rows become a :class:`~groundstation.session.dataflash.FlightLog`, so the session is
written as a DataFlash log's: the boot clock is the seconds since the first row, the first
row's UTC time its :attr:`~FlightLog.unix_minus_boot_s` (the record's own clock: no spread to
measure, sigma 0); ATTITUDE's body rates from the attitude's differences
(:func:`~groundstation.session.dataflash.attitude_rates`); every row with a position a GPS
row (3D fix, its UNIX time, satellites and accuracies unknown: the record has the fused
position, not the receiver's). Rows repeating a time, going back in time, or with an empty
or ``nan`` value are dropped, one warning per kind; a value that is not a number is an error.

**The camera's SRT** (one subtitle per video frame; layouts from the samples of
github.com/JuanIrache/DJI_SRT_Parser, ``samples/air2s.srt`` and ``samples/matrice_300.srt``)::

    1
    00:00:00,000 --> 00:00:00,033
    <font size="36">SrtCnt : 1, DiffTime : 33ms
    2022-08-07 13:40:40,774,808
    [iso : 100] ... [latitude: 41.424724] [longitude: 2.234156] [altitude: 117.000000] </font>

and on other models ``FrameCnt: 1, DiffTime: 33ms``, ``2023-05-14 12:34:56.789``,
``[rel_alt: 12.300 abs_alt: 564.230]``, ``[gb_yaw: -91.4 gb_pitch: -90.0 gb_roll: 0.0]``.
The subtitle's start is the frame's time in the video; the date line the camera's clock:
local time of an unknown zone (milliseconds, or ``,ms,µs``).

The older form (DJI_SRT_Parser's ``samples/sample2.SRT``; an early ``index.js`` of it reads its
``GPS`` as longitude, latitude, altitude), one subtitle a second (or a frame), no frame count::

    1
    00:00:01,000 --> 00:00:02,000
    HOME(131.1660,-25.2088) 2017.07.29 15:18:50
    GPS(131.1660,-25.2088,14) BAROMETER:0.0

Its date line (``2017.07.29 15:18:50``, on its own line or after ``HOME(...)``) is the camera's
local clock in whole seconds; each subtitle's start is taken as its time in the video (the
frame the clock line stands for is not said). ``GPS(a, b, ...)``: latitude and longitude in
either order by model (the sample above longitude first; others, ``GPS(36.6146,-6.1120,0.0M)``,
latitude first), 4 decimals (~11 m); its third number (altitude on some, 14–16 on the
sample) and ``BAROMETER`` are not used. The order is decided against the flight record
(:func:`gps_order`): both orders matched at every zone (or the given one), the one that fits
within :data:`ORDER_FIT_M` wins when the other fits at least :data:`ORDER_RATIO` times and
:data:`ORDER_MARGIN_M` worse (a latitude beyond ±90° rules an order out); else an error asking
for it (``--srt-gps-order``). The whole-second clock's fraction is left to the refinement
below: the offset found carries it, as it carries the clock's own error.

**The camera clock's zone** (:func:`srt_clock`): the SRT's per-frame positions are matched
against the flight record's at every offset of the world's time zones (−12 h to +14 h in
quarter hours), then refined within ±:data:`REFINE_S` s in :data:`REFINE_STEP_S` steps; the
residual is the RMS distance between the two tracks (m). A flight whose track fits two zones
alike (a hover) is an error: give the offset.
"""

from __future__ import annotations

import csv
import math
import re
from dataclasses import dataclass, replace
from datetime import UTC, datetime, timedelta, timezone
from pathlib import Path

import numpy as np

from groundstation.session import SessionError
from groundstation.session.dataflash import FlightLog, attitude_rates
from localizer.geodesy import geodetic_to_ned

FT_M = 0.3048
LENGTH_UNITS_M = {"m": 1.0, "meters": 1.0, "ft": FT_M, "feet": FT_M}
ANGLE_UNITS = {"deg", "°", "360"}  # [360]: PhantomHelp's 0..360 copy of an angle
FIX_3D = 3
SATS_UNKNOWN = 255  # GPS_RAW_INT satellites_visible "unknown"
#: skyfix name → (kind, the CSV's column names it may have, first preferred)
COLUMNS = {
    "lat_deg": ("angle", ("OSD.latitude", "OSD.lalitude")),
    "lon_deg": ("angle", ("OSD.longitude",)),
    "height_m": ("length", ("OSD.height",)),
    "altitude_m": ("length", ("OSD.altitude",)),
    "roll_deg": ("angle", ("OSD.roll",)),
    "pitch_deg": ("angle", ("OSD.pitch",)),
    "yaw_deg": ("angle", ("OSD.yaw",)),
    "gimbal_roll_deg": ("angle", ("GIMBAL.roll",)),
    "gimbal_pitch_deg": ("angle", ("GIMBAL.pitch",)),
    "gimbal_yaw_deg": ("angle", ("GIMBAL.yaw",)),
}
UTC_COLUMN = "CUSTOM.dateTime"
#: Airdata's CSV: skyfix name (the keys of :data:`COLUMNS`, in their order) → (kind, its column's name before the unit)
AIRDATA_COLUMNS = {
    "lat_deg": ("angle", "latitude"),
    "lon_deg": ("angle", "longitude"),
    "height_m": ("length", "height_above_takeoff"),
    "altitude_m": ("length", "altitude_above_seaLevel"),
    "roll_deg": ("angle", "roll"),
    "pitch_deg": ("angle", "pitch"),
    "yaw_deg": ("angle", "compass_heading"),
    "gimbal_roll_deg": ("angle", "gimbal_roll"),
    "gimbal_pitch_deg": ("angle", "gimbal_pitch"),
    "gimbal_yaw_deg": ("angle", "gimbal_heading"),
}
AIRDATA_TIME, AIRDATA_UTC = "time(millisecond)", "datetime(utc)"
AIRDATA_ANGLE_UNITS = {"degrees", "deg", "°"}
# how far datetime(utc) and time(millisecond) may disagree beyond the 1 s resolution
AIRDATA_CLOCK_TOLERANCE_S = 0.01
LOCAL_COLUMNS = ("CUSTOM.date [local]", "CUSTOM.updateTime [local]")
LOCAL_FORMATS = (
    "%m/%d/%Y %I:%M:%S.%f %p",
    "%m/%d/%Y %H:%M:%S.%f",
    "%m/%d/%Y %I:%M:%S %p",
    "%m/%d/%Y %H:%M:%S",
)
# every time zone's offset from UTC, quarter hours
ZONES_S = np.arange(-12 * 3600, 14 * 3600 + 1, 900)
REFINE_S = 2.0
REFINE_STEP_S = 0.01
MIN_OVERLAP = 0.5  # share of the SRT's frames that must fall within the record at an offset
MATCH_FRAMES = 400  # SRT frames used to match the tracks (evenly spread)


def split_header(header: str) -> tuple[str, str | None]:
    """``"OSD.height [ft]"`` → ``("OSD.height", "ft")``; ``"OSD.yaw"`` → ``("OSD.yaw", None)``."""
    m = re.fullmatch(r"\s*(.*?)\s*(?:\[\s*([^\]]*?)\s*\])?\s*", header)
    return m.group(1), m.group(2)


def column_scale(path: Path, header: str, kind: str, units_in_headers: bool) -> float:
    """The factor to metres (``kind`` "length") or degrees ("angle") of a column's values."""
    _, unit = split_header(header)
    if kind == "length":
        if unit is None:
            if units_in_headers:
                raise SessionError(
                    f"{path}: column {header!r}: no unit, while the other headers carry theirs "
                    f"(say [m] or [ft])"
                )
            return 1.0
        if unit.lower() not in LENGTH_UNITS_M:
            raise SessionError(
                f"{path}: column {header!r}: unknown unit {unit!r} (known: "
                f"{', '.join(LENGTH_UNITS_M)})"
            )
        return LENGTH_UNITS_M[unit.lower()]
    if unit is not None and unit not in ANGLE_UNITS:
        raise SessionError(f"{path}: column {header!r}: unknown unit {unit!r} (degrees expected)")
    return 1.0


def find_column(path: Path, headers: list[str], names: tuple[str, ...]) -> str:
    """The header of the first of ``names`` present (a unit-less or real unit before a ``[360]`` copy)."""
    for name in names:
        found = [h for h in headers if split_header(h)[0] == name]
        if found:
            return min(found, key=lambda h: split_header(h)[1] == "360")
    raise SessionError(
        f"{path}: no column {names[0]} (a DJI flight record exported by dji-log-parser or "
        "PhantomHelp has it)"
    )


def parse_number(path: Path, line: int, column: str, text: str) -> float:
    """A cell's number; NaN for an empty cell or ``nan``; :class:`SessionError` naming the cell otherwise."""
    text = text.strip()
    if text == "" or text.lower() == "nan":
        return math.nan
    try:
        return float(text)
    except ValueError:
        raise SessionError(f"{path}:{line}: {column} = {text!r}: not a number") from None


def parse_utc(path: Path, line: int, column: str, text: str) -> float:
    """UNIX seconds of an ISO-8601 time that states its zone (``2023-05-14T12:34:56.789Z``)."""
    try:
        t = datetime.fromisoformat(text.strip())
    except ValueError:
        raise SessionError(f"{path}:{line}: {column} = {text!r}: not an ISO-8601 time") from None
    if t.tzinfo is None:
        raise SessionError(
            f"{path}:{line}: {column} = {text!r}: no time zone (UTC expected, as 'Z')"
        )
    return t.timestamp()


def parse_local(path: Path, line: int, date: str, time: str, utc_offset_h: float) -> float:
    """UNIX seconds of PhantomHelp's local date and time at ``utc_offset_h`` hours east of UTC."""
    text = f"{date.strip()} {time.strip()}"
    for fmt in LOCAL_FORMATS:
        try:
            t = datetime.strptime(text, fmt)
        except ValueError:
            continue
        return t.replace(tzinfo=timezone(timedelta(hours=utc_offset_h))).timestamp()
    raise SessionError(
        f"{path}:{line}: {' + '.join(LOCAL_COLUMNS)} = {text!r}: not a date and time "
        "(6/11/2026 1:00:00.00 PM)"
    )


def clean_rows(
    path: Path,
    t_unix: np.ndarray,
    values: np.ndarray,
    line_numbers: np.ndarray,
    warnings: list[str],
) -> np.ndarray:
    """Which rows to keep: finite, each later than every row before; one warning per kind dropped."""
    finite = np.isfinite(t_unix) & np.isfinite(values).all(axis=1)
    t = np.where(finite, t_unix, -np.inf)
    before = np.maximum.accumulate(np.r_[-np.inf, t[:-1]])
    duplicate = finite & (t == before)
    backwards = finite & (t < before)
    for mask, what in (
        (~finite, "with an empty or nan value"),
        (duplicate, "repeating the time before"),
        (backwards, "earlier than a row before"),
    ):
        if mask.any():
            first = int(line_numbers[np.flatnonzero(mask)[0]])
            warnings.append(
                f"{path}: {int(mask.sum())} rows {what} dropped (the first at line {first})"
            )
    return finite & ~duplicate & ~backwards


def split_paren(header: str) -> tuple[str, str | None]:
    """Airdata's ``"height_above_takeoff(feet)"`` → ``("height_above_takeoff", "feet")``; ``"latitude"`` →
    ``("latitude", None)``."""
    m = re.fullmatch(r"\s*(.*?)\s*(?:\(\s*([^)]*?)\s*\))?\s*", header)
    return m.group(1), m.group(2)


def airdata_column(path: Path, headers: list[str], kind: str, name: str) -> tuple[str, float]:
    """The header of Airdata's column ``name`` and the factor to metres ("length") or degrees ("angle") of its
    values; :class:`SessionError` naming the column for a length without a known unit, an unknown angle unit."""
    found = [h for h in headers if split_paren(h)[0].casefold() == name.casefold()]
    if not found:
        raise SessionError(
            f"{path}: no column {name} (Airdata's CSV export has it"
            + (", with its unit: (feet) or (meters))" if kind == "length" else ")")
        )
    header = found[0]
    unit = split_paren(header)[1]
    if kind == "length":
        if unit is None or unit.lower() not in LENGTH_UNITS_M:
            raise SessionError(
                f"{path}: column {header!r}: "
                + ("no unit" if unit is None else f"unknown unit {unit!r}")
                + f" (known: {', '.join(LENGTH_UNITS_M)})"
            )
        return header, LENGTH_UNITS_M[unit.lower()]
    if unit is not None and unit.lower() not in AIRDATA_ANGLE_UNITS:
        raise SessionError(f"{path}: column {header!r}: unknown unit {unit!r} (degrees expected)")
    return header, 1.0


def parse_airdata_utc(path: Path, line: int, text: str) -> float:
    """UNIX seconds of Airdata's ``datetime(utc)`` (``2023-03-02 10:10:59``, UTC; a fraction or an ISO-8601 zone
    also read); NaN for an empty cell."""
    text = text.strip()
    if not text:
        return math.nan
    try:
        t = datetime.fromisoformat(text)
    except ValueError:
        raise SessionError(
            f"{path}:{line}: {AIRDATA_UTC} = {text!r}: not a date and time (2023-03-02 10:10:59)"
        ) from None
    return (t if t.tzinfo is not None else t.replace(tzinfo=UTC)).timestamp()


def airdata_clock(
    path: Path, utc_s: np.ndarray, record_s: np.ndarray, line_numbers: np.ndarray
) -> tuple[float, float]:
    """The UNIX time of ``time(millisecond)`` 0 and its half-uncertainty (s), from every row having both: whole
    seconds of ``datetime(utc)`` are taken as truncated (the true time within [datetime, datetime + 1 s)), so the
    rows' ``datetime − time`` bound it from both sides; times with fractions of a second are taken as they are.
    :class:`SessionError` when the two columns disagree beyond that."""
    both = np.isfinite(utc_s) & np.isfinite(record_s)
    if not both.any():
        raise SessionError(
            f"{path}: no row with both {AIRDATA_UTC} and {AIRDATA_TIME}: the record has no UTC time"
        )
    c, lines = utc_s[both] - record_s[both], line_numbers[both]
    whole = bool(np.all(np.mod(utc_s[both], 1.0) == 0.0))
    lo, hi = (float(c.max()), float(c.min()) + 1.0) if whole else (float(c.min()), float(c.max()))
    excess = lo - hi if whole else hi - lo
    if excess > AIRDATA_CLOCK_TOLERANCE_S:
        k = int(np.argmax(np.abs(c - np.median(c))))
        raise SessionError(
            f"{path}:{int(lines[k])}: {AIRDATA_UTC} and {AIRDATA_TIME} disagree with the other rows' "
            f"by {excess:.3f} s{' beyond its 1 s resolution' if whole else ''}: a clock jump?"
        )
    return (lo + hi) / 2.0, max(hi - lo, 0.0) / 2.0


def read_airdata(path: Path, headers: list[str], reader, first_line: int) -> FlightLog:
    """Airdata's CSV export (module doc) as a :class:`FlightLog`; the rows after the header from ``reader``, the
    first of them at line ``first_line``."""
    columns, scale = {}, {}
    for k, (kind, name) in AIRDATA_COLUMNS.items():
        columns[k], scale[k] = airdata_column(path, headers, kind, name)
    index = {h: i for i, h in reversed(list(enumerate(headers)))}
    record_s, utc_s, rows, line_numbers = [], [], [], []
    for line, row in enumerate(reader, start=first_line):
        if not any(cell.strip() for cell in row):
            continue
        if len(row) < len(headers):
            raise SessionError(f"{path}:{line}: {len(row)} cells, the header has {len(headers)}")
        record_s.append(parse_number(path, line, AIRDATA_TIME, row[index[AIRDATA_TIME]]) / 1000.0)
        utc_s.append(parse_airdata_utc(path, line, row[index[AIRDATA_UTC]]))
        rows.append(
            [
                parse_number(path, line, columns[k], row[index[columns[k]]]) * scale[k]
                for k in COLUMNS
            ]
        )
        line_numbers.append(line)
    if not rows:
        raise SessionError(f"{path}: no rows")
    record, lines = np.array(record_s), np.array(line_numbers)
    zero_unix, sigma = airdata_clock(path, np.array(utc_s), record, lines)
    return finish_rows(path, zero_unix + record, np.array(rows), lines, sigma)


def finish_rows(
    path: Path,
    t_unix: np.ndarray,
    values: np.ndarray,
    line_numbers: np.ndarray,
    sigma_s: float = 0.0,
) -> FlightLog:
    """The rows (UNIX times, the :data:`COLUMNS` values in metres and degrees) cleaned (:func:`clean_rows`) as a
    :class:`FlightLog` whose clock is known to ``sigma_s``."""
    warnings: list[str] = []
    keep = clean_rows(path, t_unix, values, line_numbers, warnings)
    if keep.sum() < 2:
        raise SessionError(f"{path}: fewer than 2 usable rows")
    return flight_log(
        path, t_unix[keep], dict(zip(COLUMNS, values[keep].T, strict=True)), warnings, sigma_s
    )


def wrap_deg(angle_deg):
    """Degrees onto (−180, 180]."""
    return 180.0 - np.mod(180.0 - np.asarray(angle_deg, dtype=float), 360.0)


def flight_log(
    path: Path,
    t_unix: np.ndarray,
    v: dict[str, np.ndarray],
    warnings: list[str],
    sigma_s: float = 0.0,
) -> FlightLog:
    """The record's rows (UNIX s, the :data:`COLUMNS` values in metres and degrees) as a :class:`FlightLog`."""
    t_s = t_unix - t_unix[0]
    yaw_deg, gimbal_yaw_deg = wrap_deg(v["yaw_deg"]), wrap_deg(v["gimbal_yaw_deg"])
    rpy = np.radians(np.column_stack([v["roll_deg"], v["pitch_deg"], yaw_deg]))
    att = np.column_stack([t_s, rpy, attitude_rates(t_s, rpy)])
    located = (v["lat_deg"] != 0.0) | (v["lon_deg"] != 0.0)  # DJI writes 0, 0 without a position
    if not located.any():
        raise SessionError(f"{path}: no row with a position (latitude, longitude all 0)")
    if not located.all():
        warnings.append(
            f"{path}: {int((~located).sum())} rows without a position (0, 0): no position written "
            "for them"
        )
    n = int(located.sum())
    lat, lon, alt, height = (
        v[k][located] for k in ("lat_deg", "lon_deg", "altitude_m", "height_m")
    )
    pos = np.column_stack([t_s[located], lat, lon, alt, height])
    gps = np.column_stack(
        [
            t_s[located],
            t_unix[located],
            np.full(n, FIX_3D),
            np.full(n, SATS_UNKNOWN),
            np.full(n, np.nan),
            alt,
            np.full(n, np.nan),
            np.full(n, np.nan),
            lat,
            lon,
        ]
    )
    mnt = np.column_stack(
        [
            t_s,
            v["gimbal_roll_deg"],
            v["gimbal_pitch_deg"],
            wrap_deg(gimbal_yaw_deg - yaw_deg),
            gimbal_yaw_deg,
        ]
    )
    return FlightLog(
        path,
        att,
        pos,
        gps,
        mnt,
        np.empty((0, 2)),
        np.empty(0),
        [],
        {},
        float(t_unix[0]),
        sigma_s,
        warnings,
    )


def read_dji_csv(path: str | Path, utc_offset_h: float | None = None) -> FlightLog:
    """A DJI flight record's CSV (see the module doc) as a :class:`FlightLog`; ``utc_offset_h`` the zone of a
    record that has local times only. :class:`SessionError` (one line) for a file skyfix cannot read."""
    path = Path(path)
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:
            lines = f.read().splitlines()
    except OSError as e:
        raise SessionError(f"{path}: cannot read: {e.strerror}") from None
    start = 1 if lines and lines[0].strip().lower().startswith("sep=") else 0
    reader = csv.reader(lines[start:])
    headers = [h.strip() for h in next(reader, [])]
    if AIRDATA_TIME in headers and AIRDATA_UTC in headers:
        return read_airdata(path, headers, reader, start + 2)
    units_in_headers = any(split_header(h)[1] not in (None, "360") for h in headers)
    columns = {k: find_column(path, headers, names) for k, (_, names) in COLUMNS.items()}
    scale = {k: column_scale(path, columns[k], COLUMNS[k][0], units_in_headers) for k in COLUMNS}
    index = {h: i for i, h in reversed(list(enumerate(headers)))}
    local = UTC_COLUMN not in index
    if local and not all(c in index for c in LOCAL_COLUMNS):
        raise SessionError(
            f"{path}: no column {UTC_COLUMN} (nor {' + '.join(LOCAL_COLUMNS)}): the rows have no time"
        )
    if local and utc_offset_h is None:
        raise SessionError(
            f"{path}: {LOCAL_COLUMNS[1]}: local times of a zone the file does not say: give "
            "--dji-csv-utc-offset-h (hours east of UTC)"
        )

    def time_of(row: list[str], line: int) -> float:
        if local:
            return parse_local(
                path, line, row[index[LOCAL_COLUMNS[0]]], row[index[LOCAL_COLUMNS[1]]], utc_offset_h
            )
        return parse_utc(path, line, UTC_COLUMN, row[index[UTC_COLUMN]])

    times, rows, line_numbers = [], [], []
    for line, row in enumerate(reader, start=start + 2):
        if not any(cell.strip() for cell in row):
            continue
        if len(row) < len(headers):
            raise SessionError(f"{path}:{line}: {len(row)} cells, the header has {len(headers)}")
        times.append(time_of(row, line))
        rows.append(
            [
                parse_number(path, line, columns[k], row[index[columns[k]]]) * scale[k]
                for k in COLUMNS
            ]
        )
        line_numbers.append(line)
    if not rows:
        raise SessionError(f"{path}: no rows")
    return finish_rows(path, np.array(times), np.array(rows), np.array(line_numbers))


@dataclass
class SrtTrack:
    """A DJI camera's subtitles (see the module doc); NaN where a subtitle lacks a value."""

    path: Path
    # the video frame (FrameCnt / SrtCnt − 1); the older form: the subtitle's order (from 0)
    frame: np.ndarray
    t_video_s: np.ndarray  # the subtitle's start in the video
    t_camera_s: np.ndarray  # the camera's clock, seconds since 1970-01-01 of its own (local) time
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    rel_alt_m: np.ndarray  # above the take-off point
    gimbal_ypr_deg: np.ndarray  # (n, 3) gb_yaw, gb_pitch, gb_roll
    form: str = "frame"  # "frame" (FrameCnt/SrtCnt), or "older": GPS(a, b, ...), whose order srt_clock decides —
    #                      lat_deg holds its first number, lon_deg its second, until then


SRT_TIMECODE = re.compile(r"(\d+):(\d{2}):(\d{2})[,.](\d{3})\s*-->")
SRT_COUNT = re.compile(r"(?:FrameCnt|SrtCnt)\s*:\s*(\d+)")
SRT_CLOCK = re.compile(
    r"(\d{4})-(\d{2})-(\d{2}) (\d{2}):(\d{2}):(\d{2})(?:[.,](\d{1,3}))?(?:,(\d{3}))?"
)
SRT_VALUE = re.compile(
    r"\b(latitude|longitude|longtitude|rel_alt|gb_yaw|gb_pitch|gb_roll)\s*:\s*([^\s\]]+)"
)
SRT_KEYS = {
    "latitude": 0,
    "longitude": 1,
    "longtitude": 1,
    "rel_alt": 2,
    "gb_yaw": 3,
    "gb_pitch": 4,
    "gb_roll": 5,
}
SRT_OLD_GPS = re.compile(r"\bGPS\s*\(\s*([^,()]*?)\s*,\s*([^,()]*?)\s*(?:,[^()]*)?\)")
SRT_OLD_CLOCK = re.compile(
    r"(\d{4})[.\-/](\d{1,2})[.\-/](\d{1,2})\s+(\d{1,2}):(\d{2}):(\d{2})(?:[.,](\d{1,3}))?"
)
GPS_ORDERS = (
    "lat,lon",
    "lon,lat",
)  # the older form's GPS(a, b): a latitude first, or a longitude first
# the older form: the order that fits must fit the record within this (RMS m)...
ORDER_FIT_M = 100.0
ORDER_RATIO, ORDER_MARGIN_M = 3.0, 50.0  # ...and the other must fit at least this much worse (both)


def srt_blocks(text: str):
    """``(first line number, text)`` of each subtitle: lines up to a blank one."""
    block: list[str] = []
    for number, line in enumerate(text.splitlines() + [""], start=1):
        if line.strip():
            block.append(line)
        elif block:
            yield number - len(block), "\n".join(block)
            block = []


def srt_clock_s(match: re.Match) -> float:
    """Seconds since 1970 of an SRT date line's match, its own zone taken as UTC."""
    groups = match.groups() + (None,) * (8 - len(match.groups()))
    y, mo, d, h, mi, s = (int(g) for g in groups[:6])
    ms = int(groups[6].ljust(3, "0")) if groups[6] else 0
    us = int(groups[7]) if groups[7] else 0
    return datetime(y, mo, d, h, mi, s, tzinfo=UTC).timestamp() + ms / 1e3 + us / 1e6


def old_srt_row(path: Path, first_line: int, block: str, tc: re.Match, order: int) -> list[float]:
    """A subtitle of the older form (module doc) as a row of :func:`read_srt`: its order, start, camera clock, GPS's
    first and second numbers, the rest NaN."""
    clock, gps = SRT_OLD_CLOCK.search(block, tc.end()), SRT_OLD_GPS.search(block, tc.end())
    if clock is None:
        raise SessionError(
            f"{path}:{first_line}: the older SRT form (GPS(...)) without the camera's date and time "
            "(2017.08.05 14:11:51)"
        )
    values = []
    for text in gps.groups():
        try:
            values.append(float(text))
        except ValueError:
            raise SessionError(
                f"{path}:{first_line}: GPS({gps.group(1)},{gps.group(2)},...): {text!r} is not a "
                "number"
            ) from None
    return [order, srt_start_s(tc), srt_clock_s(clock)] + values + [math.nan] * 4


def srt_start_s(tc: re.Match) -> float:
    """Seconds into the video of a subtitle's start (its ``start --> end`` line's match)."""
    return (
        int(tc.group(1)) * 3600
        + int(tc.group(2)) * 60
        + int(tc.group(3))
        + int(tc.group(4)) / 1000.0
    )


def read_srt(path: str | Path) -> SrtTrack:
    """The camera's SRT (either form of the module doc); :class:`SessionError` (one line) else."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig", errors="replace")
    except OSError as e:
        raise SessionError(f"{path}: cannot read: {e.strerror}") from None
    rows, forms = [], set()
    for first_line, block in srt_blocks(text):
        tc = SRT_TIMECODE.search(block)
        if tc is None:
            raise SessionError(
                f"{path}:{first_line}: a subtitle without its 'start --> end' line: not an SRT"
            )
        clock = SRT_CLOCK.search(block, tc.end())
        count = SRT_COUNT.search(block)
        form = (
            "frame"
            if clock is not None and count is not None
            else "older"
            if SRT_OLD_GPS.search(block, tc.end())
            else None
        )
        if form is None:
            raise SessionError(
                f"{path}:{first_line}: a subtitle without FrameCnt/SrtCnt and the camera's date and "
                "time, nor GPS(...): not a DJI camera's SRT"
            )
        forms.add(form)
        if len(forms) > 1:
            raise SessionError(
                f"{path}:{first_line}: a subtitle of the {form} form among the other form's: not one "
                "camera's SRT"
            )
        if form == "older":
            rows.append(old_srt_row(path, first_line, block, tc, len(rows)))
            continue
        row = [int(count.group(1)) - 1, srt_start_s(tc), srt_clock_s(clock)] + [math.nan] * 6
        for key, value in SRT_VALUE.findall(block[clock.end() :]):
            try:
                row[3 + SRT_KEYS[key]] = float(value)
            except ValueError:
                raise SessionError(
                    f"{path}:{first_line}: {key} = {value!r}: not a number"
                ) from None
        rows.append(row)
    if not rows:
        raise SessionError(f"{path}: no subtitles: not an SRT")
    a = np.array(rows)
    if not np.all(np.diff(a[:, 1]) > 0):
        raise SessionError(
            f"{path}: subtitle {int(np.argmin(np.diff(a[:, 1]))) + 2} starts no later than the one "
            "before"
        )
    return SrtTrack(
        path,
        a[:, 0].astype(int),
        a[:, 1],
        a[:, 2],
        a[:, 3],
        a[:, 4],
        a[:, 5],
        a[:, 6:9],
        forms.pop(),
    )


@dataclass
class SrtClock:
    """The camera clock against UTC: ``t_unix = t_camera_s − offset_s``."""

    offset_s: float
    residual_m: float  # RMS distance between the SRT's track and the record's at this offset
    frames: int  # SRT frames compared
    found: bool  # matched (else given)
    # the older form's GPS(a, b) order ("lat,lon" / "lon,lat"); None: the newer form
    gps_order: str | None = None
    # the older form: the best fit of each of GPS_ORDERS
    order_residuals_m: tuple[float, float] | None = None


def track_residual_m(srt: SrtTrack, flight: FlightLog, offsets_s: np.ndarray) -> np.ndarray:
    """RMS distance (m) between the SRT's positions (and take-off heights, where both have them) and the record's
    at the same UNIX time, for each camera-clock offset (inf where less than :data:`MIN_OVERLAP` of the frames
    fall within the record)."""
    ok = (
        np.isfinite(srt.lat_deg)
        & np.isfinite(srt.lon_deg)
        & ((srt.lat_deg != 0) | (srt.lon_deg != 0))
    )
    pick = np.flatnonzero(ok)
    pick = (
        pick[np.linspace(0, len(pick) - 1, min(len(pick), MATCH_FRAMES)).astype(int)]
        if len(pick)
        else pick
    )
    t_rec = flight.unix(flight.pos[:, 0])
    lat0, lon0 = flight.pos[0, 1], flight.pos[0, 2]
    n_rec, e_rec, _ = geodetic_to_ned(flight.pos[:, 1], flight.pos[:, 2], 0.0, lat0, lon0, 0.0)
    n_srt, e_srt, _ = geodetic_to_ned(srt.lat_deg[pick], srt.lon_deg[pick], 0.0, lat0, lon0, 0.0)
    rel = srt.rel_alt_m[pick]
    out = np.full(len(offsets_s), np.inf)
    for i, off in enumerate(np.asarray(offsets_s, dtype=float)):
        t = srt.t_camera_s[pick] - off
        inside = (t >= t_rec[0]) & (t <= t_rec[-1])
        if not len(pick) or inside.mean() < MIN_OVERLAP:
            continue
        t = t[inside]
        d2 = (n_srt[inside] - np.interp(t, t_rec, n_rec)) ** 2 + (
            e_srt[inside] - np.interp(t, t_rec, e_rec)
        ) ** 2
        dz = rel[inside] - np.interp(t, t_rec, flight.pos[:, 4])
        d2 = d2 + np.where(np.isfinite(dz), dz, 0.0) ** 2
        out[i] = float(np.sqrt(d2.mean()))
    return out


def in_order(srt: SrtTrack, order: str) -> SrtTrack:
    """The older form's track with latitude and longitude as ``order`` (one of :data:`GPS_ORDERS`) says."""
    return srt if order == "lat,lon" else replace(srt, lat_deg=srt.lon_deg, lon_deg=srt.lat_deg)


def gps_order(
    srt: SrtTrack, flight: FlightLog, utc_offset_h: float | None, given: str | None
) -> tuple[str, tuple[float, float]]:
    """The older form's GPS order: each of :data:`GPS_ORDERS` matched against the record (at every zone, or the
    given one), the one that fits within :data:`ORDER_FIT_M` while the other fits far worse; and each one's best
    residual (inf: impossible, a latitude beyond ±90°, or never within the record). ``given`` is checked the same
    way against the record, not compared. :class:`SessionError` when neither fits, or both alike."""
    offsets = ZONES_S if utc_offset_h is None else np.array([utc_offset_h * 3600.0])
    fits = []
    for order in GPS_ORDERS:
        track = in_order(srt, order)
        lat = track.lat_deg[np.isfinite(track.lat_deg)]
        fits.append(
            math.inf
            if np.any(np.abs(lat) > 90.0)
            else float(np.min(track_residual_m(track, flight, offsets)))
        )
    fit = dict(zip(GPS_ORDERS, fits, strict=True))
    text = ", ".join(f"as {o} {fit[o]:.1f} m" for o in GPS_ORDERS)
    where = "at every zone" if utc_offset_h is None else f"at UTC{utc_offset_h:+g} h"
    if given is not None:
        if not fit[given] <= ORDER_FIT_M:
            raise SessionError(
                f"{srt.path}: the older SRT form's GPS(...) read as {given} does not fit the flight "
                f"record {where} ({text}; within {ORDER_FIT_M:g} m expected)"
            )
        return given, (fits[0], fits[1])
    best, other = sorted(GPS_ORDERS, key=fit.get)
    if not fit[best] <= ORDER_FIT_M:
        raise SessionError(
            f"{srt.path}: the older SRT form's GPS(...) fits the flight record {where} in neither "
            f"order ({text}; within {ORDER_FIT_M:g} m expected): not the same flight?"
        )
    if fit[other] < max(ORDER_RATIO * fit[best], fit[best] + ORDER_MARGIN_M):
        raise SessionError(
            f"{srt.path}: the older SRT form's GPS(...) fits the flight record in either order "
            f"({text}): say which, --srt-gps-order lat,lon or lon,lat"
        )
    return best, (fits[0], fits[1])


def srt_clock(
    srt: SrtTrack, flight: FlightLog, utc_offset_h: float | None = None, order: str | None = None
) -> SrtClock:
    """The camera clock's offset from UTC: given (``utc_offset_h``, hours east), or found by matching the SRT's
    track against the record's (module doc); the older form's GPS order first (:func:`gps_order`; ``order``
    given, checked). :class:`SessionError` when nothing fits or two zones (or orders) fit alike."""
    if order is not None and order not in GPS_ORDERS:
        raise SessionError(f"options: --srt-gps-order {order!r}: one of {', '.join(GPS_ORDERS)}")
    if srt.form == "older":
        if not np.any(np.isfinite(srt.lat_deg) & ((srt.lat_deg != 0) | (srt.lon_deg != 0))):
            raise SessionError(
                f"{srt.path}: no GPS(...) position in its subtitles: its clock cannot be matched to "
                "the record"
            )
        order, fits = gps_order(srt, flight, utc_offset_h, order)
        return replace(
            match_clock(in_order(srt, order), flight, utc_offset_h),
            gps_order=order,
            order_residuals_m=fits,
        )
    return match_clock(srt, flight, utc_offset_h)


def match_clock(srt: SrtTrack, flight: FlightLog, utc_offset_h: float | None) -> SrtClock:
    """:func:`srt_clock` of a track whose latitude and longitude are known."""
    frames = int(np.sum(np.isfinite(srt.lat_deg)))
    if utc_offset_h is not None:
        offset = utc_offset_h * 3600.0
        residual = float(track_residual_m(srt, flight, [offset])[0])
        if not math.isfinite(residual):
            raise SessionError(
                f"{srt.path}: at UTC{utc_offset_h:+g} h its frames fall outside the flight record "
                f"{flight.span_unix[0]:.3f}–{flight.span_unix[1]:.3f} (UNIX s)"
            )
        return SrtClock(offset, residual, frames, False)
    if not frames:
        raise SessionError(
            f"{srt.path}: no latitude/longitude in its subtitles: its clock's zone cannot be found "
            "(give --srt-utc-offset-h)"
        )
    zones = track_residual_m(srt, flight, ZONES_S)
    rank = np.argsort(zones)
    best, second = zones[rank[0]], zones[rank[1]]
    if not math.isfinite(best):
        raise SessionError(
            f"{srt.path}: at no time zone do its frames fall within the flight record "
            f"{flight.span_unix[0]:.3f}–{flight.span_unix[1]:.3f} (UNIX s): not the same flight?"
        )
    if second < max(3.0 * best, best + 1.0):
        raise SessionError(
            f"{srt.path}: its track fits the record at UTC{ZONES_S[rank[0]] / 3600:+g} h "
            f"({best:.2f} m) and UTC{ZONES_S[rank[1]] / 3600:+g} h ({second:.2f} m) alike: give "
            "--srt-utc-offset-h"
        )
    fine = ZONES_S[rank[0]] + np.arange(-REFINE_S, REFINE_S + REFINE_STEP_S / 2, REFINE_STEP_S)
    residuals = track_residual_m(srt, flight, fine)
    k = int(np.argmin(residuals))
    return SrtClock(float(fine[k]), float(residuals[k]), frames, True)


def srt_video_start(srt: SrtTrack, clock: SrtClock) -> tuple[float, float]:
    """The video's first frame on UNIX time (the median over subtitles of camera time − offset − video time) and
    the largest departure of a subtitle from it (s)."""
    starts = srt.t_camera_s - clock.offset_s - srt.t_video_s
    start = float(np.median(starts))
    return start, float(np.max(np.abs(starts - start)))

"""A DJI drone's own records: the flight record exported as CSV, and the camera's ``.SRT`` subtitles.

**The flight record CSV.** DJI's ``DJIFlightRecord_*.txt`` is encrypted; exporters write it as
CSV, one row per OSD record (10 Hz). Two header styles are read:

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

Frames: ``OSD.roll/pitch/yaw`` are the aircraft body (FRD) against North-East-Down, Z-Y-X
Euler angles, yaw from North, −180..180 (DJI's SDK: North 0, East 90, West −90) — MAVLink's
ATTITUDE in degrees. ``GIMBAL.roll/pitch/yaw`` are the camera's attitude against the earth:
pitch −90 looks straight down, roll and pitch against the horizon, and the yaw from North,
not from the aircraft's nose (the flight record stores the gimbal's own attitude report;
DJI's SDK support: "the yaw angle reported by the gimbal is in an absolute (Earth-fixed)
frame", dji-sdk/Onboard-SDK-ROS issue 137, and Mobile-SDK-Android-V5 issue 259:
``KeyGimbalAttitude`` yaw from true North). skyfix's MOUNT_ORIENTATION wants both yaws: the
one relative to the aircraft is ``GIMBAL.yaw − OSD.yaw`` (wrapped to ±180) at the same row.

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
local time of an unknown zone (milliseconds, or ``,ms,µs``). The older form (``GPS(...)``,
``HOME(...)``, ``BAROMETER:`` lines, one subtitle per second) is not read: its samples put
latitude and longitude in either order by model, and it times no frame.

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
from dataclasses import dataclass
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
    "lat_deg": ("angle", ("OSD.latitude", "OSD.lalitude")), "lon_deg": ("angle", ("OSD.longitude",)),
    "height_m": ("length", ("OSD.height",)), "altitude_m": ("length", ("OSD.altitude",)),
    "roll_deg": ("angle", ("OSD.roll",)), "pitch_deg": ("angle", ("OSD.pitch",)), "yaw_deg": ("angle", ("OSD.yaw",)),
    "gimbal_roll_deg": ("angle", ("GIMBAL.roll",)), "gimbal_pitch_deg": ("angle", ("GIMBAL.pitch",)),
    "gimbal_yaw_deg": ("angle", ("GIMBAL.yaw",)),
}
UTC_COLUMN = "CUSTOM.dateTime"
LOCAL_COLUMNS = ("CUSTOM.date [local]", "CUSTOM.updateTime [local]")
LOCAL_FORMATS = ("%m/%d/%Y %I:%M:%S.%f %p", "%m/%d/%Y %H:%M:%S.%f", "%m/%d/%Y %I:%M:%S %p", "%m/%d/%Y %H:%M:%S")
ZONES_S = np.arange(-12 * 3600, 14 * 3600 + 1, 900)  # every time zone's offset from UTC, quarter hours
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
                raise SessionError(f"{path}: column {header!r}: no unit, while the other headers carry theirs "
                                   f"(say [m] or [ft])")
            return 1.0
        if unit.lower() not in LENGTH_UNITS_M:
            raise SessionError(f"{path}: column {header!r}: unknown unit {unit!r} (known: "
                               f"{', '.join(LENGTH_UNITS_M)})")
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
    raise SessionError(f"{path}: no column {names[0]} (a DJI flight record exported by dji-log-parser or "
                       "PhantomHelp has it)")


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
        raise SessionError(f"{path}:{line}: {column} = {text!r}: no time zone (UTC expected, as 'Z')")
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
    raise SessionError(f"{path}:{line}: {' + '.join(LOCAL_COLUMNS)} = {text!r}: not a date and time "
                       "(6/11/2026 1:00:00.00 PM)")


def clean_rows(path: Path, t_unix: np.ndarray, values: np.ndarray, line_numbers: np.ndarray,
               warnings: list[str]) -> np.ndarray:
    """Which rows to keep: finite, each later than every row before; one warning per kind dropped."""
    finite = np.isfinite(t_unix) & np.isfinite(values).all(axis=1)
    t = np.where(finite, t_unix, -np.inf)
    before = np.maximum.accumulate(np.r_[-np.inf, t[:-1]])
    duplicate = finite & (t == before)
    backwards = finite & (t < before)
    for mask, what in ((~finite, "with an empty or nan value"), (duplicate, "repeating the time before"),
                       (backwards, "earlier than a row before")):
        if mask.any():
            first = int(line_numbers[np.flatnonzero(mask)[0]])
            warnings.append(f"{path}: {int(mask.sum())} rows {what} dropped (the first at line {first})")
    return finite & ~duplicate & ~backwards


def wrap_deg(angle_deg):
    """Degrees onto (−180, 180]."""
    return 180.0 - np.mod(180.0 - np.asarray(angle_deg, dtype=float), 360.0)


def flight_log(path: Path, t_unix: np.ndarray, v: dict[str, np.ndarray], warnings: list[str]) -> FlightLog:
    """The record's rows (UNIX s, the :data:`COLUMNS` values in metres and degrees) as a :class:`FlightLog`."""
    t_s = t_unix - t_unix[0]
    yaw_deg, gimbal_yaw_deg = wrap_deg(v["yaw_deg"]), wrap_deg(v["gimbal_yaw_deg"])
    rpy = np.radians(np.column_stack([v["roll_deg"], v["pitch_deg"], yaw_deg]))
    att = np.column_stack([t_s, rpy, attitude_rates(t_s, rpy)])
    located = (v["lat_deg"] != 0.0) | (v["lon_deg"] != 0.0)  # DJI writes 0, 0 without a position
    if not located.any():
        raise SessionError(f"{path}: no row with a position (OSD.latitude, OSD.longitude all 0)")
    if not located.all():
        warnings.append(f"{path}: {int((~located).sum())} rows without a position (0, 0): no position written "
                        "for them")
    n = int(located.sum())
    lat, lon, alt, height = (v[k][located] for k in ("lat_deg", "lon_deg", "altitude_m", "height_m"))
    pos = np.column_stack([t_s[located], lat, lon, alt, height])
    gps = np.column_stack([t_s[located], t_unix[located], np.full(n, FIX_3D), np.full(n, SATS_UNKNOWN),
                           np.full(n, np.nan), alt, np.full(n, np.nan), np.full(n, np.nan), lat, lon])
    mnt = np.column_stack([t_s, v["gimbal_roll_deg"], v["gimbal_pitch_deg"],
                           wrap_deg(gimbal_yaw_deg - yaw_deg), gimbal_yaw_deg])
    return FlightLog(path, att, pos, gps, mnt, np.empty((0, 2)), np.empty(0), [], {}, float(t_unix[0]), 0.0,
                     warnings)


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
    units_in_headers = any(split_header(h)[1] not in (None, "360") for h in headers)
    columns = {k: find_column(path, headers, names) for k, (_, names) in COLUMNS.items()}
    scale = {k: column_scale(path, columns[k], COLUMNS[k][0], units_in_headers) for k in COLUMNS}
    index = {h: i for i, h in reversed(list(enumerate(headers)))}
    local = UTC_COLUMN not in index
    if local and not all(c in index for c in LOCAL_COLUMNS):
        raise SessionError(f"{path}: no column {UTC_COLUMN} (nor {' + '.join(LOCAL_COLUMNS)}): the rows have no time")
    if local and utc_offset_h is None:
        raise SessionError(f"{path}: {LOCAL_COLUMNS[1]}: local times of a zone the file does not say: give "
                           "--dji-csv-utc-offset-h (hours east of UTC)")

    def time_of(row: list[str], line: int) -> float:
        if local:
            return parse_local(path, line, row[index[LOCAL_COLUMNS[0]]], row[index[LOCAL_COLUMNS[1]]], utc_offset_h)
        return parse_utc(path, line, UTC_COLUMN, row[index[UTC_COLUMN]])

    times, rows, line_numbers = [], [], []
    for line, row in enumerate(reader, start=start + 2):
        if not any(cell.strip() for cell in row):
            continue
        if len(row) < len(headers):
            raise SessionError(f"{path}:{line}: {len(row)} cells, the header has {len(headers)}")
        times.append(time_of(row, line))
        rows.append([parse_number(path, line, columns[k], row[index[columns[k]]]) * scale[k] for k in COLUMNS])
        line_numbers.append(line)
    if not rows:
        raise SessionError(f"{path}: no rows")
    warnings: list[str] = []
    values = np.array(rows)
    keep = clean_rows(path, np.array(times), values, np.array(line_numbers), warnings)
    if keep.sum() < 2:
        raise SessionError(f"{path}: fewer than 2 usable rows")
    return flight_log(path, np.array(times)[keep], dict(zip(COLUMNS, values[keep].T, strict=True)), warnings)


@dataclass
class SrtTrack:
    """A DJI camera's per-frame subtitles (see the module doc); NaN where a subtitle lacks a value."""

    path: Path
    frame: np.ndarray  # the video frame (FrameCnt / SrtCnt − 1)
    t_video_s: np.ndarray  # the subtitle's start in the video
    t_camera_s: np.ndarray  # the camera's clock, seconds since 1970-01-01 of its own (local) time
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    rel_alt_m: np.ndarray  # above the take-off point
    gimbal_ypr_deg: np.ndarray  # (n, 3) gb_yaw, gb_pitch, gb_roll


SRT_TIMECODE = re.compile(r"(\d+):(\d{2}):(\d{2})[,.](\d{3})\s*-->")
SRT_COUNT = re.compile(r"(?:FrameCnt|SrtCnt)\s*:\s*(\d+)")
SRT_CLOCK = re.compile(r"(\d{4})-(\d{2})-(\d{2}) (\d{2}):(\d{2}):(\d{2})(?:[.,](\d{1,3}))?(?:,(\d{3}))?")
SRT_VALUE = re.compile(r"\b(latitude|longitude|longtitude|rel_alt|gb_yaw|gb_pitch|gb_roll)\s*:\s*([^\s\]]+)")
SRT_KEYS = {"latitude": 0, "longitude": 1, "longtitude": 1, "rel_alt": 2, "gb_yaw": 3, "gb_pitch": 4, "gb_roll": 5}


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
    y, mo, d, h, mi, s = (int(g) for g in match.groups()[:6])
    ms = int(match.group(7).ljust(3, "0")) if match.group(7) else 0
    us = int(match.group(8)) if match.group(8) else 0
    return datetime(y, mo, d, h, mi, s, tzinfo=UTC).timestamp() + ms / 1e3 + us / 1e6


def read_srt(path: str | Path) -> SrtTrack:
    """The camera's SRT (the modern bracketed form of the module doc); :class:`SessionError` (one line) else."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig", errors="replace")
    except OSError as e:
        raise SessionError(f"{path}: cannot read: {e.strerror}") from None
    rows = []
    for first_line, block in srt_blocks(text):
        tc = SRT_TIMECODE.search(block)
        if tc is None:
            raise SessionError(f"{path}:{first_line}: a subtitle without its 'start --> end' line: not an SRT")
        clock = SRT_CLOCK.search(block, tc.end())
        count = SRT_COUNT.search(block)
        if clock is None or count is None:
            if "GPS(" in block:
                raise SessionError(f"{path}:{first_line}: the older SRT form (GPS(...), one subtitle a second): "
                                   "not read (its latitude and longitude come in either order by model)")
            raise SessionError(f"{path}:{first_line}: a subtitle without FrameCnt/SrtCnt or the camera's date and "
                               "time: not a DJI camera's SRT")
        row = [int(count.group(1)) - 1, int(tc.group(1)) * 3600 + int(tc.group(2)) * 60 + int(tc.group(3))
               + int(tc.group(4)) / 1000.0, srt_clock_s(clock)] + [math.nan] * 6
        for key, value in SRT_VALUE.findall(block[clock.end():]):
            try:
                row[3 + SRT_KEYS[key]] = float(value)
            except ValueError:
                raise SessionError(f"{path}:{first_line}: {key} = {value!r}: not a number") from None
        rows.append(row)
    if not rows:
        raise SessionError(f"{path}: no subtitles: not an SRT")
    a = np.array(rows)
    if not np.all(np.diff(a[:, 1]) > 0):
        raise SessionError(f"{path}: subtitle {int(np.argmin(np.diff(a[:, 1]))) + 2} starts no later than the one "
                           "before")
    return SrtTrack(path, a[:, 0].astype(int), a[:, 1], a[:, 2], a[:, 3], a[:, 4], a[:, 5], a[:, 6:9])


@dataclass
class SrtClock:
    """The camera clock against UTC: ``t_unix = t_camera_s − offset_s``."""

    offset_s: float
    residual_m: float  # RMS distance between the SRT's track and the record's at this offset
    frames: int  # SRT frames compared
    found: bool  # matched (else given)


def track_residual_m(srt: SrtTrack, flight: FlightLog, offsets_s: np.ndarray) -> np.ndarray:
    """RMS distance (m) between the SRT's positions (and take-off heights, where both have them) and the record's
    at the same UNIX time, for each camera-clock offset (inf where less than :data:`MIN_OVERLAP` of the frames
    fall within the record)."""
    ok = np.isfinite(srt.lat_deg) & np.isfinite(srt.lon_deg) & ((srt.lat_deg != 0) | (srt.lon_deg != 0))
    pick = np.flatnonzero(ok)
    pick = pick[np.linspace(0, len(pick) - 1, min(len(pick), MATCH_FRAMES)).astype(int)] if len(pick) else pick
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
        d2 = (n_srt[inside] - np.interp(t, t_rec, n_rec)) ** 2 + (e_srt[inside] - np.interp(t, t_rec, e_rec)) ** 2
        dz = rel[inside] - np.interp(t, t_rec, flight.pos[:, 4])
        d2 = d2 + np.where(np.isfinite(dz), dz, 0.0) ** 2
        out[i] = float(np.sqrt(d2.mean()))
    return out


def srt_clock(srt: SrtTrack, flight: FlightLog, utc_offset_h: float | None = None) -> SrtClock:
    """The camera clock's offset from UTC: given (``utc_offset_h``, hours east), or found by matching the SRT's
    track against the record's (module doc). :class:`SessionError` when nothing fits or two zones fit alike."""
    frames = int(np.sum(np.isfinite(srt.lat_deg)))
    if utc_offset_h is not None:
        offset = utc_offset_h * 3600.0
        residual = float(track_residual_m(srt, flight, [offset])[0])
        if not math.isfinite(residual):
            raise SessionError(f"{srt.path}: at UTC{utc_offset_h:+g} h its frames fall outside the flight record "
                               f"{flight.span_unix[0]:.3f}–{flight.span_unix[1]:.3f} (UNIX s)")
        return SrtClock(offset, residual, frames, False)
    if not frames:
        raise SessionError(f"{srt.path}: no latitude/longitude in its subtitles: its clock's zone cannot be found "
                           "(give --srt-utc-offset-h)")
    zones = track_residual_m(srt, flight, ZONES_S)
    order = np.argsort(zones)
    best, second = zones[order[0]], zones[order[1]]
    if not math.isfinite(best):
        raise SessionError(f"{srt.path}: at no time zone do its frames fall within the flight record "
                           f"{flight.span_unix[0]:.3f}–{flight.span_unix[1]:.3f} (UNIX s): not the same flight?")
    if second < max(3.0 * best, best + 1.0):
        raise SessionError(f"{srt.path}: its track fits the record at UTC{ZONES_S[order[0]] / 3600:+g} h "
                           f"({best:.2f} m) and UTC{ZONES_S[order[1]] / 3600:+g} h ({second:.2f} m) alike: give "
                           "--srt-utc-offset-h")
    fine = ZONES_S[order[0]] + np.arange(-REFINE_S, REFINE_S + REFINE_STEP_S / 2, REFINE_STEP_S)
    residuals = track_residual_m(srt, flight, fine)
    k = int(np.argmin(residuals))
    return SrtClock(float(fine[k]), float(residuals[k]), frames, True)


def srt_video_start(srt: SrtTrack, clock: SrtClock) -> tuple[float, float]:
    """The video's first frame on UNIX time (the median over subtitles of camera time − offset − video time) and
    the largest departure of a subtitle from it (s)."""
    starts = srt.t_camera_s - clock.offset_s - srt.t_video_s
    start = float(np.median(starts))
    return start, float(np.max(np.abs(starts - start)))

"""``skyfix process --reference auto``: a surveyed marker of known position found in the video, and the fixes
corrected by the drone's absolute offset it shows (:mod:`localizer.reference`).

The session's ``reference.toml`` states the marker: ``lat_deg``, ``lon_deg`` (WGS84), ``depth_m`` (below the water
surface; on the seafloor its depth there), ``sigma_m`` (the survey's 1-sigma per horizontal axis) and ``radius_m``
(a bullseye: a light disc of that radius with a dark centre of half of it). At :data:`RATE_HZ` the marker is looked for
around where the reported pose puts it (:func:`localizer.tracking.predict.project_uuv` at its depth), within
:data:`SEARCH_SIGMAS` of the pose's position and attitude sigmas, by normalised cross-correlation with a bullseye of
its size there (:func:`bullseye`); a peak below :data:`MIN_SCORE` is no sighting. positions.csv gets the offset
applied per fix (columns ``ref_offset_n_m``, ``ref_offset_e_m``, ``ref_sigma_n_m``, ``ref_sigma_e_m``; empty where
none), and one line on stderr says what was found.

A buoy or boat reporting its GNSS over MAVLink (a moving reference, :class:`Buoy`) carries the same bullseye; its
``reference.toml`` has ``system_id`` (its MAVLink system) instead of ``lat_deg``/``lon_deg``, ``depth_m`` (its
marking's below the surface: 0 at it), ``radius_m``, and optionally ``time_sigma_s``, ``latency_s`` and ``sigma_m``
(:class:`Buoy`). Its positions are the GPS_RAW_INT messages of that system in the session's ``uav.tlog`` (the
station records what it hears; messages of any other system are not used), each at its fix's GNSS time
(``time_usec``, UNIX µs) on the station clock (the UAV's SYSTEM_TIME alignment), or, without one, its receive time
less ``latency_s``; each one's 1-sigma per axis its ``h_acc``/√2 (``sigma_m`` where it states none). A buoy that
sends GLOBAL_POSITION_INT instead (its autopilot's EKF: an ArduPilot boat, BlueOS) is read from those: they carry its
boot time, not GNSS time, put on the station clock by the fastest of its reports of the last :data:`BOOT_WINDOW_S`
(:class:`BootClock`: its time's 1-sigma half of ``latency_s``), each one's 1-sigma ``sigma_m`` (they state none); one
that sends both is followed by its GPS_RAW_INT. The buoy is looked for where its reported position, interpolated at
each frame's time (:func:`localizer.reference.reported_at`), projects.
"""

from __future__ import annotations

import sys
import tomllib
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from groundstation.offline.bottom import subsample_rows
from groundstation.session.read import Session, SessionError
from groundstation.session.tlog import read_tlog
from localizer import reference
from localizer.fix import Fixes
from localizer.pose import camera_pose
from localizer.tracking.predict import project_uuv

MODES = ("auto", "off")
FILE = "reference.toml"
RATE_HZ = 5.0  # frames searched per second of video
SEARCH_SIGMAS = 3.0
MIN_SCORE = 0.6  # the correlation's peak that counts as a sighting
COLUMNS = ("ref_offset_n_m", "ref_offset_e_m", "ref_sigma_n_m", "ref_sigma_e_m")
GNSS_TIME_MIN_US = (
    1e15  # a GPS_RAW_INT time_usec above this is UNIX time (after 2001), below it boot time
)
MIN_FIX_TYPE = 3  # GPS_RAW_INT fix_type: 3D fix or better
#: the messages a buoy's reports come in (:func:`report`)
REPORT_KINDS = ("GPS_RAW_INT", "GLOBAL_POSITION_INT")
#: a buoy's GLOBAL_POSITION_INT is put on the station clock by the fastest of its reports of this long before (s): a
#: window, so that the buoy's clock drifting against the station's is followed (:class:`BootClock`)
BOOT_WINDOW_S = 60.0


@dataclass(frozen=True)
class Buoy:
    """A moving reference reporting its GNSS over MAVLink (``reference.toml`` with ``system_id``): its MAVLink
    system id; its marking's depth below the surface (m); how well its reports' GNSS times are known on the station
    clock (``time_sigma_s``, s); its link's latency when a report has no GNSS time (``latency_s``, s: it is stamped
    when received less that, that whole latency its time's 1-sigma); a report's 1-sigma per axis when its
    ``h_acc`` is 0 (``sigma_m``, m)."""

    system_id: int
    depth_m: float
    time_sigma_s: float = 0.02
    latency_s: float = 0.3
    sigma_m: float = 0.5


def read_reference(session: Session) -> tuple[reference.Reference | Buoy, float] | None:
    """The session's ``reference.toml``: the reference (a marker's :class:`~localizer.reference.Reference`, or a
    :class:`Buoy`) and its marking's radius (m); None without the file."""
    path = session.path / FILE
    return read_file(path) if path.is_file() else None


def read_file(path: Path) -> tuple[reference.Reference | Buoy, float]:
    """A ``reference.toml`` (see the module doc) at ``path``: the reference (a :class:`Buoy` where it names a
    ``system_id``) and its marking's radius (m); :class:`~groundstation.session.read.SessionError` (one line: the
    file, what is wrong) for a bad one."""
    try:
        d = tomllib.loads(path.read_text())
        if "system_id" in d:
            return _buoy(path, d), float(d["radius_m"])
        ref = reference.Reference(
            float(d["lat_deg"]),
            float(d["lon_deg"]),
            float(d["depth_m"]),
            float(d.get("sigma_m", 0.0)),
        )
        return ref, float(d["radius_m"])
    except (KeyError, ValueError, TypeError, tomllib.TOMLDecodeError) as e:
        raise SessionError(
            f"{path}: {type(e).__name__}: {e} (needs lat_deg, lon_deg, depth_m, radius_m)"
        ) from None


def _buoy(path: Path, d: dict) -> Buoy:
    sid = d["system_id"]
    if not isinstance(sid, int) or not 1 <= sid <= 255:
        raise ValueError(f"system_id = {sid!r}: a MAVLink system id, 1-255")
    buoy = Buoy(
        sid,
        float(d["depth_m"]),
        **{k: float(d[k]) for k in ("time_sigma_s", "latency_s", "sigma_m") if k in d},
    )
    for key in ("depth_m", "time_sigma_s", "latency_s", "sigma_m"):
        if not getattr(buoy, key) >= 0:
            raise ValueError(f"{key} = {getattr(buoy, key)!r}: must be >= 0")
    return buoy


class BootClock:
    """A buoy's boot clock (GLOBAL_POSITION_INT's ``time_boot_ms``, s) on the station clock: its reports of the last
    :data:`BOOT_WINDOW_S` came ``receipt − boot time`` apart, the smallest of these the fastest report's, whose
    latency on the link is between 0 and the buoy's ``latency_s``: half of it is taken, its 1-sigma half of it too
    (a bound's, where a uniform one's would be 0.29 of it). A boot time that goes back (the buoy restarted) starts
    over."""

    def __init__(self):
        self._seen: deque[tuple[float, float]] = deque()  # (receipt, receipt − boot time) (s)
        self._last_boot_s = -np.inf

    def station(self, boot_s: float, recv_unix_s: float, latency_s: float) -> tuple[float, float]:
        """``(t_unix, its 1-sigma)`` (s) of a report stamped ``boot_s`` received at ``recv_unix_s``."""
        if boot_s < self._last_boot_s:
            self._seen.clear()
        self._last_boot_s = boot_s
        self._seen.append((recv_unix_s, recv_unix_s - boot_s))
        while self._seen[0][0] < recv_unix_s - BOOT_WINDOW_S:
            self._seen.popleft()
        return boot_s + min(d for _, d in self._seen) - latency_s / 2, latency_s / 2


def report(
    msg,
    recv_unix_s: float,
    buoy: Buoy,
    station_minus_gnss_s: float | None,
    boot_clock: BootClock | None = None,
):
    """One of the buoy's GNSS reports from a MAVLink message received at ``recv_unix_s`` (station clock):
    ``(t_unix, lat_deg, lon_deg, sigma_m, time_sigma_s)`` for a GPS_RAW_INT of its system with a 3D fix or better
    (see the module doc; ``time_sigma_s`` its time's 1-sigma: the buoy's ``time_sigma_s`` for its fix's GNSS time,
    else ``latency_s``), or a GLOBAL_POSITION_INT of its system (its autopilot's EKF, as an ArduPilot boat or BlueOS
    sends; no accuracy in it: the buoy's ``sigma_m``; not at 0, 0) at its ``time_boot_ms`` on ``boot_clock``
    (:class:`BootClock`; None: not taken), else None. Live or offline."""
    kind = msg.get_type()
    if kind not in REPORT_KINDS or msg.get_srcSystem() != buoy.system_id:
        return None
    if kind == "GLOBAL_POSITION_INT":
        if boot_clock is None or msg.lat == msg.lon == 0:
            return None
        t, time_sigma_s = boot_clock.station(msg.time_boot_ms / 1e3, recv_unix_s, buoy.latency_s)
        return t, msg.lat / 1e7, msg.lon / 1e7, buoy.sigma_m, max(time_sigma_s, buoy.time_sigma_s)
    if msg.fix_type < MIN_FIX_TYPE:
        return None
    h_acc_mm = getattr(msg, "h_acc", 0)
    sigma = h_acc_mm / 1000 / np.sqrt(2.0) if h_acc_mm > 0 else buoy.sigma_m
    gnss_time = msg.time_usec > GNSS_TIME_MIN_US and station_minus_gnss_s is not None
    t = msg.time_usec / 1e6 + station_minus_gnss_s if gnss_time else recv_unix_s - buoy.latency_s
    time_sigma_s = buoy.time_sigma_s if gnss_time else max(buoy.time_sigma_s, buoy.latency_s)
    return t, msg.lat / 1e7, msg.lon / 1e7, float(sigma), time_sigma_s


class BuoyReports:
    """A buoy's GNSS reports as they come, live or from a log: :meth:`add` each MAVLink message heard (those of other
    systems, or without a fix, are not used; a report not later than the last is dropped); :meth:`at` its position
    at given times (:func:`localizer.reference.reported_at`: a :class:`~localizer.reference.Reference` of arrays for
    :func:`expected` and :func:`localizer.reference.sightings`). ``keep_s``: reports older than this before the
    newest are let go (live); None keeps all. A buoy that sends GPS_RAW_INT beside GLOBAL_POSITION_INT is followed by
    the former (its fix's GNSS time and accuracy) from its first one on. Not thread-safe."""

    def __init__(self, buoy: Buoy, keep_s: float | None = None):
        self.buoy, self.keep_s = buoy, keep_s
        self._rows: deque[tuple[float, float, float, float]] = deque()
        self.time_sigma_s = (
            buoy.time_sigma_s
        )  # the 1-sigma of the reports' times (s): the largest kept so far
        self.boot_clock = BootClock()  # a GLOBAL_POSITION_INT's time_boot_ms on the station clock
        self.gps_raw = False  # a GPS_RAW_INT was kept: GLOBAL_POSITION_INT no longer are

    def add(self, msg, recv_unix_s: float, station_minus_gnss_s: float | None) -> bool:
        """Take one message received at ``recv_unix_s`` (station clock); True if it was the buoy's report, kept."""
        r = report(msg, recv_unix_s, self.buoy, station_minus_gnss_s, self.boot_clock)
        return r is not None and self.add_report(*r, msg.get_type() == "GPS_RAW_INT")

    def add_report(
        self,
        t_unix: float,
        lat_deg: float,
        lon_deg: float,
        sigma_m: float,
        time_sigma_s: float,
        gps_raw: bool = True,
    ) -> bool:
        """Take one report (:func:`report`'s, or one that came another way, e.g. Zenoh): its time on the station clock
        (s), WGS84 degrees, its 1-sigma per axis (m), its time's 1-sigma (s), whether a GPS_RAW_INT's (else a
        GLOBAL_POSITION_INT's: not taken once a GPS_RAW_INT was); True if kept."""
        if (self._rows and t_unix <= self._rows[-1][0]) or (self.gps_raw and not gps_raw):
            return False
        self.gps_raw |= gps_raw
        self._rows.append((t_unix, lat_deg, lon_deg, sigma_m))
        self.time_sigma_s = max(self.time_sigma_s, time_sigma_s)
        while self.keep_s is not None and self._rows[0][0] < t_unix - self.keep_s:
            self._rows.popleft()
        return True

    def __len__(self) -> int:
        return len(self._rows)

    def reports(self) -> reference.Reports:
        cols = np.array(self._rows, dtype=float).reshape(-1, 4).T
        return reference.Reports(*cols)

    def at(self, t_unix) -> reference.Reference:
        """Where the reports put the buoy at times ``t_unix`` (station clock; NaN where they do not)."""
        return reference.reported_at(self.reports(), t_unix, self.buoy.depth_m, self.time_sigma_s)


def bullseye(radius_px: float) -> np.ndarray:
    """A template (float32, square) of the marker ``radius_px`` across its light disc: 1 inside, −1 in the dark
    centre, 0 in a ring of the floor around it as wide as the radius."""
    half = int(np.ceil(2 * radius_px)) + 1
    y, x = np.mgrid[-half : half + 1, -half : half + 1].astype(np.float32)
    r = np.hypot(x, y)
    t = np.where(r <= radius_px, 1.0, 0.0) - np.where(r <= radius_px / 2, 2.0, 0.0)
    return cv2.GaussianBlur(t.astype(np.float32), (0, 0), 0.7)


def find(grey: np.ndarray, u0: float, v0: float, radius_px: float, reach_px: float):
    """The marker's centre (u, v) near (u0, v0) within ``reach_px``, or None (no peak of :data:`MIN_SCORE`)."""
    tpl = bullseye(radius_px)
    half = tpl.shape[0] // 2
    h, w = grey.shape
    x0, x1 = int(max(0, u0 - reach_px - half)), int(min(w, u0 + reach_px + half + 1))
    y0, y1 = int(max(0, v0 - reach_px - half)), int(min(h, v0 + reach_px + half + 1))
    if x1 - x0 <= tpl.shape[1] + 2 or y1 - y0 <= tpl.shape[0] + 2:
        return None
    score = cv2.matchTemplate(grey[y0:y1, x0:x1].astype(np.float32), tpl, cv2.TM_CCOEFF_NORMED)
    _, best, _, (px, py) = cv2.minMaxLoc(score)
    if best < MIN_SCORE:
        return None
    du = _peak(score[py, px - 1 : px + 2]) if 0 < px < score.shape[1] - 1 else 0.0
    dv = _peak(score[py - 1 : py + 2, px]) if 0 < py < score.shape[0] - 1 else 0.0
    return x0 + half + px + du, y0 + half + py + dv


def _peak(three) -> float:
    """The sub-pixel offset of a parabola's top through three samples about the middle one."""
    a, b, c = (float(x) for x in three)
    den = a - 2 * b + c
    return 0.0 if den >= 0 else 0.5 * (a - c) / den


def expected(cal, pose, ref: reference.Reference, radius_m: float):
    """Where the reported ``pose`` puts the marker in each of its frames, and how far to look: ``(u0, v0, radius_px,
    reach_px)`` arrays (pixels; NaN where it is not in front of the camera), the reach :data:`SEARCH_SIGMAS` of the
    pose's position and attitude sigmas."""
    u0, v0, px_per_m = project_uuv(cal, pose, ref.lat_deg, ref.lon_deg, ref.depth_m)
    slant_m = pose.height_m + ref.depth_m
    angle = np.radians(np.hypot(cal.sigmas.tilt_deg, cal.sigmas.yaw_deg))
    reach_m = SEARCH_SIGMAS * (np.nan_to_num(pose.sigma_uav_m) + slant_m * angle)
    return u0, v0, radius_m * px_per_m, reach_m * px_per_m


def sightings(session: Session, ref, radius_m: float):
    """The times and pixels (NaN: not found) of the marker in the frames at :data:`RATE_HZ`; ``ref`` a
    :class:`~localizer.reference.Reference`, or a function of the frames' times giving one (a moving reference)."""
    cal, tel = session.calibration, session.telemetry
    rows = subsample_rows(session.frames["t"], RATE_HZ)
    t = session.frames["t"][rows]
    at = ref(t) if callable(ref) else ref
    u0, v0, radius_px, reach_px = expected(cal, camera_pose(cal, tel, t), at, radius_m)
    u, v = np.full(len(rows), np.nan), np.full(len(rows), np.nan)
    wanted = {int(session.frames["frame"][r]): k for k, r in enumerate(rows)}
    with session.open_video(grey=True) as video:
        for vf in video.prefetch():
            k = wanted.get(vf.index)
            if k is None or not np.isfinite(u0[k]):
                continue
            grey = vf.image if vf.image.ndim == 2 else cv2.cvtColor(vf.image, cv2.COLOR_BGR2GRAY)
            hit = find(grey, u0[k], v0[k], radius_px[k], reach_px[k])
            if hit is not None:
                u[k], v[k] = hit
    return t, u, v


def buoy_track(session: Session, buoy: Buoy):
    """``(where, what)``: the buoy's position at given times (a function of them giving a
    :class:`~localizer.reference.Reference`: :func:`localizer.reference.reported_at` of its reports in uav.tlog) and
    a few words on its reports; None, with a warning, where the session has no usable reports of its system."""
    where = f"{session.path / FILE}: system_id = {buoy.system_id}"
    if buoy.system_id == session.uav_sysid:
        session.warnings.append(f"{where}: that is the UAV's own system; the buoy is not used")
        return None
    records = read_tlog(session.path / "uav.tlog")
    track = BuoyReports(buoy)
    for t, msg in records:
        track.add(msg, t, session.telemetry.station_minus_gnss_s)
    if len(track) < 2:
        heard = sorted({m.get_srcSystem() for _, m in records if m.get_type() in REPORT_KINDS})
        session.warnings.append(
            f"{where}: no GPS_RAW_INT with a fix nor GLOBAL_POSITION_INT from that system in uav.tlog (from systems "
            f"{', '.join(map(str, heard)) or 'none'}); the buoy is not used"
        )
        return None
    what = (
        f"the buoy (system {buoy.system_id}: {len(track)} GNSS reports, median 1-sigma "
        f"{np.median(track.reports().sigma_m):.3f} m per axis, their times ± {1000 * track.time_sigma_s:.0f} ms)"
    )
    return track.at, what


def sigma_seen(at: reference.Reference, seen) -> float:
    """The reference's 1-sigma per axis the offset carries: the marker's, or a moving reference's RMS over the frames
    it was seen in (``seen``, (N,) bool; 0 where none)."""
    if np.ndim(at.sigma_m) == 0:
        return float(at.sigma_m)
    return float(np.sqrt(np.mean(np.square(at.sigma_m[seen])))) if np.any(seen) else 0.0


def apply(session: Session, fixes: Fixes, mode: str, correction=None):
    """``--reference``: the fixes corrected by the marker's offset and positions.csv's cells (:data:`COLUMNS`), or
    ``(fixes, None)`` (``off``, no reference.toml, no video: a warning says why); ``correction`` the pose's from the
    bottom (:class:`groundstation.offline.bottom.PoseCorrection`) the fixes were made with, if any."""
    found = None if mode == "off" else read_reference(session)
    if found is None:
        return fixes, None
    if session.video_path is None or session.frames is None:
        session.warnings.append(f"{session.path}: {FILE} but no video to find the marker in")
        return fixes, None
    ref, radius_m = found
    cal, tel = session.calibration, session.telemetry
    where, what = ref, "the marker"
    if isinstance(ref, Buoy):
        moving = buoy_track(session, ref)
        if moving is None:
            return fixes, None
        where, what = moving
    t, u, v = sightings(session, where, radius_m)
    at = where(t) if callable(where) else where
    seen_pose, seen_cal = camera_pose(cal, tel, t), cal
    pose = camera_pose(cal, tel, fixes.t_unix)
    if correction is not None:
        seen_pose, seen_cal = correction.apply(session, seen_pose)
        pose, cal = correction.apply(session, pose)
    off, seen, jac = reference.sightings(seen_cal, seen_pose, u, v, at)
    offsets = reference.offsets(t[seen], off[seen], jac[seen], fixes.t_unix, sigma_seen(at, seen))
    better = reference.correct(cal, pose, fixes, offsets)
    print(
        f"{session.path.name}: {what} seen in {int(seen.sum())} of {len(t)} frames searched; "
        f"{offsets.describe()}",
        file=sys.stderr,
    )
    used = reference.applied(fixes, better)
    cells = {
        c: [f"{x:.4f}" if ok else "" for x, ok in zip(col, used)]
        for c, col in zip(COLUMNS, [*offsets.offset_ne_m.T, *offsets.sigma_ne_m.T])
    }
    return better, cells

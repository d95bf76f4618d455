"""A reference of known position in view, live (``reference = FILE``, ``reference_every_s``): a surveyed marker, or a
buoy reporting its GNSS (:class:`LiveBuoy`); the drone's absolute offset it shows added to every fix, as ``skyfix
process --reference auto`` does offline (:mod:`groundstation.offline.reference`, :mod:`localizer.reference`).

A buoy (the file names its ``system_id``, and optionally ``component_id``) reports GPS_RAW_INT, or GLOBAL_POSITION_INT
(an ArduPilot boat, BlueOS: its boot time put on the station clock as offline,
:class:`groundstation.offline.reference.BootClock`), on the UAV's MAVLink link; the UAV's source hands this module every message of another system (its ``others``) and never takes the buoy's
system for the UAV's; with ``reference_zenoh_key`` its reports also come on Zenoh as BlueOS publishes them
(:class:`BuoyZenoh`). Only the buoy's reports are kept (:class:`LiveBuoy`: any other system's are refused and counted,
malformed ones refused in a log line); a frame is searched for it where its reports, interpolated at the frame's
time, put it (:meth:`LiveBuoy.at` waits up to :data:`WAIT_S` for the report after the frame), its sigma the
reports' with their speed times their time's sigma. When its reports stop, frames are no longer searched
(``no_report``) and the correction lapses as when a marker leaves the view.

Every ``reference_every_s`` seconds of video an aligned frame is taken with its camera pose, and the marker is looked
for around where that pose puts it (:func:`search`: :func:`groundstation.offline.reference.expected`,
:func:`~groundstation.offline.reference.find`) in a low-priority process of its own, the frame handed over in shared
memory (:class:`groundstation.live.side_process.SideProcess`, as the live mosaic's painter: a thread of the service at
a low priority held the interpreter's lock while it waited for a core); a frame that comes while the search is still
busy with the one before is skipped and counted (:class:`groundstation.live.every_frame.EveryFrame`). A sighting is
the offset known − located of the marker through the frame's reported pose (:func:`localizer.reference.sightings`).

Each fix (:meth:`LiveReference.correct`, called by the pipeline with the fix's pose) gets the offset of the sightings
of the :data:`~localizer.reference.WINDOW_S` before its frame (causal): a straight line through their
:data:`~localizer.reference.BLOCK_S` means taken at the frame's time (:func:`drift_line`; the offline window's
mean, whose sigma is the floor of the line's, would trail a plain GNSS's walk by half the window), with sightings in
at least :data:`~localizer.reference.MIN_BLOCKS` + 1 of its seconds and the newest at most :data:`HORIZON_S` before the
frame (its sigma growing with that age). Its claim is :func:`localizer.reference.correct`'s:
the offset's sigma in h_acc, the UAV position's term gone, the pose terms the reference's sensitivities to them (its
pose_jacobian, on the same line at the frame's time: a buoy moves in the image) leave. The fix says what
was added (``ref_offset_n_m`` …, ``ref_sightings``, ``ref_age_s``); with too few sightings in the window the
correction lapses and the fixes are the telemetry's again. Station-clock seconds, north/east metres.
"""

from __future__ import annotations

import asyncio
import dataclasses
import json
import logging
import math
import threading
import tomllib
from collections import Counter, deque
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from groundstation.live.every_frame import EveryFrame
from groundstation.live.side_process import SideProcess
from groundstation.mavlink.ingest import mavutil
from groundstation.offline.reference import (
    REPORT_KINDS,
    Buoy,
    BuoyReports,
    expected,
    find,
    report,
)
from groundstation.runtime.logs import Throttle, kind_of
from groundstation.runtime.threads import Handoff
from groundstation.runtime.zenoh_session import subscribe
from localizer import reference
from localizer.fix import Fix, Fixes
from localizer.pose import CameraPose

log = logging.getLogger("skyfix.reference")

#: sightings older than this before the newest are let go (s)
KEEP_S = 2 * reference.WINDOW_S
#: how long the search waits for the buoy's first report after a frame's time (s): it comes over its own radio
WAIT_S = 1.0
#: a buoy's report whose time on the station clock is further than this from when it came is refused (s)
MAX_SKEW_S = 5.0
#: the line through the sightings is carried at most this long past the newest of them (s; 5 searches at the default
#: 5 Hz, one of its 1-s blocks): beyond, the correction lapses and the fixes go out as the telemetry made them. A plain
#: GNSS's walk curves away from the line: its claim covers 90 % of it within 2 sigma 1 s on, 80 % 2 s on
#: (tests/test_live_reference.py)
HORIZON_S = 1.0


def drift_line(t_sight: np.ndarray, offset_ne_m: np.ndarray, t_unix: float):
    """The offset at ``t_unix`` (2,) and its 1-sigma per axis (2,) from a straight line through the sightings'
    :data:`~localizer.reference.BLOCK_S` means (``offset_ne_m`` (M, 2) at ``t_sight``, all before ``t_unix``): the
    window's mean lags its newest sighting by half the window, and a plain GNSS walks centimetres a second. The sigma
    is a prediction's, not the line's standard error alone (a walk is no line: that one covered 65 % of a plain GNSS's
    within 2 sigma): the means' scatter about the line (s) at the newest sighting, with the line's standard error
    there, growing as a walk of s per block with the time since that sighting, plus the slope's standard error times
    that time (at least the statistical error of the line carried there, whatever their correlation). None with
    fewer than
    :data:`~localizer.reference.MIN_BLOCKS` + 1 blocks, or when the newest sighting is more than :data:`HORIZON_S`
    before ``t_unix``."""
    if not len(t_sight) or t_unix - t_sight.max() > HORIZON_S:
        return None
    block = np.floor((t_unix - t_sight) / reference.BLOCK_S).astype(int)
    labels, which = np.unique(block, return_inverse=True)
    k = len(labels)
    if k < reference.MIN_BLOCKS + 1:
        return None
    age_s = t_unix - t_sight.max()
    per = np.bincount(which)
    t_block = np.bincount(which, weights=t_sight - t_sight.max()) / per
    means = np.stack([np.bincount(which, weights=o) / per for o in offset_ne_m.T], axis=1)
    design = np.column_stack([np.ones(k), t_block])
    coef, *_ = np.linalg.lstsq(design, means, rcond=None)
    scatter = ((means - design @ coef) ** 2).sum(axis=0) / (k - 2)
    spread = np.linalg.inv(design.T @ design)
    # a block mean's own scatter about the line, the line's error at the newest sighting, and the scatter again per
    # block of age (what the line does not explain walks on)
    sigma_last = np.sqrt(scatter * (1.0 + spread[0, 0] + age_s / reference.BLOCK_S))
    sigma_slope = np.sqrt(scatter * spread[1, 1])
    return coef[0] + coef[1] * age_s, sigma_last + sigma_slope * age_s


def search(cal, radius_m: float, image: np.ndarray, pose: CameraPose, at: reference.Reference):
    """The marker (``at``, of radius ``radius_m``) looked for in one frame around where ``pose`` puts it: the
    sighting's offset (2,) and pose jacobian (2, 4), or None where it was not found."""
    u0, v0, radius_px, reach_px = expected(cal, pose, at, radius_m)
    if not np.isfinite(u0[0]):
        return None
    grey = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    hit = find(grey, u0[0], v0[0], radius_px[0], reach_px[0])
    if hit is None:
        return None
    off, ok, jac = reference.sightings(cal, pose, [hit[0]], [hit[1]], at)
    return (off[0], jac[0]) if ok[0] else None


#: The search's process: its calibration and the marker's radius (:func:`start_search`).
_searching: list = []


def start_search(cal, radius_m: float) -> None:
    """The search's process: what :func:`search` takes besides the frame, and its imports, now."""
    _searching[:] = [cal, radius_m]


def search_now(image: np.ndarray, pose: CameraPose, at: reference.Reference):
    """The search's process: :func:`search`."""
    return search(*_searching, image, pose, at)


def as_fixes(fix: Fix) -> Fixes:
    """One fix as :class:`~localizer.fix.Fixes` of one."""
    names = [f.name for f in dataclasses.fields(Fixes)][2:]
    return Fixes.of([fix.t_unix], [fix.status], **{n: [getattr(fix, n)] for n in names})


def component_id(path: Path) -> int | None:
    """A buoy's ``reference.toml``'s ``component_id`` (its MAVLink component, 1-255): only its reports from that
    component are taken; None (the key absent): any component of its ``system_id``. ValueError for a bad one."""
    cid = tomllib.loads(Path(path).read_text()).get("component_id")
    if cid is not None and (type(cid) is not int or not 1 <= cid <= 255):
        raise ValueError(f"component_id = {cid!r}: a MAVLink component id, 1-255")
    return cid


def malformed(msg) -> str | None:
    """Why a GPS_RAW_INT or GLOBAL_POSITION_INT is no position (its lat/lon, 1e-7 degrees, out of range, NaN, or 0,
    0), or None."""
    lat, lon = float(msg.lat), float(msg.lon)
    if not (abs(lat) <= 90e7 and abs(lon) <= 180e7):
        return f"lat {msg.lat}, lon {msg.lon} (1e-7 deg): out of range"
    if lat == 0 and lon == 0:
        return "lat 0, lon 0: no position"
    return None


class LiveBuoy:
    """A buoy's GNSS reports heard live: :meth:`on_mavlink` (on the event loop) gets every message of a system other
    than the UAV's on its MAVLink link. Only the GPS_RAW_INT (or GLOBAL_POSITION_INT) of the buoy's ``system_id``
    (and ``component_id``, when the file names one) are taken (:class:`groundstation.offline.reference.BuoyReports`); one from any other system or
    component is refused and counted by ``system:component`` (``foreign``), one of the buoy's that is no position
    (:func:`malformed`) or whose time is more than :data:`MAX_SKEW_S` from its receipt refused with a log line, one
    without a 3D fix counted. :meth:`at` (the search's thread) is where the reports put it at a frame's time."""

    def __init__(self, tel, buoy: Buoy, component: int | None):
        self.tel, self.buoy, self.component = tel, buoy, component
        self.reports = BuoyReports(buoy, keep_s=KEEP_S)
        self.taken = 0  # reports kept
        self.no_fix = 0  # the buoy's reports without a 3D fix
        self.refused = 0  # the buoy's reports that are no position
        self.foreign: Counter[str] = Counter()  # reports of other systems/components
        self.last_recv = math.nan  # station time the last report kept came
        self._newest_t = -math.inf  # the last report's time (station clock)
        self._throttle = Throttle()
        self._changed = threading.Condition()

    def on_mavlink(self, msg, t_recv: float) -> None:
        kind = msg.get_type()
        if kind not in REPORT_KINDS:
            return
        sysid, compid = msg.get_srcSystem(), msg.get_srcComponent()
        if sysid != self.buoy.system_id or self.component not in (None, compid):
            self.foreign[f"{sysid}:{compid}"] += 1
            if self._throttle(f"foreign {sysid}:{compid}"):
                log.warning(
                    "reference: %s of system %d component %d refused (the buoy is system %d%s)",
                    kind,
                    sysid,
                    compid,
                    self.buoy.system_id,
                    "" if self.component is None else f" component {self.component}",
                )
            return
        why = malformed(msg)
        got = (
            None
            if why
            else report(
                msg, t_recv, self.buoy, self.tel.station_minus_gnss_s, self.reports.boot_clock
            )
        )
        if why is None and got is None:
            self.no_fix += 1
            return
        if why is None and not abs(got[0] - t_recv) <= MAX_SKEW_S:
            why = f"its time is {got[0] - t_recv:+.1f} s from its receipt"
        if why:
            self.refused += 1
            n = self._throttle(why)
            if n:
                log.warning("reference: the buoy's %s #%d refused: %s", kind, n, why)
            return
        with self._changed:
            if self.reports.add_report(*got, kind == "GPS_RAW_INT"):
                self.taken += 1
                self.last_recv = t_recv
                self._newest_t = got[0]
                self._changed.notify_all()

    def at(self, t_unix: float) -> reference.Reference:
        """Where the reports put the buoy at ``t_unix`` (arrays of one; NaN where they do not), once a report after
        it has come or :data:`WAIT_S` has passed: a report comes over the buoy's radio after the frame."""
        with self._changed:
            self._changed.wait_for(lambda: self._newest_t >= t_unix, WAIT_S)
            return self.reports.at(np.array([t_unix]))

    def status(self, now: float) -> dict:
        return {
            "system_id": self.buoy.system_id,
            "component_id": self.component,
            "reports": self.taken,
            "last_report_age_s": round(now - self.last_recv, 3)
            if math.isfinite(self.last_recv)
            else None,
            "no_fix": self.no_fix,
            "refused": self.refused,
            "foreign": dict(self.foreign),
        }


@dataclasses.dataclass(frozen=True)
class HeardReport:
    """A GPS_RAW_INT or GLOBAL_POSITION_INT (``kind``) that came on Zenoh, as :meth:`LiveBuoy.on_mavlink` reads a
    pymavlink message (the fields the other kind lacks 0)."""

    system: int
    component: int
    lat: float
    lon: float
    kind: str = "GPS_RAW_INT"
    time_usec: int = 0
    fix_type: int = 0
    h_acc: int = 0
    time_boot_ms: int = 0

    def get_type(self) -> str:
        return self.kind

    def get_srcSystem(self) -> int:
        return self.system

    def get_srcComponent(self) -> int:
        return self.component


class BadReport(ValueError):
    """A report's payload on Zenoh that cannot be read."""


def parse_gps_raw(payload: bytes) -> HeardReport:
    """A GPS_RAW_INT as BlueOS's mavlink-server publishes it on Zenoh (``mavlink/{sys}/{comp}/GPS_RAW_INT``:
    ``{"header": {"system_id", "component_id", ...}, "message": {"type": "GPS_RAW_INT", "lat", "lon", "time_usec",
    "fix_type": {"type": "GPS_FIX_TYPE_..."}, "h_acc", ...}}``), or a GLOBAL_POSITION_INT (its ``time_boot_ms``,
    ``lat``, ``lon``); its system and component the header's. :class:`BadReport` naming what is wrong (a lat/lon that
    is no position is :func:`malformed`'s to refuse)."""
    try:
        obj = json.loads(payload)
    except (ValueError, UnicodeDecodeError, RecursionError):
        raise BadReport("not JSON") from None
    head = obj.get("header") if isinstance(obj, dict) else None
    msg = obj.get("message") if isinstance(obj, dict) else None
    if not isinstance(head, dict) or not isinstance(msg, dict):
        raise BadReport("no 'header' and 'message' objects")
    kind = msg.get("type")
    if kind not in REPORT_KINDS:
        raise BadReport(f"message type {kind!r} is not {' or '.join(REPORT_KINDS)}")
    fields = {
        "system": head.get("system_id"),
        "component": head.get("component_id"),
        "lat": msg.get("lat"),
        "lon": msg.get("lon"),
    }
    if kind == "GLOBAL_POSITION_INT":
        fields["time_boot_ms"] = msg.get("time_boot_ms")
    else:
        fix = msg.get("fix_type")
        if isinstance(fix, dict):
            entry = mavutil().mavlink.enums["GPS_FIX_TYPE"]
            fix = next((k for k, e in entry.items() if e.name == fix.get("type")), None)
        fields |= {
            "time_usec": msg.get("time_usec", 0),
            "fix_type": fix,
            "h_acc": msg.get("h_acc", 0),
        }
    for name, value in fields.items():
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise BadReport(f"{name} = {value!r}: expected a number")
    return HeardReport(kind=kind, **fields)


class BuoyZenoh:
    """A worker subscribing to ``key`` (a Zenoh key expression; BlueOS's ``mavlink/*/*/GPS_RAW_INT`` hears every
    system's; ``mavlink/*/*/GLOBAL_POSITION_INT`` for a buoy that sends those) and handing each report
    (:func:`parse_gps_raw`) to ``buoy``'s :meth:`LiveBuoy.on_mavlink`, which
    keeps only the buoy's; a payload that does not parse is refused with a log line and counted in the buoy's
    ``refused``."""

    def __init__(self, session, key: str, buoy: LiveBuoy):
        self.session, self.key, self.buoy = session, key, buoy
        self._throttle = Throttle()

    async def run(self) -> None:
        handoff = Handoff(asyncio.get_running_loop(), lambda item: self._on(*item), 256)
        await subscribe(self.session, self.key, handoff)

    def _on(self, key: str, data: bytes, t_recv: float) -> None:
        try:
            heard = parse_gps_raw(data)
        except BadReport as e:
            self.buoy.refused += 1
            if self._throttle(kind_of(str(e))):
                # the message its key names (BlueOS's keys end with it)
                kind = key.rsplit("/", 1)[-1]
                log.warning("reference: %s on %s refused: %s: %r", kind, key, e, data[:120])
            return
        self.buoy.on_mavlink(heard, t_recv)


class LiveReference:
    """The marker's sightings and the offset they give: :meth:`on_frame` (a frame listener, on the event loop) takes
    a frame every ``every_s`` s of video to search; :meth:`correct` (each UUV's pipeline) adds the offset to a fix;
    :meth:`status` the ``reference`` section. ``ref``, ``radius_m``: :func:`groundstation.offline.reference.read_file`'s
    of ``path``."""

    def __init__(
        self, cal, tel, path: str, ref: reference.Reference, radius_m: float, every_s: float
    ):
        self.cal, self.tel = cal, tel
        self.path, self.ref, self.radius_m, self.every_s = path, ref, radius_m, every_s
        self.buoy = LiveBuoy(tel, ref, component_id(Path(path))) if isinstance(ref, Buoy) else None
        self.no_report = 0  # frames the buoy's reports did not cover
        self.searched = 0  # frames searched
        self.seen = 0  # frames the marker was found in
        self.corrected = 0  # fixes the offset was added to
        self.kept_own = (
            0  # fixes whose own claim was smaller than the corrected one's (kept as they were)
        )
        # (t_unix, offset (2,), jacobian (2, 4), the reference's 1-sigma per axis) of each sighting: appended by the
        # search, read by correct()
        self._sightings: deque[tuple[float, np.ndarray, np.ndarray, float]] = deque()
        self._lock = threading.Lock()
        self._applying = False  # the last fix was corrected (its change is logged)
        self._estimated = False  # an offset was found once: without one now, it lapsed
        self._process = SideProcess("reference", start_search, cal, radius_m)
        self._search = EveryFrame(cal, tel, every_s, self.look, "reference")

    def on_frame(self, frame) -> None:
        if frame.aligned:  # a frame stamped before the video's latency settled is not searched
            self._search.on_frame(frame)

    def sight_through(self, adjust: Callable[[CameraPose], CameraPose]) -> None:
        """Search each frame with the pose ``adjust`` gives (e.g. the bottom's corrected one: the offset found is
        then what is left after that correction)."""
        self._search.adjust = adjust

    def look(self, image: np.ndarray, pose: CameraPose) -> None:
        """Search one frame (the search's thread: in its process) and keep the sighting."""
        self.searched += 1
        t = float(pose.t_unix[0])
        at = self.ref if self.buoy is None else self.buoy.at(t)
        if not np.all(np.isfinite(at.lat_deg)):
            self.no_report += 1
            return
        found = self._process.call_on(search_now, image, pose, at)
        if found is None:
            return
        self.seen += 1
        sigma_m = float(np.ravel(at.sigma_m)[0])
        with self._lock:
            self._sightings.append((t, *found, sigma_m))
            while self._sightings and self._sightings[0][0] < t - KEEP_S:
                self._sightings.popleft()

    def offsets(self, t_unix: float) -> tuple[reference.Offsets, float]:
        """The offset at ``t_unix`` from the sightings of the window before it, and the age of the last of them (s;
        NaN: none)."""
        with self._lock:
            kept = [s for s in self._sightings if s[0] <= t_unix]
        if not kept:
            t, off, jac, ref_sigma = np.zeros(0), np.zeros((0, 2)), np.zeros((0, 2, 4)), np.zeros(0)
        else:
            t, ref_sigma = np.array([s[0] for s in kept]), np.array([s[3] for s in kept])
            off, jac = np.stack([s[1] for s in kept]), np.stack([s[2] for s in kept])
        recent = t >= t_unix - reference.WINDOW_S
        # the reference's own sigma: the marker's survey, or a buoy's reports' RMS over its sightings
        sigma_m = float(np.sqrt(np.mean(np.square(ref_sigma[recent])))) if recent.any() else 0.0
        found = reference.offsets(t, off, jac, [t_unix - reference.WINDOW_S / 2], sigma_m)
        line = drift_line(t[recent], off[recent], t_unix)
        if line is None or not np.isfinite(found.offset_ne_m[0, 0]):
            found = dataclasses.replace(found, offset_ne_m=np.full((1, 2), np.nan))
        else:
            at, sigma = line
            # the reference's sensitivity to the pose where the line puts the offset, at the fix's time (a buoy moves
            # in the image: the window's mean of it lags, and the compass term it leaves is under-stated)
            jac_at, _ = drift_line(t[recent], jac[recent].reshape(-1, 8), t_unix)
            found = dataclasses.replace(
                found,
                offset_ne_m=at[None],
                sigma_ne_m=np.maximum(sigma, found.sigma_ne_m[0])[None],
                jacobian=jac_at.reshape(1, 2, 4),
            )
        self._estimated |= bool(np.isfinite(found.offset_ne_m[0, 0]))
        return found, (t_unix - t[-1]) if len(t) else math.nan

    def correct(self, fix: Fix, pose: CameraPose) -> Fix:
        """``fix`` (made with ``pose``) with the offset added and its claim, when there is one at its time (on the
        event loop)."""
        if not fix.ok:
            return fix
        found, age_s = self.offsets(fix.t_unix)
        applying = bool(np.isfinite(found.offset_ne_m[0, 0]))
        if applying != self._applying:
            self._applying = applying
            log.info(
                "%s",
                found.describe()
                if applying
                else "reference: the correction lapsed (too few sightings)",
            )
        if not applying:
            return fix
        own = as_fixes(fix)
        moved = reference.correct(self.cal, pose, own, found)
        if not reference.applied(own, moved)[0]:
            self.kept_own += 1
            return fix
        self.corrected += 1
        better = moved[0]
        (n, e), (sn, se) = found.offset_ne_m[0], found.sigma_ne_m[0]
        return dataclasses.replace(
            better,
            frame=fix.frame,
            confidence=fix.confidence,
            ref_offset_n_m=float(n),
            ref_offset_e_m=float(e),
            ref_sigma_n_m=float(sn),
            ref_sigma_e_m=float(se),
            ref_sightings=float(found.sightings[0]),
            ref_age_s=float(age_s),
        )

    def status(self, now: float) -> dict:
        found, age_s = self.offsets(now)
        applied = bool(np.isfinite(found.offset_ne_m[0, 0]))
        (n, e), (sn, se) = found.offset_ne_m[0], found.sigma_ne_m[0]

        def num(x: float, digits: int = 4) -> float | None:
            return round(float(x), digits) if applied else None

        return {
            "file": self.path,
            "kind": "marker" if self.buoy is None else "buoy",
            "buoy": None if self.buoy is None else self.buoy.status(now),
            "no_report": self.no_report,
            "state": "applied" if applied else "lapsed" if self._estimated else "searching",
            "offset_n_m": num(n),
            "offset_e_m": num(e),
            "sigma_n_m": num(sn),
            "sigma_e_m": num(se),
            "sightings": int(found.sightings[0]),
            "age_s": round(age_s, 3) if math.isfinite(age_s) else None,
            "window_s": reference.WINDOW_S,
            "searched": self.searched,
            "seen": self.seen,
            "skipped": self._search.skipped,
            "no_pose": self._search.no_pose,
            "every_s": self.every_s,
            "corrected": self.corrected,
            "kept_own": self.kept_own,
        }

    def close(self) -> None:
        self._process.close()
        self._search.close()

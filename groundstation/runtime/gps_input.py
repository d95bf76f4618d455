"""MAVLink ``GPS_INPUT`` to the UUV's autopilot, filled the way ArduSub's AP_GPS_MAV reads it.

When: every new fix is sent as soon as it is ready (from the event loop), and whenever ``1 / hz`` has
passed without a message, the latest state is sent again from a thread of the sink's own (the
keep-alive), not from the event loop: a loaded machine stretches the loop's steps (up to 0.7 s seen
with two UUVs and two busy processes on 2 cores), and the autopilot must not see that. So the autopilot
sees at least ``hz`` messages per second (ArduPilot calls a MAVLink GPS unhealthy below ~5 Hz or after
two gaps over 245 ms) and at most the video's frame rate (EKF3 fuses GPS at most every 70 ms and skips
the rest).

What (:func:`gps_input_fields`):

- The newest ``ok`` fix that passed the gates (below), while at most ``max_age_s`` old: ``fix_type``
  3; ``lat``/``lon`` degE7; ``alt`` the UUV's altitude AMSL (m);
  ``horiz_accuracy``/``vert_accuracy`` the fix's ``h_acc_m``/``v_acc_m`` (AP_GPS_MAV copies
  ``horiz_accuracy`` into the GPS state's horizontal accuracy and EKF3 fuses it as the north and the
  east position's 1-sigma each, floored at EK3_POSNE_M_NSE: ``h_acc_m``, half the 95 % circle's radius,
  is that sigma for a round error; see docs/explanation/accuracy.md);
  ``hdop`` = ``h_acc_m / UERE_M`` and ``vdop`` = ``v_acc_m / UERE_M`` with a
  nominal 1 m user range error, so EKF3's alignment gate hdop ≤ 2.5 means
  h_acc ≤ 2.5 m; ``satellites_visible`` the constant :data:`SATELLITES` (EKF3
  wants ≥ 6 to align; there are no satellites, the number only passes that
  gate); ``time_week``/``time_week_ms`` the frame's exposure time as GPS time
  (UTC + 18 leap seconds), used by ArduPilot's jitter correction; velocities
  are not estimated and flagged ignored.
- Once the newest ok fix is older than ``max_age_s`` (telemetry stale, video
  stopped; ``--fix-max-age-ms``, default 500 ms), or at once when the tracker
  reports the UUV lost, awaits a target or was released, finds its tracker on the same vehicle as another UUV's
  (``same_vehicle``), or ``skyfix fuse`` finds its drones disagreeing (:data:`LOSS_STATUSES`):
  ``fix_type`` 1 (NO_FIX), lat/lon/alt 0, every ``ignore_flags`` bit set, 0
  satellites, hdop/vdop 99.99. Why 1 and not 0: AP_GPS copies ``fix_type`` into
  the GPS status, and 0 is NO_GPS ("no GPS connected") while 1 is NO_FIX ("GPS
  connected, no position"): the link is fine and only the position is missing,
  so the pilot's "GPS: no fix" is the true message and a lost UUV track is not
  confused with a broken cable. Either way the EKF (which needs a 3D fix) stops
  using GPS position; a stale fix is never sent as valid. The status names why
  (``no_fix_reason``, in plain words ``no_fix_why``: :mod:`.no_fix`).

Which fixes: only those that pass the safety gates (:mod:`localizer.fix_gate`: accuracy,
age, order, the frame's prediction window, and a track of the UUV — a fix off the track,
out of the UUV's reach after a loss, or of a target not yet confirmed over a second is
refused), counted by reason in the status; a refused fix leaves the last accepted one in
place until it ages out. The fix itself goes out, never the track's estimate (the UUV's
EKF does the filtering). A loss of the track, and an operator's command (a selection), make
the next fixes a re-acquisition, a new lock judged against the last trusted track. The gates
keep to the monotonic clock (each frame's arrival on it and on the station clock).

Stopping (:meth:`GpsInputSink.stop`, also on cancellation): one last no-fix message, so
the autopilot drops the position at once instead of after its 4 s timeout, then the
link is closed.

Links: :func:`mavlink_gps_link` (system 245, component 220, a
:class:`~groundstation.mavlink.link.MavlinkLink` with its own thread, reconnecting,
HEARTBEAT, optional signing; not MAVSDK, which sends to every link and reports
success on failure), or
:class:`~.zenoh_mavlink.ZenohMavlinkIn` for ``zenoh:KEY`` (BlueOS's mavlink-server).
"""

from __future__ import annotations

import asyncio
import logging
import math
import threading
import time
from collections import deque

from groundstation.mavlink.ids import GPS_COMPID, SKYFIX_SYSID
from groundstation.mavlink.ingest import mavutil
from groundstation.mavlink.link import MavlinkLink
from groundstation.runtime.no_fix import NO_FIX_WHY, no_fix_reason
from groundstation.runtime.threads import Supervised, in_thread
from localizer.fix import Fix
from localizer.fix_gate import Arrival, FixGate

log = logging.getLogger("skyfix.gps_input")

SATELLITES = 10
UERE_M = 1.0
GPS_EPOCH_UNIX = 315964800  # 1980-01-06T00:00:00Z
LEAP_S = 18  # GPS − UTC since 2017
WEEK_S = 604800
IGNORE_ALT, IGNORE_HDOP, IGNORE_VDOP = 1, 2, 4
IGNORE_VEL_HORIZ, IGNORE_VEL_VERT, IGNORE_SPEED_ACC = 8, 16, 32
IGNORE_HORIZ_ACC, IGNORE_VERT_ACC = 64, 128
IGNORE_VELOCITY = IGNORE_VEL_HORIZ | IGNORE_VEL_VERT | IGNORE_SPEED_ACC
IGNORE_ALL = 255
FIX_NONE, FIX_3D = 1, 3
DOP_MAX = 99.99
STOP_WAIT_S = 1.0  # a stop waits this long for the keep-alive thread
#: Frame statuses meaning the UUV is no longer where the last fix put it: the last fix is dropped at once.
LOSS_STATUSES = ("lost", "no_track", "awaiting_target", "released", "same_vehicle", "disagree")


def gps_time(t_unix: float) -> tuple[int, int]:
    """``(week, ms of week)`` of a UNIX time, in GPS time (UTC + 18 leap seconds)."""
    ms = round((t_unix - GPS_EPOCH_UNIX + LEAP_S) * 1000.0)
    week, ms_of_week = divmod(ms, WEEK_S * 1000)
    return week, ms_of_week


def _dop(acc_m: float) -> float:
    return min(max(acc_m / UERE_M, 0.01), DOP_MAX)


def gps_input_fields(fix: Fix | None, t_send_unix: float, max_age_s: float) -> dict:
    """GPS_INPUT fields for the newest fix at send time (a no-fix message unless it is ok and fresh)."""
    valid = (
        fix is not None
        and fix.ok
        and abs(t_send_unix - fix.t_unix) <= max_age_s
        and math.isfinite(fix.lat)
        and math.isfinite(fix.lon)
        and math.isfinite(fix.alt_amsl_m)
    )
    if not valid:
        week, week_ms = gps_time(t_send_unix)
        return {
            "time_usec": int(t_send_unix * 1e6),
            "gps_id": 0,
            "ignore_flags": IGNORE_ALL,
            "time_week_ms": week_ms,
            "time_week": week,
            "fix_type": FIX_NONE,
            "lat": 0,
            "lon": 0,
            "alt": 0.0,
            "hdop": DOP_MAX,
            "vdop": DOP_MAX,
            "vn": 0.0,
            "ve": 0.0,
            "vd": 0.0,
            "speed_accuracy": 0.0,
            "horiz_accuracy": 0.0,
            "vert_accuracy": 0.0,
            "satellites_visible": 0,
            "yaw": 0,
        }
    t_exposure = fix.t_gnss if math.isfinite(fix.t_gnss) else fix.t_unix
    week, week_ms = gps_time(t_exposure)
    ignore = IGNORE_VELOCITY
    h_acc, v_acc = fix.h_acc_m, fix.v_acc_m
    if not math.isfinite(h_acc):
        ignore |= IGNORE_HORIZ_ACC | IGNORE_HDOP
        h_acc = 0.0
    if not math.isfinite(v_acc):
        ignore |= IGNORE_VERT_ACC | IGNORE_VDOP
        v_acc = 0.0
    return {
        "time_usec": int(t_exposure * 1e6),
        "gps_id": 0,
        "ignore_flags": ignore,
        "time_week_ms": week_ms,
        "time_week": week,
        "fix_type": FIX_3D,
        "lat": round(fix.lat * 1e7),
        "lon": round(fix.lon * 1e7),
        "alt": float(fix.alt_amsl_m),
        "hdop": _dop(h_acc),
        "vdop": _dop(v_acc),
        "vn": 0.0,
        "ve": 0.0,
        "vd": 0.0,
        "speed_accuracy": 0.0,
        "horiz_accuracy": float(h_acc),
        "vert_accuracy": float(v_acc),
        "satellites_visible": SATELLITES,
        "yaw": 0,
    }


def mavlink_gps_link(url: str, signing_key: bytes | None = None) -> MavlinkLink:
    """GPS_INPUT's own MAVLink link: system 245, component 220, a HEARTBEAT as ``MAV_TYPE_ONBOARD_CONTROLLER``.

    The HEARTBEAT (``MAV_AUTOPILOT_INVALID``: a component, neither a vehicle nor a ground station,
    so it plays no part in ArduPilot's GCS failsafe) lets routers learn the route, and MAVProxy or
    QGroundControl in between see a live component.
    """
    m = mavutil().mavlink
    return MavlinkLink(
        url,
        SKYFIX_SYSID,
        GPS_COMPID,
        name="GPS_INPUT link",
        signing_key=signing_key,
        heartbeat=(m.MAV_TYPE_ONBOARD_CONTROLLER, m.MAV_AUTOPILOT_INVALID),
    )


class GpsInputSink:
    """Worker sending GPS_INPUT through ``link`` (:func:`mavlink_gps_link` or
    :class:`~.zenoh_mavlink.ZenohMavlinkIn`); ``ok`` fixes pass ``gate`` first (:mod:`localizer.fix_gate`).

    :meth:`stop` ends it cleanly: one last no-fix GPS_INPUT (so the autopilot drops the
    position at once rather than after its 4 s timeout), then the link is closed.
    Cancelling :meth:`run` does the same.
    """

    def __init__(self, link, hz: float, max_age_s: float, gate: FixGate | None = None):
        self.link = link
        self.period_s = 1.0 / hz
        self.max_age_s = max_age_s
        self.gate = gate if gate is not None else FixGate(max_age_s=max_age_s)
        self.sent = 0
        self.sent_valid = 0
        self.not_delivered = 0  # handed to a link that was down
        self.last_fix_type: int | None = None
        self.last_sent_t: float | None = None  # UNIX s, station clock
        self.no_fix_reason: str | None = None  # why the last message said no fix (:mod:`.no_fix`)
        self.sent_fix: Fix | None = None  # the fix the last message carried, when it carried one
        # frame arrival → GPS_INPUT sent, new fixes
        self.latencies_s: deque[float] = deque(maxlen=100_000)
        self._fix: Fix | None = None
        self._info = None
        self._new = asyncio.Event()
        self._last_ok: Fix | None = None
        self._refusal: str | None = None  # the gates' word for the newest ok fix (None: taken)
        self._lock = 0  # the operator's commands before the newest frame (FrameInfo.lock)
        self._stopping = False
        self._closed = False
        # the loop (new fixes) and the keep-alive thread both send
        self._send_lock = threading.Lock()
        # time.monotonic() by which the keep-alive sends if nothing else was sent
        self._next_due = 0.0
        self._keep_alive = Supervised("GPS_INPUT keep-alive", self._keep_alive_body)

    def on_fix(self, fix: Fix, info) -> None:
        lock = getattr(info, "lock", 0)
        if lock != self._lock:  # the operator selected (released, acquired): a new lock
            self._lock = lock
            self._last_ok = None
            self.gate.target_lost()
        if fix.ok:
            t_mono = getattr(info, "t_recv_mono", None)
            arrival = Arrival(info.t_recv, t_mono, time.monotonic()) if t_mono is not None else None
            self._refusal = self.gate.check(
                fix, time.time(), getattr(info, "window", None), arrival
            )
            if self._refusal is None:
                self._last_ok = fix
        elif fix.status in LOSS_STATUSES:
            self._last_ok = None
            self.gate.target_lost()
        self._fix, self._info = fix, info
        self._new.set()

    async def run(self) -> None:
        await in_thread(self.link.open, name="GPS_INPUT open")
        self._keep_alive.start()
        try:
            while not self._stopping:
                await self._new.wait()
                if self._stopping:
                    break
                self._new.clear()
                self._send(fresh=True)
        finally:
            await self.stop()

    def _keep_alive_body(self, stop: threading.Event) -> None:
        """The keep-alive thread: the latest state again whenever ``1 / hz`` passed without a message."""
        while not stop.wait(max(0.0, self._next_due - time.monotonic())):
            if time.monotonic() >= self._next_due:
                self._send(fresh=False)

    async def stop(self) -> None:
        """The last GPS_INPUT, no fix, then the link closed; further calls do nothing."""
        if self._closed:
            return
        self._stopping = self._closed = True
        self._new.set()
        await in_thread(self._keep_alive.join, STOP_WAIT_S, name="GPS_INPUT keep-alive stop")
        final = gps_input_fields(None, time.time(), self.max_age_s)
        delivered = await in_thread(self.link.close, ("GPS_INPUT", final), name="GPS_INPUT close")
        self._sent(final, None, "stopped", delivered)
        log.info(
            "GPS_INPUT %s: stopped; %s",
            self.link.url,
            "the last message said no fix" if delivered else "the link was down: no last message",
        )

    def _send(self, fresh: bool) -> None:
        """The latest state now (the event loop for a new fix, ``fresh``; the keep-alive thread otherwise)."""
        with self._send_lock:
            if self._stopping:
                return  # the last message is the no-fix stop() sends
            self._next_due = time.monotonic() + self.period_s
            last_ok, latest = self._last_ok, self._fix
            fields = gps_input_fields(last_ok, time.time(), self.max_age_s)
            delivered = self.link.send("GPS_INPUT", fields)
            valid = fields["fix_type"] == FIX_3D
            t_sent = self._sent(
                fields,
                last_ok if valid else None,
                None if valid else no_fix_reason(latest, self._refusal),
                delivered,
            )
            if valid and delivered and fresh and latest is last_ok:
                self.latencies_s.append(t_sent - self._info.t_recv)

    def _sent(self, fields: dict, fix: Fix | None, reason: str | None, delivered: bool) -> float:
        """Counts a message handed to the link (``fix`` the one it carried, ``reason`` why none); its time."""
        self.last_sent_t = time.time()
        self.sent += 1
        self.not_delivered += not delivered
        self.sent_valid += fix is not None and delivered
        self.last_fix_type, self.sent_fix, self.no_fix_reason = fields["fix_type"], fix, reason
        return self.last_sent_t

    def sending(self) -> tuple[int | None, str | None]:
        """What the last message said: its fix_type and why no fix (the web page pushes a change at once)."""
        return self.last_fix_type, self.no_fix_reason

    def status(self, now: float) -> dict:
        fix, reason = (
            self.sent_fix,
            self.no_fix_reason,
        )  # the keep-alive thread may replace them meanwhile
        return {
            "url": self.link.url,
            "sent": self.sent,
            "sent_valid": self.sent_valid,
            "not_delivered": self.not_delivered,
            "last_fix_type": self.last_fix_type,
            "last_sent_t": self.last_sent_t,
            "no_fix_reason": reason,
            "no_fix_why": NO_FIX_WHY.get(reason),
            "sent_h_acc_m": None if fix is None else fix.h_acc_m,  # the gates took it: finite
            "sent_fix_t": None if fix is None else fix.t_unix,
            "keep_alive_restarts": self._keep_alive.restarts,
            "keep_alive_failure": self._keep_alive.failure,
            "link": self.link.status(now),
            "gates": self.gate.status(now),
        }

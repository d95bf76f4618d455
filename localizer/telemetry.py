"""The telemetry a fix needs, aligned to the station clock.

One time base: the station's clock (frames, depth arrivals and MAVLink receive
times are stamped with it). The UAV's samples carry its autopilot's
``time_boot_ms``; each is stored at ``boot + offset``, the offset being the least
``receive − boot`` over a sliding window (:class:`~localizer.clock.ClockMap`), i.e.
when the fastest delivery would have brought it. A frame at station time ``t`` is
looked up at ``t + uav_latency_s``, the link's one-way delay: configured
(``[timing] mavlink_latency_s``), else measured with MAVLink TIMESYNC, else the
frames' offset to the telemetry estimated from the video's motion
(:meth:`Telemetry.set_motion_latency`, offline), else unknown and taken as 0
(:attr:`Telemetry.latency_source` says which: :data:`LATENCY_SOURCES`).
A reboot of the autopilot (its boot clock going back) starts a new clock segment;
samples from before it keep their times and stay usable. A MAVLink gimbal with
its own boot clock gets its own :class:`~localizer.clock.ClockMap` onto the same scale.

SYSTEM_TIME does not align anything: it measures the station clock's offset from
GNSS time (:attr:`Telemetry.station_minus_gnss_s`), which gives GPS_INPUT its
week time. The UUV's depth is stored at station time: by the UUV's own stamp when
its clock agrees with the station's (within ``depth_clock_tolerance_s``), else
mapped by its arrival times minus ``depth_latency_s``; a depth from the UUV's autopilot
comes already mapped from its boot clock (:class:`localizer.depth.ArduSubDepth`). Each depth
sample keeps its 1-sigma, its source (a word of :data:`localizer.depth.SOURCE_WORDS`, or the name of the depth
source that :meth:`Telemetry.name_depth_source` was given) and the vehicle's vertical speed, which
:func:`localizer.depth.frame_sigma_m` grows its sigma with.

Angles in radians, positions in degrees and metres, rates per second.
"""

from __future__ import annotations

import math

import numpy as np

from .attitude import euler_rates
from .calibration import Timing
from .clock import OUTLIER, RESTART, STEP, ClockMap, Median, RoundTrip
from .depth import DEPTH_RANGE_M, SOURCE_WORDS
from .height import rangefinder_height_m, rangefinder_sigma_m
from .timeline import Series

#: Station-clock disagreements (seconds) worth telling the operator about.
CLOCK_NOTICE_S = 0.1
# latitude degrees per metre north (sphere; for rates only)
DEG_PER_M = math.degrees(1.0 / 6_378_137.0)
_NOTICE_AFTER = 3  # samples before a clock offset is reported
#: A SYSTEM_TIME sample of the station-minus-GNSS offset this far (s) from the median is a step of the station clock
#: (NTP, an operator) once :data:`GNSS_STEP_SAMPLES` of them in a row agree within :data:`GNSS_STEP_AGREE_S`: the
#: offset restarts from them (:attr:`Telemetry.gnss_clock_steps`); one alone is an outlier and moves nothing.
GNSS_STEP_S = 1.0
GNSS_STEP_SAMPLES = 2
GNSS_STEP_AGREE_S = 0.25
_ASIDE_MAX = 256  # samples kept aside while a clock waits for a reboot's confirmation
#: Where the UAV link's delay in use comes from (a frame's ``time_source``), and what each word means.
LATENCY_SOURCES = {
    "configured": "[timing] mavlink_latency_s",
    "timesync": "measured with MAVLink TIMESYNC",
    "motion": "the frames' offset to the telemetry, estimated from the video's motion against the camera attitude",
    "unknown": "neither stated, measured nor estimated: taken as 0, its 1-sigma [timing] unknown_latency_sigma_s",
}

# a GPS_RAW_INT time_usec below this (31 years) counts from the autopilot's boot
_BOOT_USEC_MAX = 10**15


class DepthSeries(Series):
    """The UUV's depth below the surface (m, positive down), its 1-sigma (m; NaN: the calibration's), the vehicle's
    vertical speed (m/s, positive down; NaN: unknown) and its source, an index into :attr:`words` (those of
    :data:`~localizer.depth.SOURCE_WORDS`, then the names given to :meth:`Telemetry.name_depth_source`)."""

    def __init__(self, max_gap_s: float, max_hold_s: float, keep_s: float | None):
        super().__init__("lsss", max_gap_s, max_hold_s, keep_s)
        self.words: list[str] = list(SOURCE_WORDS)


class Telemetry:
    """Buffers for ATTITUDE, GLOBAL_POSITION_INT, the gimbal message, GPS_RAW_INT and depth.

    ``keep_s`` bounds the history kept (live service); None keeps all (offline).
    Every ``add_*`` returns False when it refuses a sample, with the reason in
    :attr:`refusal`; only samples that pass reach the clocks, so a garbage frame
    cannot fake a reboot. :attr:`notices` collects one-line news for the log
    (reboots, clocks that disagree): the caller takes them out.
    """

    def __init__(self, timing: Timing | None = None, keep_s: float | None = None):
        self.timing = timing = timing or Timing()
        w = timing.clock_window_s
        # the autopilot's time_boot_ms (the component that sends ATTITUDE)
        self.uav_clock = ClockMap(w)
        self._component_clocks: dict[
            int, ClockMap
        ] = {}  # other components' boot clocks (a MAVLink gimbal)
        self.timesync = RoundTrip(w)
        self._measured_latency_s: float | None = None
        # arrival (station s) of the first TIMESYNC measurement
        self.measured_latency_from_s: float | None = None
        # (delay, 1-sigma) from the video's motion, s
        self._motion_latency: tuple[float, float] | None = None
        self._gnss = Median()  # arrival-scale minus GNSS time, per SYSTEM_TIME
        self._gnss_new: list[
            float
        ] = []  # samples off the median by a step, not yet agreeing enough
        self.gnss_clock_steps = 0  # station clock steps seen against GNSS time (SYSTEM_TIME)
        self.last_gnss_clock_step_s: float | None = None
        self.uuv_clock = ClockMap(w)  # the UUV's own depth stamps
        self.depth_aligned_by: str | None = None  # "uuv_clock", "arrival" or "autopilot_clock"
        # roll, pitch, yaw of the UAV body (FRD in NED) and their rates
        self.attitude = Series("HHHddd", timing.attitude_gap_s, timing.attitude_hold_s, keep_s)
        # lat_deg, lon_deg, alt_amsl_m, relative_alt_m and their rates
        self.position = Series("hhhhdddd", timing.position_gap_s, timing.position_hold_s, keep_s)
        # GIMBAL_DEVICE_ATTITUDE_STATUS: q (w, x, y, z), flags
        self.gimbal = Series("qqqqs", timing.gimbal_gap_s, timing.gimbal_hold_s, keep_s)
        # MOUNT_ORIENTATION: roll, pitch, yaw relative to the vehicle
        self.mount = Series("aaa", timing.gimbal_gap_s, timing.gimbal_hold_s, keep_s)
        # GPS_RAW_INT at receive times: the receiver's horizontal accuracy (m), the geoid separation (m), fix_type,
        # the GNSS altitude (m AMSL), vertical accuracy (m), HDOP and VDOP (NaN: not given); see add_gps_raw
        self.gnss = Series("sssssss", math.inf, 10.0, keep_s)
        # the UUV's depth, station seconds (see DepthSeries); a depth added without a source word is depth_source's
        self.depth = DepthSeries(timing.depth_gap_s, timing.depth_hold_s, keep_s)
        self.depth_source = "skyfix"
        # absolute measurements of the UAV's height above the water, per source ("rangefinder", "size", ...):
        # the reported position's height (m) and its 1-sigma (m), on the UAV buffers' time scale
        self.height_fixes: dict[str, Series] = {}
        # the height filter over them (localizer.height), made on first use
        self.height_estimator = None
        # offline (the whole recording): each height uses the measurements after it too (localizer.height)
        self.height_two_sided = False
        self.armed: bool | None = None  # the autopilot's HEARTBEAT SAFETY_ARMED flag, once seen
        self.arm_times: list[float] = []  # when it armed (UAV buffers' scale), transitions seen
        # a downward DISTANCE_SENSOR came: ArduPilot's RANGEFINDER is its copy
        self.distance_sensor_seen = False
        # readings at or beyond their range: no return from the water
        self.rangefinder_out_of_range = 0
        self._keep_s = keep_s
        self.autopilot_component: int | None = None
        self.mount_type: int | None = None  # the autopilot's MNT1_TYPE parameter, once seen
        self.refusal: str | None = None
        self._boot_s = math.nan  # the boot time of the sample being added
        self._aside: dict[
            int, list
        ] = {}  # per clock: samples that did not fit it, until it confirms or drops them
        self._last_boot: dict[int, float] = {}  # per series: the boot time of its newest sample
        self.notices: list[str] = []
        self._noticed: dict[str, float] = {}

    @property
    def keep_s(self) -> float | None:
        """How long the buffers keep samples (live), or None (offline: everything)."""
        return self._keep_s

    # -- clocks --------------------------------------------------------------------------------
    @property
    def uav_latency_s(self) -> float:
        """The UAV link's one-way delay (s) subtracted from the least-delay alignment."""
        if self.timing.mavlink_latency_s is not None:
            return self.timing.mavlink_latency_s
        if self._measured_latency_s is not None:
            return self._measured_latency_s
        return self._motion_latency[0] if self._motion_latency is not None else 0.0

    @property
    def latency_source(self) -> str:
        """Where :attr:`uav_latency_s` comes from: a word of :data:`LATENCY_SOURCES`."""
        if self.timing.mavlink_latency_s is not None:
            return "configured"
        if self._measured_latency_s is not None:
            return "timesync"
        return "motion" if self._motion_latency is not None else "unknown"

    @property
    def latency_sigma_s(self) -> float:
        """The 1-sigma (s) of :attr:`uav_latency_s` beyond ``[uncertainty] time_s``: 0 when stated or measured,
        the estimate's from the video's motion, ``[timing] unknown_latency_sigma_s`` when unknown."""
        source = self.latency_source
        if source == "motion":
            return self._motion_latency[1]
        return self.timing.unknown_latency_sigma_s if source == "unknown" else 0.0

    def set_motion_latency(self, offset_s: float, sigma_s: float) -> None:
        """The frames' offset to the telemetry (s; a frame at ``t`` matches the telemetry at ``t + offset_s``
        as aligned now), estimated from the video's motion: taken as the link's delay where it is neither
        configured nor measured. Signed: frames stamped late (a video latency set too low) give a negative one."""
        self._motion_latency = (self.uav_latency_s + offset_s, sigma_s)

    @property
    def measured_latency_s(self) -> float | None:
        """The link delay TIMESYNC measured (s), whether or not it is used."""
        return self._measured_latency_s

    def uav_time(self, t_station):
        """Station time(s) as the UAV buffers' time scale (see the module doc)."""
        return np.asarray(t_station, dtype=float) + self.uav_latency_s

    @property
    def station_minus_gnss_s(self) -> float | None:
        """The station clock minus GNSS time (s), from SYSTEM_TIME; None without it."""
        x = self._gnss.value
        return None if x is None else x - self.uav_latency_s

    @property
    def uuv_clock_minus_station_s(self) -> float | None:
        """The UUV's clock minus the station's (s), from its depth stamps and arrivals; None without them."""
        off = self.uuv_clock.offset_s
        return None if off is None else -(off - self.timing.depth_latency_s)

    def _notice_once(self, key: str, value: float, text: str) -> None:
        """Add ``text`` to the notices unless ``key`` was reported within CLOCK_NOTICE_S of ``value``."""
        last = self._noticed.get(key)
        if last is None or abs(value - last) > CLOCK_NOTICE_S:
            self._noticed[key] = value
            self.notices.append(text)

    def _uav_t(
        self,
        time_boot_ms,
        receive_s: float,
        component: int | None,
        series: Series | None = None,
        values=None,
    ) -> float | None:
        """A sample's time on the UAV buffers' scale, feeding the clock of its component.

        None (the reason in :attr:`refusal`, ``series`` counting a rejection) when its boot time does
        not fit that clock (:class:`~localizer.clock.ClockMap`): such a sample is kept aside, and
        appended after all when the next ones confirm the new time (a reboot)."""
        boot_s = float(time_boot_ms) / 1000.0
        own = component is None or component == self.autopilot_component
        clock = (
            self.uav_clock
            if own
            else self._component_clocks.setdefault(component, ClockMap(self.timing.clock_window_s))
        )
        before = clock.last_source_s
        result = clock.add(boot_s, receive_s)
        aside = self._aside.setdefault(id(clock), [])
        if result == OUTLIER:
            if clock.candidates == 1:
                aside.clear()
            if series is not None and len(aside) < _ASIDE_MAX:
                aside.append((series, boot_s, values))
                series.rejected += 1
            elif series is not None:
                series.rejected += 1
            self.refusal = (
                f"time_boot_ms {boot_s:.3f} s does not fit the clock of its other messages "
                f"(latest {before:.3f} s); a reboot is taken once samples agree for {clock.confirm_s} s"
            )
            return None
        if result == RESTART:
            was, now = clock.last_restart
            who = "autopilot" if own else f"component {component}"
            self.notices.append(
                f"the station clock stepped back ({who}'s time_boot_ms went on from {was:.1f} s to {now:.1f} s): "
                "a new clock segment; the telemetry before it is kept"
                if now >= was
                else f"{who} rebooted (time_boot_ms went back from {was:.1f} s to {now:.1f} s): "
                "a new clock segment; the telemetry before it is kept"
            )
            if own:
                self.timesync.clear()
                self._gnss.clear()
        if result in (RESTART, STEP):
            for s, b, v in aside:  # confirmed after all
                s.rejected -= 1
                self._boot_s = b
                self._append_uav(s, b + clock.offset_s, v)
        aside.clear()
        self._boot_s = boot_s
        return boot_s + clock.offset_s

    def _refuse(self, series: Series, why: str) -> bool:
        series.rejected += 1
        self.refusal = why
        return False

    def _append(self, series: Series, t: float, values) -> bool:
        if series.append(t, values):
            return True
        self.refusal = "not finite, or not after the previous sample"
        return False

    def _append_uav(self, series: Series, t: float, values) -> bool:
        """Append a UAV sample. One that follows the previous on its own clock but not on the station's
        (the least-delay offset just improved by more than the sample interval: the first
        samples of a link) is dropped without complaint: it carries nothing wrong."""
        last_boot = self._last_boot.get(id(series))
        if (
            series.last_t is not None
            and t <= series.last_t
            and last_boot is not None
            and self._boot_s > last_boot
        ):
            self._last_boot[id(series)] = self._boot_s
            return True
        if not self._append(series, t, values):
            return False
        self._last_boot[id(series)] = self._boot_s
        return True

    # -- MAVLink ---------------------------------------------------------------------------------
    def add_attitude(self, time_boot_ms, roll, pitch, yaw, rates, receive_s: float) -> bool:
        """ATTITUDE (radians) with its body rates ``(p, q, r)`` (rad/s, FRD; None or NaN: unknown)."""
        if not all(abs(a) <= 2 * np.pi for a in (roll, pitch, yaw)):
            return self._refuse(
                self.attitude, "angles not finite or beyond ±2π (degrees sent as radians?)"
            )
        p, q, r = (math.nan,) * 3 if rates is None else rates
        if not all(
            abs(x) < 100.0 for x in (p, q, r)
        ):  # NaN and absurd rates alike: interpolate linearly
            p = q = r = math.nan
        values = (roll, pitch, yaw, *euler_rates(roll, pitch, p, q, r))
        t = self._uav_t(time_boot_ms, receive_s, None, self.attitude, values)
        return t is not None and self._append_uav(self.attitude, t, values)

    def add_position(
        self,
        time_boot_ms,
        lat_deg,
        lon_deg,
        alt_amsl_m,
        relative_alt_m,
        velocity_ned_mps,
        receive_s: float,
    ) -> bool:
        """GLOBAL_POSITION_INT in degrees, metres and m/s (velocity None: unknown)."""
        if lat_deg == 0 and lon_deg == 0:
            return self._refuse(self.position, "lat/lon 0/0: the UAV has no GPS fix yet")
        if not (-90 <= lat_deg <= 90 and -180 <= lon_deg <= 180):
            return self._refuse(self.position, "lat/lon out of range (degE7 not converted?)")
        if not np.all(np.isfinite((alt_amsl_m, relative_alt_m))):
            return self._refuse(self.position, "altitude not finite")
        vn, ve, vd = (math.nan,) * 3 if velocity_ned_mps is None else velocity_ned_mps
        rates = (vn * DEG_PER_M, ve * DEG_PER_M / math.cos(math.radians(lat_deg)), -vd, -vd)
        values = (lat_deg, lon_deg, alt_amsl_m, relative_alt_m, *rates)
        t = self._uav_t(time_boot_ms, receive_s, None, self.position, values)
        return t is not None and self._append_uav(self.position, t, values)

    def add_gimbal(
        self, time_boot_ms, q_wxyz, flags, receive_s: float, component: int | None = None
    ) -> bool:
        """GIMBAL_DEVICE_ATTITUDE_STATUS quaternion (w, x, y, z), which must be near unit length."""
        q = np.asarray(q_wxyz, dtype=float)
        if q.shape != (4,) or not np.all(np.isfinite(q)) or abs(np.linalg.norm(q) - 1.0) > 0.1:
            return self._refuse(self.gimbal, "quaternion not finite or not of unit length")
        values = (*q, flags)
        t = self._uav_t(time_boot_ms, receive_s, component, self.gimbal, values)
        return t is not None and self._append_uav(self.gimbal, t, values)

    def add_mount(
        self,
        time_boot_ms,
        roll_deg,
        pitch_deg,
        yaw_deg,
        receive_s: float,
        component: int | None = None,
    ) -> bool:
        """MOUNT_ORIENTATION (degrees; yaw relative to the vehicle)."""
        if not all(abs(a) <= 360.0 for a in (roll_deg, pitch_deg, yaw_deg)):
            return self._refuse(self.mount, "angles not finite or beyond ±360°")
        values = np.radians((roll_deg, pitch_deg, yaw_deg))
        t = self._uav_t(time_boot_ms, receive_s, component, self.mount, values)
        return t is not None and self._append_uav(self.mount, t, values)

    def add_system_time(self, time_boot_ms, time_unix_usec: int, receive_s: float) -> bool:
        """SYSTEM_TIME: feeds the autopilot's clock; a GNSS time (nonzero) measures the station's offset."""
        t = self._uav_t(time_boot_ms, receive_s, None)
        if t is None:
            return False
        if time_unix_usec <= 0:
            return True  # the autopilot has no UNIX time yet
        self._gnss_sample(t - time_unix_usec / 1e6)
        off = self.station_minus_gnss_s
        if len(self._gnss) >= _NOTICE_AFTER and abs(off) > CLOCK_NOTICE_S:
            way = "behind" if off < 0 else "ahead of"
            self._notice_once(
                "gnss",
                off,
                f"the station clock is {abs(off):.2f} s {way} GNSS time (SYSTEM_TIME): "
                "telemetry is aligned by receive times, GPS_INPUT carries GNSS time",
            )
        return True

    def _gnss_sample(self, x: float) -> None:
        """One station-minus-GNSS sample (s): into the median, or, off it by :data:`GNSS_STEP_S`, held until
        :data:`GNSS_STEP_SAMPLES` in a row agree: a step of the station clock, the median restarted from them (GNSS
        time does not step: the station clock did). Without this the median of the last 31 would keep the old
        offset until 16 samples of the new (GPS_INPUT's time that far off meanwhile)."""
        median = self._gnss.value
        if median is None or abs(x - median) <= GNSS_STEP_S:
            self._gnss_new.clear()
            self._gnss.add(x)
            return
        self._gnss_new.append(x)
        new = self._gnss_new[-GNSS_STEP_SAMPLES:]
        if len(new) == GNSS_STEP_SAMPLES and max(new) - min(new) <= GNSS_STEP_AGREE_S:
            self.gnss_clock_steps += 1
            self.last_gnss_clock_step_s = float(np.median(new)) - median
            self._gnss.clear()
            for v in new:
                self._gnss.add(v)
            self._gnss_new.clear()
            self.notices.append(
                f"the station clock stepped {self.last_gnss_clock_step_s:+.2f} s against GNSS time (SYSTEM_TIME): "
                "GPS_INPUT's time follows the new offset"
            )

    def add_timesync(self, tc1_ns: int, ts1_ns: int, receive_s: float) -> bool:
        """A TIMESYNC reply to our request: ``ts1`` our send time (station ns), ``tc1`` the autopilot's receipt (boot ns)."""
        if tc1_ns <= 0 or not self.timesync.add(tc1_ns / 1e9, ts1_ns / 1e9, receive_s):
            self.refusal = "not a reply to a request of this station"
            return False
        delay = self.timesync.one_way_delay_s(self.uav_clock)
        if delay is not None:
            if self._measured_latency_s is None:
                self.measured_latency_from_s = receive_s
            self._measured_latency_s = max(0.0, delay)
        return True

    def add_gps_raw(
        self,
        time_usec: int,
        fix_type: int,
        alt_amsl_m: float,
        h_acc_m: float,
        v_acc_m: float,
        hdop: float,
        vdop: float,
        geoid_separation_m: float,
        receive_s: float,
    ) -> bool:
        """GPS_RAW_INT: its time, fix type, the GNSS altitude (m AMSL), the receiver's accuracies (m), HDOP, VDOP
        and the geoid separation (m); NaN (or 0 for the accuracies and DOPs) where the receiver gives none.

        Stored at the fix's own time on the UAV buffers' scale where it can be told (GNSS altitudes are
        compared with the EKF's height at that time): ``time_usec`` since boot (ArduPilot: the last fix's
        time) on the autopilot's clock, or UNIX time through SYSTEM_TIME's GNSS time; else at its arrival."""

        def given(x):
            return x if math.isfinite(x) and x > 0 else math.nan

        if fix_type >= 3 and not -1000.0 < alt_amsl_m < 10_000.0:
            return self._refuse(
                self.gnss,
                f"GNSS altitude {alt_amsl_m!r} m outside (-1000, 10000) (mm not converted?)",
            )
        t = receive_s
        if 0 < time_usec < _BOOT_USEC_MAX and self.uav_clock.offset_s is not None:
            t = time_usec / 1e6 + self.uav_clock.offset_s
        elif time_usec >= _BOOT_USEC_MAX and self._gnss.value is not None:
            t = time_usec / 1e6 + self._gnss.value
        if not abs(t - receive_s) < 1.0:  # a stale or mistimed fix: at its arrival
            t = receive_s
        alt = alt_amsl_m if fix_type >= 3 and math.isfinite(alt_amsl_m) else math.nan
        values = (
            given(h_acc_m),
            geoid_separation_m,
            float(fix_type),
            alt,
            given(v_acc_m),
            given(hdop),
            given(vdop),
        )
        return self._append(self.gnss, t, values)

    def add_heartbeat(self, armed: bool, receive_s: float) -> None:
        """The autopilot's HEARTBEAT: whether it is armed; an arming seen (disarmed, then armed) is kept in
        :attr:`arm_times` at its receive time (a take-off's height reference is set then)."""
        if armed and self.armed is False:
            self.arm_times.append(receive_s)
        self.armed = armed

    def add_param(self, name: str, value: float) -> None:
        """A PARAM_VALUE of the autopilot; MNT1_TYPE tells what its gimbal reports."""
        if name == "MNT1_TYPE" and math.isfinite(value):
            self.mount_type = round(value)

    # -- height above the water ------------------------------------------------------------------
    def add_rangefinder(
        self,
        time_boot_ms,
        distance_m: float,
        min_m: float,
        max_m: float,
        receive_s: float,
        sigma_m: float | None = None,
    ) -> bool:
        """A downward rangefinder's reading (m along the body's down axis; ``time_boot_ms`` None: stamped by
        its arrival, ArduPilot's RANGEFINDER), added as a height above the water (``"rangefinder"``,
        :meth:`add_height`) with the attitude at its time. A reading outside ``[min_m, max_m)`` is no
        return (counted in :attr:`rangefinder_out_of_range`, not refused); ``sigma_m`` the sensor's own
        1-sigma, else :func:`localizer.height.rangefinder_sigma_m`."""
        if not (math.isfinite(distance_m) and min_m <= distance_m < max_m and distance_m > 0):
            self.rangefinder_out_of_range += 1
            return False
        if time_boot_ms is None:
            t = receive_s
        else:
            t = self._uav_t(time_boot_ms, receive_s, None)
            if t is None:
                return False
        att, status, _ = self.attitude.sample(np.array([t]))
        if status[0] != 0:
            self.refusal = "no ATTITUDE at its time to turn the slant range into a height"
            return False
        height = float(rangefinder_height_m(distance_m, att[0, 0], att[0, 1]))
        sigma = rangefinder_sigma_m(distance_m) if sigma_m is None else sigma_m
        return self.add_height("rangefinder", t, height, sigma)

    def add_height(self, source: str, t_uav: float, uav_height_m: float, sigma_m: float) -> bool:
        """An absolute measurement of the height of the UAV's reported position above the water (m, with
        its 1-sigma) at ``t_uav`` (the UAV buffers' time scale: :meth:`uav_time` of a station time)."""
        series = self.height_fixes.setdefault(
            source, Series("ll", math.inf, math.inf, self._keep_s)
        )
        if not (0.0 < uav_height_m < 10_000.0 and 0.0 < sigma_m < 1_000.0):
            return self._refuse(
                series,
                f"height {uav_height_m!r} m or its sigma {sigma_m!r} m not finite and positive",
            )
        return self._append(series, t_uav, (uav_height_m, sigma_m))

    # -- depth -----------------------------------------------------------------------------------
    def add_depth(
        self,
        t_source: float,
        depth_m: float,
        receive_s: float | None = None,
        *,
        sigma_m: float = math.nan,
        source: str | None = None,
        vspeed_mps: float = math.nan,
    ) -> bool:
        """The UUV's depth (m, positive down), stamped ``t_source`` by the UUV and received at ``receive_s``.

        Without ``receive_s`` (sessions that did not record arrivals) the UUV's stamp
        is taken as station time. ``sigma_m`` (NaN: the calibration's), ``source`` (None:
        :attr:`depth_source`) and ``vspeed_mps`` (positive down, NaN: unknown) are kept with it.
        """
        source = self.depth_source if source is None else source
        if not self._depth_ok(depth_m, source):
            return False
        latency = self.timing.depth_latency_s
        if receive_s is None:
            t = t_source
        else:
            if not math.isfinite(t_source):
                return self._refuse(self.depth, "time not finite")
            if self.uuv_clock.add(t_source, receive_s) == OUTLIER:
                return self._refuse(
                    self.depth,
                    f"t {t_source:.3f} does not fit the UUV's clock of its other samples; "
                    f"a clock step is taken once samples agree for {self.uuv_clock.confirm_s} s",
                )
            station_minus_uuv = self.uuv_clock.offset_s - latency
            if abs(station_minus_uuv) <= self.timing.depth_clock_tolerance_s:
                t, self.depth_aligned_by = t_source, "uuv_clock"
            else:
                t, self.depth_aligned_by = t_source + station_minus_uuv, "arrival"
                if self.uuv_clock.segments or len(self.depth) >= _NOTICE_AFTER:
                    self._notice_once(
                        "uuv",
                        -station_minus_uuv,
                        f"the UUV's clock is {-station_minus_uuv:+.2f} s "
                        "off the station's: its depth is aligned by arrival times",
                    )
        return self._append(
            self.depth, t, (depth_m, sigma_m, vspeed_mps, self.depth.words.index(source))
        )

    def name_depth_source(self, name: str) -> None:
        """Depths added without a source word are ``name``'s from now on (the live depth source's name, as the
        service registered it): a word of this telemetry's depth."""
        if name not in self.depth.words:
            self.depth.words.append(name)
        self.depth_source = name

    def add_autopilot_depth(
        self, t_station: float, depth_m: float, sigma_m: float, source: str, vspeed_mps: float
    ) -> bool:
        """A depth from the UUV's autopilot, already on the station clock (mapped from its boot clock)."""
        if not self._depth_ok(depth_m, source):
            return False
        self.depth_aligned_by = "autopilot_clock"
        return self._append(
            self.depth, t_station, (depth_m, sigma_m, vspeed_mps, self.depth.words.index(source))
        )

    def _depth_ok(self, depth_m: float, source: str) -> bool:
        if source not in self.depth.words:
            return self._refuse(
                self.depth, f"depth source {source!r} is not one of {', '.join(self.depth.words)}"
            )
        if not (
            isinstance(depth_m, (int, float)) and DEPTH_RANGE_M[0] <= depth_m <= DEPTH_RANGE_M[1]
        ):
            return self._refuse(
                self.depth,
                f"depth_m not finite or outside [{DEPTH_RANGE_M[0]:g}, {DEPTH_RANGE_M[1]:g}]",
            )
        return True

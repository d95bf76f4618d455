"""The UUV's depth: its autopilot's readings made into one depth with a 1-sigma and a source word; jumps refused.

What ArduSub reports, read in ArduPilot's source and checked on the ArduSub SITL (ArduPilot master of
2025-07-21, "ArduSub V4.7.0-dev"):

- **The depth sensor's pressure.** ``Sub::init_ardupilot`` makes the first water-type barometer the primary
  (``BARO_PRIMARY``, 0-based; its pressure is ``SCALED_PRESSURE`` for 0, ``SCALED_PRESSURE2`` for 1,
  ``SCALED_PRESSURE3`` for 2). ``AP_Baro::update`` turns it into ArduSub's depth with the sensor's ground
  pressure ``BARO{n}_GND_PRESS`` (the pressure where depth is zero: at boot its first reading, or a preflight
  calibration) and ``BARO_SPEC_GRAV`` (1.0 fresh water, 1.024 sea water):
  depth = (ground − pressure) / 9800 / specific gravity (:func:`depth_from_pressure_m`). This is the depth
  ArduSub's EKF, depth hold and ground station use.
- **Its EKF's height.** ``GLOBAL_POSITION_INT.relative_alt`` (``Sub::get_alt_rel``) is minus the EKF's down
  position while the EKF has no origin; once ArduSub has a home (it sets one as soon as the EKF has an origin and
  a position: skyfix's own first fixes), it subtracts the home's altitude above sea level from a position
  relative to the origin: relative_alt becomes origin altitude − depth, an altitude (measured on the SITL: 115.9
  at 4.1 m depth with the origin at 120 m). ``GLOBAL_POSITION_INT.alt`` (``Sub::get_alt_msl``, also
  ``VFR_HUD.alt``) is exactly 0 without an origin, else the origin's altitude minus the depth. So the EKF's depth is
  −relative_alt while alt is exactly 0 (no origin, hence no home), and the origin's altitude
  (``GPS_GLOBAL_ORIGIN``) minus alt after (:func:`ekf_depth_m`). ``VFR_HUD.alt`` is never a depth.

:class:`ArduSubDepth` follows both: the pressure depth is the measurement (``ardusub_pressure``) once its
parameters are known; the EKF's depth stands in only until the first pressure depth after the autopilot's
(re)boot (``ardusub_ekf``), never when the pressure pauses later (measured: while ArduSub recalibrates its
barometer, its EKF's depth wanders by metres); each pressure depth is cross-checked against the EKF's: a
disagreement beyond :data:`DISAGREE_M` is one warning line with both values and goes into that depth's sigma.
A ground pressure that would move the zero more than :data:`RECAL_MAX_DEPTH_M` down was taken under water
(measured: MAV_CMD_PREFLIGHT_CALIBRATION at 4 m sets BARO1_GND_PRESS to the pressure there): it is not
followed, and while ArduSub's EKF works from that other zero it is not compared. :class:`DepthGate` refuses
a depth that moved faster than the vehicle can dive. :func:`frame_sigma_m` grows a depth's sigma with its age
by the vehicle's vertical speed.

Units: metres (depth positive down), pascals, seconds; times of samples on the station clock.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .clock import OUTLIER, RESTART, ClockMap

#: ArduSub's pascals per metre of water of specific gravity 1 (AP_Baro::update: "9800 Pascal/m depth in water").
ARDUSUB_PA_PER_M = 9800.0
#: Where a depth came from (the word in the pose, the fix message and positions.csv): the built-in words. A live
#: depth source registered under another name records its name (passed in:
#: :meth:`~localizer.telemetry.Telemetry.name_depth_source`).
SOURCES = {
    "skyfix": "skyfix's JSON {t, depth_m} on Zenoh (skyfix replay, or the UUV's own publisher)",
    "session": "a recorded session's depth.jsonl that does not name its source",
    "ardusub_pressure": "ArduSub's depth sensor: SCALED_PRESSURE{BARO_PRIMARY+1} with BARO{n}_GND_PRESS and "
    "BARO_SPEC_GRAV, ArduSub's own formula",
    "ardusub_ekf": "ArduSub's EKF: -relative_alt before an EKF origin, the origin's altitude - alt after "
    "(while the pressure's parameters are not known yet)",
}
SOURCE_WORDS = tuple(SOURCES)
#: Pressure depth and EKF depth further apart than this (m) disagree (the EKF follows the same sensor: they
#: differ by centimetres, its lag, in a dive at 0.5 m/s on the SITL).
DISAGREE_M = 0.2
#: An EKF depth this close in time (s) to a pressure depth cross-checks it.
CROSSCHECK_S = 0.5
#: A new ground pressure that puts the old zero this deep (m) was taken under water: not followed.
RECAL_MAX_DEPTH_M = 0.5
#: Depths (m) that can be real: a little above the surface (waves, a sensor zeroed under water) to the deepest sea.
DEPTH_RANGE_M = (-5.0, 11000.0)
#: A BlueROV2's top vertical speed (m/s): its rated top speed, 1.5 m/s (3 knots).
BLUEROV2_MAX_VERTICAL_SPEED_MPS = 1.5


class DepthSample(NamedTuple):
    t: float  # station clock, when it was measured
    depth_m: float  # positive down
    sigma_m: float  # 1-sigma (NaN: the calibration's [uncertainty] depth_m)
    source: str  # a word of SOURCES
    vspeed_mps: float  # the vehicle's vertical speed, positive down (NaN: unknown)


def depth_from_pressure_m(pressure_pa, ground_pressure_pa, specific_gravity):
    """ArduSub's depth (m, positive down) of a water pressure sensor reading, as ``AP_Baro::update`` computes it."""
    return (
        (np.asarray(pressure_pa, dtype=float) - ground_pressure_pa)
        / ARDUSUB_PA_PER_M
        / specific_gravity
    )


def ekf_depth_m(
    relative_alt_m: float, alt_amsl_m: float, origin_amsl_m: float | None
) -> float | None:
    """ArduSub's EKF depth (m) from GLOBAL_POSITION_INT (see the module doc); None when it has an origin whose
    altitude is not known."""
    if alt_amsl_m == 0.0:
        return -relative_alt_m
    return None if origin_amsl_m is None else origin_amsl_m - alt_amsl_m


def crosscheck_sigma_m(sigma_m: float, disagreement_m):
    """A pressure depth's 1-sigma (m) given its difference from the EKF's depth (m, scalar or array): its own within
    :data:`DISAGREE_M`, else with the difference added in quadrature."""
    d = np.asarray(disagreement_m, dtype=float)
    return np.where(np.abs(d) <= DISAGREE_M, sigma_m, np.hypot(sigma_m, d))


def frame_sigma_m(sigma_m, vspeed_mps, held_error_m, age_s, default_sigma_m: float):
    """A depth's 1-sigma at frames ``age_s`` past its newest sample (0 between samples).

    ``sigma_m``: the samples' own (NaN: ``default_sigma_m``, the calibration's); grown in quadrature by the
    larger of the vehicle's vertical speed (``vspeed_mps``, NaN: unknown) and the depth's own last rate of
    change (``held_error_m``, already × age: :meth:`~localizer.timeline.Series.sample`'s error) times the age.
    """
    base = np.where(np.isfinite(sigma_m), sigma_m, default_sigma_m)
    moved = np.fmax(
        np.abs(np.asarray(vspeed_mps, dtype=float)) * age_s, np.nan_to_num(held_error_m)
    )
    return np.hypot(base, np.nan_to_num(moved))


class DepthGate:
    """Refuses a depth that moved faster than the vehicle can dive.

    A sample is accepted when it lies within ``max_vertical_speed_mps`` × Δt + 3 × its and the last accepted
    sample's combined sigma (``sigma_m`` for a sample without one) of that sample. Refused samples that agree with each other in the same way become
    the reference once :attr:`confirm` of them span :attr:`confirm_s` (a real step: a recalibrated sensor, a
    source back after a long gap), so one garbage value cannot stop the depth for good; :attr:`notices` then
    says so (the caller takes them out).
    """

    def __init__(
        self,
        max_vertical_speed_mps: float = BLUEROV2_MAX_VERTICAL_SPEED_MPS,
        sigma_m: float = 0.05,
        confirm: int = 5,
        confirm_s: float = 1.0,
    ):
        self.max_vertical_speed_mps = max_vertical_speed_mps
        self.sigma_m = sigma_m
        self.confirm, self.confirm_s = confirm, confirm_s
        self._last: tuple[float, float, float] | None = None  # t, depth, sigma of the last accepted
        self._chain: list[tuple[float, float, float]] = []
        self.refused = 0
        self.confirmed_steps = 0
        self.notices: list[str] = []

    def _fits(self, ref, t: float, depth: float, sigma: float) -> bool:
        t0, d0, s0 = ref
        return abs(depth - d0) <= self.max_vertical_speed_mps * abs(t - t0) + 3.0 * math.hypot(
            sigma, s0
        )

    def check(self, t: float, depth_m: float, sigma_m: float = math.nan) -> str | None:
        """None when the sample is accepted, else why not (one line with the values); a depth outside
        :data:`DEPTH_RANGE_M` is refused as such."""
        if not DEPTH_RANGE_M[0] <= depth_m <= DEPTH_RANGE_M[1]:
            return f"depth_m = {depth_m!r} outside [{DEPTH_RANGE_M[0]:g}, {DEPTH_RANGE_M[1]:g}]"
        sample = (t, depth_m, sigma_m if math.isfinite(sigma_m) else self.sigma_m)
        if self._last is None or self._fits(self._last, *sample):
            self._last, self._chain = sample, []
            return None
        if self._chain and not self._fits(self._chain[-1], *sample):
            self._chain = []
        self._chain.append(sample)
        if (
            len(self._chain) >= self.confirm
            and self._chain[-1][0] - self._chain[0][0] >= self.confirm_s
        ):
            self.notices.append(
                f"depth stepped from {self._last[1]:.2f} m to {depth_m:.2f} m and stayed there for "
                f"{len(self._chain)} samples over {self._chain[-1][0] - self._chain[0][0]:.1f} s: "
                "taken as the depth from now on"
            )
            self._last, self._chain = sample, []
            self.confirmed_steps += 1
            return None
        self.refused += 1
        t0, d0, _ = self._last
        return (
            f"depth {depth_m:.2f} m refused: {abs(depth_m - d0):.2f} m from {d0:.2f} m {t - t0:+.2f} s "
            f"before, faster than the vehicle can dive (uuv_max_vertical_speed_mps = "
            f"{self.max_vertical_speed_mps:g})"
        )


#: ArduSub's pressure messages by barometer instance (0-based).
PRESSURE_MESSAGES = ("SCALED_PRESSURE", "SCALED_PRESSURE2", "SCALED_PRESSURE3")


def ground_pressure_param(instance: int) -> str:
    """The name of barometer ``instance``'s (0-based) ground pressure parameter."""
    return f"BARO{instance + 1}_GND_PRESS"


class ArduSubDepth:
    """ArduSub's depth from its messages (values in SI units: :func:`groundstation.mavlink.ingest.ingest_ardusub`
    converts them), as :class:`DepthSample` on the station clock; see the module doc.

    ``sigma_m`` is the depth sensor's 1-sigma (the calibration's ``[uncertainty] depth_m``), ``latency_s`` the
    time from measurement to arrival (``[timing] depth_latency_s``): the autopilot's ``time_boot_ms`` is mapped
    onto the station clock by the least arrival − boot time (:class:`~localizer.clock.ClockMap`) minus it.
    A sample whose boot time does not fit that clock is refused (:attr:`refusal`) until a reboot is
    confirmed; after one the parameters are asked for again (:meth:`wanted_params`). :attr:`notices` collects
    one-line news for the log; the caller takes them out.
    """

    def __init__(self, sigma_m: float, latency_s: float, window_s: float = 30.0):
        self.sigma_m = sigma_m
        self.latency_s = latency_s
        self.clock = ClockMap(window_s)
        self.primary: int | None = None  # BARO_PRIMARY
        self.ground_pa: dict[int, float] = {}  # BARO{n}_GND_PRESS by 0-based instance, as used
        self.specific_gravity: float | None = None  # BARO_SPEC_GRAV
        self.origin_amsl_m: float | None = None  # GPS_GLOBAL_ORIGIN.altitude
        self.has_origin: bool | None = None  # GLOBAL_POSITION_INT.alt != 0
        self.ekf: tuple[float, float] | None = None  # (t, depth) of the newest EKF depth
        self.vspeed_mps = math.nan  # GLOBAL_POSITION_INT.vz, positive down
        self.pressure: tuple[float, float] | None = None  # (t, depth) of the newest pressure depth
        # pressure depth − EKF depth at the newest cross-check
        self.disagreement_m: float | None = None
        self.disagreeing = False
        self.reboots = 0
        # ArduSub's depth sensor zero taken under water, not followed
        self.zero_not_followed_pa: float | None = None
        self.refusal: str | None = None
        self.notices: list[str] = []
        self._received: set[str] = set()  # parameters received since the autopilot's last (re)boot

    # -- what the autopilot is asked for ------------------------------------------------------------------
    def wanted_params(self) -> list[str]:
        """Parameters not received since the autopilot's (re)boot."""
        names = ["BARO_PRIMARY", "BARO_SPEC_GRAV"]
        if self.primary is not None:
            names.append(ground_pressure_param(self.primary))
        return [n for n in names if n not in self._received]

    @property
    def wants_origin(self) -> bool:
        """The EKF has an origin whose altitude is not known (ask for GPS_GLOBAL_ORIGIN)."""
        return bool(self.has_origin) and self.origin_amsl_m is None

    @property
    def pressure_message(self) -> str | None:
        """The message carrying the depth sensor's pressure, once BARO_PRIMARY is known."""
        return None if self.primary is None else PRESSURE_MESSAGES[self.primary]

    @property
    def calibrated(self) -> bool:
        """Whether the pressure can be turned into depth."""
        return self.primary in self.ground_pa and self.specific_gravity is not None

    # -- the messages ---------------------------------------------------------------------------------------
    def _station_t(self, time_boot_ms: float, receive_s: float) -> float | None:
        boot_s = time_boot_ms / 1000.0
        before = self.clock.last_source_s
        result = self.clock.add(boot_s, receive_s)
        if result == OUTLIER:
            self.refusal = (
                f"time_boot_ms {boot_s:.3f} s does not fit the autopilot's clock (latest {before:.3f} s); "
                f"a reboot is taken once samples agree for {self.clock.confirm_s} s"
            )
            return None
        if result == RESTART:
            self.reboots += 1
            was, now = self.clock.last_restart
            self.notices.append(
                f"the UUV's autopilot rebooted (time_boot_ms went back from {was:.1f} s to "
                f"{now:.1f} s): its depth parameters and EKF origin are read again"
            )
            self._received.clear()
            self.origin_amsl_m = self.has_origin = self.ekf = self.pressure = None
        return boot_s + self.clock.offset_s - self.latency_s

    def param(self, name: str, value: float) -> None:
        """A PARAM_VALUE of the autopilot (the others are ignored)."""
        if not math.isfinite(value):
            return
        if name == "BARO_PRIMARY" and value in range(len(PRESSURE_MESSAGES)):
            self._received.add(name)
            if self.primary is not None and round(value) != self.primary:
                self.notices.append(
                    f"ArduSub's BARO_PRIMARY changed {self.primary} → {round(value)}: the depth "
                    f"sensor is now {PRESSURE_MESSAGES[round(value)]}"
                )
            self.primary = round(value)
        elif name == "BARO_SPEC_GRAV" and value > 0:
            self._received.add(name)
            if self.specific_gravity is not None and value != self.specific_gravity:
                self.notices.append(
                    f"ArduSub's BARO_SPEC_GRAV changed {self.specific_gravity:g} → {value:g}"
                )
            self.specific_gravity = value
        elif name in (ground_pressure_param(i) for i in range(len(PRESSURE_MESSAGES))):
            self._received.add(name)
            self._ground(int(name[4]) - 1, name, value)

    def _ground(self, instance: int, name: str, pa: float) -> None:
        if pa <= 0:  # not set yet: AP_Baro takes its first reading
            self._received.discard(name)
            return
        old = self.ground_pa.get(instance)
        if (
            instance != self.primary or old is None or pa == old
        ):  # another barometer's, the first, the same
            self.ground_pa[instance] = pa
            if instance == self.primary:
                self.zero_not_followed_pa = None
            return
        moved_m = float(depth_from_pressure_m(pa, old, self.specific_gravity or 1.0))
        if moved_m > RECAL_MAX_DEPTH_M:
            if self.zero_not_followed_pa != pa:
                self.zero_not_followed_pa = pa
                self.notices.append(
                    f"ArduSub's {name} changed {old:.0f} → {pa:.0f} Pa: a depth zero {moved_m:.2f} m "
                    "below the old one (recalibrated under water): skyfix keeps the old zero; "
                    f"ArduSub's own depth and its EKF's now read {moved_m:.2f} m shallow (not compared "
                    "until the sensor is zeroed at the surface again)"
                )
            return
        self.notices.append(
            f"ArduSub's {name} changed {old:.0f} → {pa:.0f} Pa (recalibrated): the depth zero moved "
            f"{moved_m:+.2f} m"
        )
        self.ground_pa[instance] = pa
        self.zero_not_followed_pa = None

    def origin(self, alt_amsl_m: float) -> None:
        """GPS_GLOBAL_ORIGIN's altitude (m above mean sea level)."""
        if math.isfinite(alt_amsl_m):
            if self.origin_amsl_m is not None and alt_amsl_m != self.origin_amsl_m:
                self.notices.append(
                    f"ArduSub's EKF origin moved from {self.origin_amsl_m:.2f} m to {alt_amsl_m:.2f} m "
                    "above sea level"
                )
            self.origin_amsl_m = alt_amsl_m

    def position(
        self,
        time_boot_ms: float,
        relative_alt_m: float,
        alt_amsl_m: float,
        vz_mps: float,
        receive_s: float,
    ) -> DepthSample | None:
        """GLOBAL_POSITION_INT: the EKF's depth; a sample until the first pressure depth (since the last boot)."""
        t = self._station_t(time_boot_ms, receive_s)
        if t is None:
            return None
        self.has_origin = alt_amsl_m != 0.0
        self.vspeed_mps = vz_mps
        depth = ekf_depth_m(relative_alt_m, alt_amsl_m, self.origin_amsl_m)
        self.ekf = None if depth is None else (t, depth)
        if depth is None or self.pressure is not None:
            return None
        return DepthSample(t, depth, self.sigma_m, "ardusub_ekf", vz_mps)

    def scaled_pressure(
        self, instance: int, time_boot_ms: float, pressure_pa: float, receive_s: float
    ) -> DepthSample | None:
        """SCALED_PRESSURE{instance+1}: a sample when it is the depth sensor's and its parameters are known."""
        if instance != self.primary:
            return None
        t = self._station_t(time_boot_ms, receive_s)
        if t is None:
            return None
        if not self.calibrated:
            return None
        depth = float(
            depth_from_pressure_m(pressure_pa, self.ground_pa[instance], self.specific_gravity)
        )
        self.pressure = (t, depth)
        return DepthSample(
            t, depth, self._crosscheck(t, depth), "ardusub_pressure", self.vspeed_mps
        )

    def _crosscheck(self, t: float, depth: float) -> float:
        """The pressure depth's sigma: its own, and the disagreement with the EKF's depth when beyond DISAGREE_M."""
        if (
            self.ekf is None
            or abs(t - self.ekf[0]) > CROSSCHECK_S
            or self.zero_not_followed_pa is not None
        ):
            self.disagreement_m = None
            return self.sigma_m
        te, de = self.ekf
        ekf = de + (self.vspeed_mps if math.isfinite(self.vspeed_mps) else 0.0) * (t - te)
        diff = self.disagreement_m = depth - ekf
        agree = abs(diff) <= DISAGREE_M
        if agree and self.disagreeing:
            self.notices.append(
                f"ArduSub's pressure depth {depth:.2f} m and its EKF's {ekf:.2f} m agree again"
            )
        if not agree and not self.disagreeing:
            self.notices.append(
                f"ArduSub's pressure depth {depth:.2f} m and its EKF's {ekf:.2f} m disagree by "
                f"{diff:+.2f} m (more than {DISAGREE_M:g} m): the difference goes into the depth's sigma"
            )
        self.disagreeing = not agree
        return float(crosscheck_sigma_m(self.sigma_m, diff))

    def status(self) -> dict:
        def r(x, nd=3):
            return None if x is None or not math.isfinite(x) else round(x, nd)

        return {
            "params": {
                "BARO_PRIMARY": self.primary,
                "BARO_SPEC_GRAV": self.specific_gravity,
                "ground_pressure_pa": None
                if self.primary is None
                else self.ground_pa.get(self.primary),
                "pressure_message": self.pressure_message,
                "missing": self.wanted_params(),
            },
            "pressure_depth_m": r(self.pressure and self.pressure[1]),
            "ekf_depth_m": r(self.ekf and self.ekf[1]),
            "disagreement_m": r(self.disagreement_m),
            "vertical_speed_mps": r(self.vspeed_mps, 2),
            "ekf_origin_amsl_m": r(self.origin_amsl_m),
            "ekf_has_origin": self.has_origin,
            "zero_not_followed_pa": self.zero_not_followed_pa,
            "autopilot_reboots": self.reboots,
        }

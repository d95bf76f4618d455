"""Whether the UUV's horizontal thrusters push: a second source of its motion, read from its autopilot's outputs.

The fixes alone cannot tell a UUV starting to move from a tracker starting to drift
(:mod:`localizer.fix_gate`). The UUV's autopilot knows whether it pushes: ArduSub's
``SERVO_OUTPUT_RAW`` carries the pulse each output channel sends to an ESC. ArduSub
(``AP_Motors6DOF``) sends 1500 µs for no thrust — always while disarmed — and
``1500 + 400·thrust`` otherwise. Which motors push horizontally is the frame's
(``FRAME_CONFIG``; in ``AP_Motors6DOF::setup_motors`` the motors with a forward or
lateral factor): motors 1–4 on the vectored frames (1: BlueROV2, 2: BlueROV2 Heavy); the
other frames are not known here and give no evidence. Which output channel drives motor
``k`` is the channel whose ``SERVOn_FUNCTION`` is ``32 + k``.

The horizontal thrusters are *idle* when each of them is within :attr:`Thrusters.deadband_us`
of 1500 µs: an ESC does not turn its motor inside its deadband (Blue Robotics states ±25 µs
for its Basic ESC — not measured here; set your ESCs' own). ArduSub's heading hold moves them
by up to ±25 µs in ALT_HOLD on its simulator in still water (measured); a vehicle yawing
harder, or pushed by the pilot, is not idle. A vehicle whose horizontal thrusters are idle
moves only as the water moves it and as drag slows it: :func:`idle_accel_mps2`.

Times are the outputs' arrival on the station clock (UNIX s). The tether's delay is
milliseconds, the video's a hundred or more: an output arriving after a frame's exposure
was set before the frame was processed. An interval counts as idle only when the outputs
cover it from :data:`MARGIN_S` before its start, no two of them more than :data:`STALE_S`
apart and the newest no older than that; anything less is *unknown* and gives no
evidence. Pure computation.
"""

from __future__ import annotations

import math
from collections import deque

#: ArduSub's pulse for no thrust (µs).
NEUTRAL_US = 1500
#: FRAME_CONFIG → the motors (1-based) that push horizontally.
HORIZONTAL_MOTORS = {1: (1, 2, 3, 4), 2: (1, 2, 3, 4)}
#: SERVOn_FUNCTION of motor k is this plus k (ArduPilot's SRV_Channel: 33 is motor 1).
MOTOR_FUNCTION_BASE = 32
#: Output channels SERVO_OUTPUT_RAW carries (servo1_raw … servo16_raw).
CHANNELS = 16
#: The default deadband (µs) around :data:`NEUTRAL_US` in which an ESC does not turn its motor.
DEADBAND_US = 25.0
#: Outputs further apart than this (s), or a newest output older than this, leave the thrust unknown.
STALE_S = 0.5
#: An interval is idle only if the outputs were idle from this long (s) before it began.
MARGIN_S = 0.2
#: Outputs are kept this long (s).
KEEP_S = 30.0
#: A BlueROV2's surge drag (N) at speed v (m/s): 4.03·v + 18.18·v² (Wu 2018), on its mass with added mass (kg).
DRAG_LINEAR, DRAG_QUADRATIC, MASS_KG = 4.03, 18.18, 17.0


def idle_accel_mps2(speed_mps: float, water_accel_mps2: float) -> float:
    """The largest horizontal acceleration (m/s²) of a UUV at ``speed_mps`` whose horizontal thrusters are idle: its
    drag (a BlueROV2's) slowing it, plus what the water can do to it (``water_accel_mps2``: currents changing,
    waves, the tether)."""
    v = abs(speed_mps)
    return (DRAG_LINEAR * v + DRAG_QUADRATIC * v * v) / MASS_KG + water_accel_mps2


def servo_params() -> list[str]:
    """The parameters that say which channels drive which motors."""
    return ["FRAME_CONFIG", *(f"SERVO{n}_FUNCTION" for n in range(1, CHANNELS + 1))]


class Thrusters:
    """The horizontal thrusters' state from ``SERVO_OUTPUT_RAW`` (:meth:`outputs`), given the autopilot's parameters
    (:meth:`param`)."""

    def __init__(self, deadband_us: float = DEADBAND_US):
        self.deadband_us = deadband_us
        self.frame: int | None = None
        self.functions: dict[int, int] = {}  # channel (1-based) → SERVOn_FUNCTION
        self.received = self.unusable = 0
        self.last_pulses_us: tuple[int, ...] | None = None  # the horizontal motors', newest
        self._samples: deque[tuple[float, bool]] = deque()  # (arrival, idle)

    # -- what the autopilot says -------------------------------------------------------------------------
    def wanted_params(self) -> list[str]:
        """Parameters still missing while the horizontal motors' channels are not known."""
        if self.channels is not None:
            return []
        have = {"FRAME_CONFIG"} if self.frame is not None else set()
        have |= {f"SERVO{n}_FUNCTION" for n in self.functions}
        return [p for p in servo_params() if p not in have]

    def param(self, name: str, value: float) -> None:
        """A PARAM_VALUE of the autopilot (the others are ignored)."""
        if not math.isfinite(value):
            return
        if name == "FRAME_CONFIG":
            self.frame = round(value)
        elif name.startswith("SERVO") and name.endswith("_FUNCTION"):
            n = name[len("SERVO") : -len("_FUNCTION")]
            if n.isdigit() and 1 <= int(n) <= CHANNELS:
                self.functions[int(n)] = round(value)

    def restarted(self) -> None:
        """The autopilot rebooted: its parameters are read again; what came before says nothing of now."""
        self.frame = None
        self.functions.clear()
        self._samples.clear()

    @property
    def channels(self) -> tuple[int, ...] | None:
        """The output channels of the horizontal motors; None while not known (or the frame is not one known here)."""
        motors = HORIZONTAL_MOTORS.get(self.frame)
        if motors is None:
            return None
        by_function = {f: ch for ch, f in self.functions.items()}
        found = tuple(by_function.get(MOTOR_FUNCTION_BASE + k) for k in motors)
        return None if None in found else found

    @property
    def why_unknown(self) -> str | None:
        """Why :attr:`channels` is None (None when it is known)."""
        if self.frame is None:
            return "waiting for FRAME_CONFIG"
        if self.frame not in HORIZONTAL_MOTORS:
            return f"FRAME_CONFIG {self.frame}: a frame whose horizontal motors are not known here"
        if self.channels is None:
            return (
                "waiting for SERVOn_FUNCTION"
                if len(self.functions) < CHANNELS
                else "no output channel drives one of the horizontal motors (SERVOn_FUNCTION)"
            )
        return None

    def outputs(self, t: float, pulses_us: dict[int, int]) -> bool | None:
        """One ``SERVO_OUTPUT_RAW`` (channel → pulse, µs) arriving at ``t``: whether the horizontal thrusters are
        idle (None: not known)."""
        self.received += 1
        channels = self.channels
        if channels is None:
            return None
        pulses = tuple(pulses_us.get(ch, 0) for ch in channels)
        if any(
            p <= 0 for p in pulses
        ):  # 0: the channel is not output (SERVO_OUTPUT_RAW's "unused")
            self.unusable += 1
            return None
        idle = all(abs(p - NEUTRAL_US) <= self.deadband_us for p in pulses)
        self.last_pulses_us = pulses
        if self._samples and t < self._samples[-1][0]:
            return idle
        self._samples.append((t, idle))
        while self._samples[0][0] < t - KEEP_S:
            self._samples.popleft()
        return idle

    # -- what the gate asks ----------------------------------------------------------------------------
    def idle_since(self, t0: float, now: float) -> bool:
        """Whether the horizontal thrusters were idle from ``t0`` until ``now`` (a fix's exposure lies between; see
        the module doc: covered from :data:`MARGIN_S` before ``t0``, gaps at most :data:`STALE_S`, the newest that
        fresh)."""
        s = self._samples
        if not s or now - s[-1][0] > STALE_S or s[0][0] > t0 - MARGIN_S:
            return False
        start = t0 - MARGIN_S
        previous = None
        for t, idle in reversed(s):
            if previous is not None and previous - t > STALE_S:
                return False
            if not idle:
                return False
            if t <= start:
                return True
            previous = t
        return False

    def state(self, now: float) -> str:
        """``idle``, ``pushing`` or ``unknown`` now."""
        s = self._samples
        if self.channels is None or not s or now - s[-1][0] > STALE_S:
            return "unknown"
        return "idle" if s[-1][1] else "pushing"

    def status(self, now: float) -> dict:
        return {
            "state": self.state(now),
            "why_unknown": self.why_unknown,
            "frame": self.frame,
            "channels": list(self.channels) if self.channels else None,
            "deadband_us": self.deadband_us,
            "pulses_us": list(self.last_pulses_us) if self.last_pulses_us else None,
            "received": self.received,
            "unusable": self.unusable,
        }

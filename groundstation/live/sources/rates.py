"""The telemetry rates skyfix needs from an autopilot, what arrives, and what to ask it for.

Needed from the UAV (per second): ATTITUDE 25 (the camera's attitude between frames; slower is
interpolated with its body rates, at a cost), GLOBAL_POSITION_INT 10, the gimbal
message 20, SYSTEM_TIME 1, GPS_RAW_INT 2 (the UAV's own accuracy and its GNSS
altitude), and DISTANCE_SENSOR 10 (a downward rangefinder's height) once the
autopilot has sent one (a UAV without a rangefinder sends none); from the UUV's
autopilot (ArduSub) its depth sensor's SCALED_PRESSURE message and GLOBAL_POSITION_INT
at :data:`DEPTH_HZ`, its thrusters' SERVO_OUTPUT_RAW at :data:`THRUSTERS_HZ`. As a
ground station skyfix asks for the ones that arrive slower with
``MAV_CMD_SET_MESSAGE_INTERVAL``; a refusal or no answer falls back to the older
``REQUEST_DATA_STREAM`` for the stream that carries the message (ArduPilot's
stream tables). A message already faster than needed is left alone. Every
request and answer is kept for the status.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

NEEDED_HZ = {"ATTITUDE": 25.0, "GLOBAL_POSITION_INT": 10.0, "SYSTEM_TIME": 1.0, "GPS_RAW_INT": 2.0}
GIMBAL_HZ = 20.0
RANGEFINDER_HZ = 10.0  # DISTANCE_SENSOR, asked for once one has come
GIMBAL_MESSAGE = {
    "gimbal_device": "GIMBAL_DEVICE_ATTITUDE_STATUS",
    "mount_orientation": "MOUNT_ORIENTATION",
}
DEPTH_HZ = 5.0
THRUSTERS_HZ = 10.0  # the UUV's SERVO_OUTPUT_RAW (localizer.thrusters)
MESSAGE_ID = {
    "ATTITUDE": 30,
    "GLOBAL_POSITION_INT": 33,
    "SYSTEM_TIME": 2,
    "GPS_RAW_INT": 24,
    "GIMBAL_DEVICE_ATTITUDE_STATUS": 285,
    "MOUNT_ORIENTATION": 265,
    "DISTANCE_SENSOR": 132,
    "SCALED_PRESSURE": 29,
    "SCALED_PRESSURE2": 137,
    "SCALED_PRESSURE3": 143,
    "SERVO_OUTPUT_RAW": 36,
}
# MAV_DATA_STREAM carrying each message on ArduPilot: EXTRA1, POSITION, EXTRA3, EXTENDED_STATUS, RAW_SENSORS,
# RC_CHANNELS
STREAM = {
    "ATTITUDE": 10,
    "GLOBAL_POSITION_INT": 6,
    "SYSTEM_TIME": 12,
    "GPS_RAW_INT": 2,
    "GIMBAL_DEVICE_ATTITUDE_STATUS": 12,
    "MOUNT_ORIENTATION": 12,
    "DISTANCE_SENSOR": 12,
    "SCALED_PRESSURE": 1,
    "SCALED_PRESSURE2": 1,
    "SCALED_PRESSURE3": 1,
    "SERVO_OUTPUT_RAW": 3,
}
MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_RESULT_ACCEPTED = 0
SETTLE_S = 3.0  # measure this long after the autopilot appears before asking
RETRY_S = 10.0  # ask again this often while a message stays slow
ACK_TIMEOUT_S = 2.0
WINDOW_S = 5.0  # rates are measured over this window
SLOW = 0.8  # a message below this share of its needed rate counts as slow (scheduling jitter stays above)


def needed_rates(attitude_source: str) -> dict[str, float]:
    """The rates (Hz) needed for a calibration's camera attitude source."""
    out = dict(NEEDED_HZ)
    if attitude_source in GIMBAL_MESSAGE:
        out[GIMBAL_MESSAGE[attitude_source]] = GIMBAL_HZ
    return out


class RateMeter:
    """Receive rate of each message type over the last :data:`WINDOW_S` seconds."""

    def __init__(self):
        self._times: dict[str, deque[float]] = {}

    def add(self, kind: str, t: float) -> None:
        q = self._times.setdefault(kind, deque())
        q.append(t)
        while q[0] < t - WINDOW_S:
            q.popleft()

    def rate_hz(self, kind: str, now: float) -> float:
        """Messages per second over the window: intervals between the first and the newest received,
        or one interval's worth when the newest is older than the typical interval (a stream that stopped)."""
        q = self._times.get(kind)
        if not q or len(q) < 2 or now - q[-1] > WINDOW_S:
            return 0.0
        span = q[-1] - q[0]
        interval = span / (len(q) - 1)
        return (len(q) - 1) / max(span + max(0.0, now - q[-1] - interval), 1e-9)

    def rates(self, now: float) -> dict[str, float]:
        return {k: round(self.rate_hz(k, now), 1) for k in sorted(self._times)}


@dataclass
class RateRequests:
    """Which rate requests to send now, and the autopilot's answers (``state`` per message)."""

    needed: dict[str, float]
    enabled: bool = True
    state: dict[str, str] = field(default_factory=dict)
    _since: float | None = None
    _asked: dict[str, float] = field(default_factory=dict)
    _pending: deque = field(default_factory=deque)  # (kind, sent at) awaiting COMMAND_ACK, in order
    _denied: list = field(default_factory=list)  # refused requests, to ask again the older way

    def start(self, now: float) -> None:
        """The autopilot has appeared: requests may follow after :data:`SETTLE_S`."""
        if self._since is None:
            self._since = now

    def due(self, meter: RateMeter, now: float) -> list[tuple[str, int, float]]:
        """Requests to send now: ``(kind, message id, Hz)`` for SET_MESSAGE_INTERVAL."""
        if not self.enabled or self._since is None or now - self._since < SETTLE_S:
            return []
        out = []
        for kind, hz in self.needed.items():
            measured = meter.rate_hz(kind, now)
            if measured >= SLOW * hz:
                if kind in self._asked:
                    self.state[kind] = f"{self.state.get(kind, 'requested')}, now {measured:.1f} Hz"
                    del self._asked[kind]
                continue
            if now - self._asked.get(kind, -1e9) >= RETRY_S:
                self._asked[kind] = now
                self._pending.append((kind, now))
                self.state[kind] = f"requested {hz:g} Hz (was {measured:.1f} Hz)"
                out.append((kind, MESSAGE_ID[kind], hz))
        return out

    def on_ack(self, command: int, result: int) -> None:
        """A COMMAND_ACK (a refused rate request is asked for again the older way by :meth:`messages`)."""
        if command != MAV_CMD_SET_MESSAGE_INTERVAL or not self._pending:
            return
        kind, _ = self._pending.popleft()
        self.state[kind] = (
            "accepted" if result == MAV_RESULT_ACCEPTED else f"denied (MAV_RESULT {result})"
        )
        if result != MAV_RESULT_ACCEPTED:
            self._denied.append(kind)

    def unanswered(self, now: float) -> list[str]:
        """Requests with no COMMAND_ACK within :data:`ACK_TIMEOUT_S` (dropped from the pending list)."""
        out = []
        while self._pending and now - self._pending[0][1] > ACK_TIMEOUT_S:
            kind, _ = self._pending.popleft()
            self.state[kind] = "no answer"
            out.append(kind)
        return out

    def messages(
        self, meter: RateMeter, now: float, target: tuple[int, int]
    ) -> list[tuple[str, str, dict]]:
        """The requests to send now, as ``(a line for the log, message type, fields)``: SET_MESSAGE_INTERVAL for
        the slow messages, REQUEST_DATA_STREAM for those whose request was refused or not answered."""
        out = [
            (
                f"{kind} at {meter.rate_hz(kind, now):.1f} Hz; asking for {hz:g} Hz (SET_MESSAGE_INTERVAL)",
                *interval_request(target, msg_id, hz),
            )
            for kind, msg_id, hz in self.due(meter, now)
        ]
        fall_back = [(kind, "no answer") for kind in self.unanswered(now)] + [
            (kind, "denied") for kind in self._denied
        ]
        self._denied.clear()
        for kind, why in fall_back:
            hz = self.needed[kind]
            self.state[kind] = f"{self.state[kind]}; stream requested at {hz:g} Hz"
            out.append(
                (
                    f"SET_MESSAGE_INTERVAL for {kind}: {why}; asking with REQUEST_DATA_STREAM",
                    *stream_request(target, kind, hz),
                )
            )
        return out


def interval_request(target: tuple[int, int], msg_id: int, hz: float) -> tuple[str, dict]:
    """``MAV_CMD_SET_MESSAGE_INTERVAL`` for one message: ``(message type, fields)``."""
    return "COMMAND_LONG", {
        "target_system": target[0],
        "target_component": target[1],
        "command": MAV_CMD_SET_MESSAGE_INTERVAL,
        "confirmation": 0,
        "param1": float(msg_id),
        "param2": 1e6 / hz,
        "param3": 0.0,
        "param4": 0.0,
        "param5": 0.0,
        "param6": 0.0,
        "param7": 0.0,
    }


def stream_request(target: tuple[int, int], kind: str, hz: float) -> tuple[str, dict]:
    """The older ``REQUEST_DATA_STREAM`` for the stream that carries ``kind``: ``(message type, fields)``."""
    return "REQUEST_DATA_STREAM", {
        "target_system": target[0],
        "target_component": target[1],
        "req_stream_id": STREAM[kind],
        "req_message_rate": max(1, round(hz)),
        "start_stop": 1,
    }

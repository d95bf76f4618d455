"""The UUV's own position estimate over Zenoh: a prior to find it in the video without a selection.

BlueOS's mavlink-server publishes the UUV autopilot's ``GLOBAL_POSITION_INT`` on
``mavlink/{sys}/{comp}/GLOBAL_POSITION_INT`` as JSON
(``{"header": {...}, "message": {"type": "GLOBAL_POSITION_INT", "lat": <degE7>, "lon": <degE7>, ...}}``).
Its estimate may be metres off (dead reckoning, or skyfix's own earlier fixes), so
it only says where to look: :meth:`UuvPosition.prior` gives it with a 1-sigma of
``sigma_m`` growing at :data:`~localizer.tracking.predict.UUV_SPEED_MPS` with its age,
and nothing once it is older than :data:`MAX_AGE_S`. A fixed ``hint`` (``--uuv-hint
LAT,LON``, e.g. where the UUV was launched) stands in while no estimate has arrived.

ArduPilot sends lat = lon = 0 before it has a position: such samples are counted
as ``unknown`` and ignored. A payload that does not parse is logged in one line with
the offending value and counted; the service keeps running.
"""

from __future__ import annotations

import asyncio
import json
import logging

import zenoh

from groundstation.runtime.logs import Throttle, kind_of
from groundstation.runtime.threads import Handoff
from groundstation.runtime.zenoh_session import subscribe
from localizer.tracking.predict import UUV_SPEED_MPS
from localizer.tracking.session import Prior

log = logging.getLogger("skyfix.uuv_position")

#: An estimate older than this (s) is no longer a prior.
MAX_AGE_S = 30.0
# samples received but not yet taken by the event loop (beyond: oldest dropped, counted)
HANDOFF_SAMPLES = 256


class BadPosition(ValueError):
    """A GLOBAL_POSITION_INT payload that cannot be used."""


def parse_global_position(payload: bytes) -> tuple[float, float] | None:
    """``(lat_deg, lon_deg)`` of BlueOS's GLOBAL_POSITION_INT JSON; None for ArduPilot's "no position" (0, 0).

    Raises :class:`BadPosition` naming what is wrong.
    """
    try:
        obj = json.loads(payload)
    except (ValueError, UnicodeDecodeError):
        raise BadPosition("not JSON") from None
    except RecursionError:
        raise BadPosition("JSON nested too deeply") from None
    msg = obj.get("message") if isinstance(obj, dict) else None
    if not isinstance(msg, dict):
        raise BadPosition("no 'message' object")
    if msg.get("type", "GLOBAL_POSITION_INT") != "GLOBAL_POSITION_INT":
        raise BadPosition(f"message type {msg.get('type')!r} is not GLOBAL_POSITION_INT")
    out = []
    for key, limit in (("lat", 90.0), ("lon", 180.0)):
        value = msg.get(key)
        if isinstance(value, bool) or not isinstance(value, int):
            raise BadPosition(f"{key} = {value!r}: expected an integer (degE7)")
        if not abs(value) <= limit * 1e7:
            raise BadPosition(f"{key} = {value!r}: beyond ±{limit:g}°")
        out.append(value / 1e7)
    return None if out == [0.0, 0.0] else (out[0], out[1])


def parse_hint(text: str) -> tuple[float, float]:
    """``"LAT,LON"`` (degrees) → (lat, lon); ValueError naming the text."""
    parts = text.split(",")
    try:
        lat, lon = (float(x) for x in parts)
    except ValueError:
        raise ValueError(f"{text!r}: expected LAT,LON in degrees") from None
    if not (abs(lat) <= 90.0 and abs(lon) <= 180.0):
        raise ValueError(f"{text!r}: expected LAT within ±90 and LON within ±180")
    return lat, lon


class UuvPosition:
    """Worker subscribing to the UUV's GLOBAL_POSITION_INT (when ``key`` is given); :meth:`prior` for the tracker."""

    def __init__(
        self,
        session: zenoh.Session,
        key: str | None,
        sigma_m: float,
        hint: tuple[float, float] | None = None,
    ):
        self.session = session
        self.key = key
        self.sigma_m = sigma_m
        self.hint = hint
        self.received = 0
        self.bad = 0
        self.unknown = 0
        self.last: tuple[float, float, float] | None = None  # lat, lon, t_recv
        self._throttle = Throttle()
        self.handoff: Handoff | None = None

    def prior(self, t_unix: float) -> Prior | None:
        """The UUV's estimate at a frame's time: the latest received (if fresh), else the hint, else None."""
        if self.last is not None:
            lat, lon, t_recv = self.last
            age = max(0.0, t_unix - t_recv)
            if age <= MAX_AGE_S:
                return Prior(lat, lon, self.sigma_m + UUV_SPEED_MPS * age)
        if self.hint is not None:
            return Prior(*self.hint, self.sigma_m)
        return None

    async def run(self) -> None:
        if self.key is None:
            await asyncio.Event().wait()
        self.handoff = Handoff(
            asyncio.get_running_loop(), lambda item: self._on_payload(*item), HANDOFF_SAMPLES
        )
        await subscribe(self.session, self.key, self.handoff)

    def _on_payload(self, key: str, data: bytes, t_recv: float) -> None:
        self.received += 1
        try:
            position = parse_global_position(data)
        except BadPosition as e:
            self.bad += 1
            if self._throttle(kind_of(str(e))):
                log.warning("UUV position on %s: %s: %r", key, e, data[:120])
            return
        if position is None:
            self.unknown += 1
            return
        if self.last is None:
            log.info("UUV position estimate on %s: %.7f, %.7f", key, *position)
        self.last = (*position, t_recv)

    def status(self, now: float) -> dict:
        age = None if self.last is None else round(max(0.0, now - self.last[2]), 3)
        lat, lon = (self.last[0], self.last[1]) if self.last else (self.hint or (None, None))
        return {
            "key": self.key,
            "received": self.received,
            "bad": self.bad,
            "unknown": self.unknown,
            "age_s": age,
            "lat": lat,
            "lon": lon,
            "hint": self.hint is not None,
            "sigma_m": self.sigma_m,
        }

"""The UUV's depth over Zenoh, in one of two payload shapes.

``skyfix``: JSON ``{"t": <UNIX s>, "depth_m": <m, positive down>}`` on the depth
key (extra keys ignored), the same shape as a session's ``depth.jsonl``. ``t`` is
the UUV's own clock (a vehicle computer without network may be minutes off): the
telemetry aligns it by the arrival times (:meth:`localizer.telemetry.Telemetry.add_depth`).

``blueos``: BlueOS mavlink-server's JSON on ``mavlink/{sys}/{comp}/VFR_HUD``
(``{"header": {...}, "message": {"type": "VFR_HUD", "alt": -1.23, ...}}``);
ArduSub's depth is ``-alt``. VFR_HUD carries no time, so the sample's time is
its arrival minus ``[timing] depth_latency_s``.

Zenoh's callback thread only copies the payload and hands it to the event loop
(:func:`~groundstation.zenoh_session.subscribe`, a bounded hand-off).
A payload that does not parse is logged in one line with the offending value
and counted; the service keeps running.
"""

from __future__ import annotations

import asyncio
import json
import logging
import math
from collections.abc import Callable

import zenoh

from localizer.telemetry import Telemetry

from ..logs import Throttle, kind_of
from ..threads import Handoff
from ..zenoh_session import subscribe

log = logging.getLogger("skyfix.depth")

BLUEOS_KEY = "mavlink/*/*/VFR_HUD"
HANDOFF_SAMPLES = 256  # samples received but not yet taken by the event loop (beyond: oldest dropped, counted)


class BadDepth(ValueError):
    """A depth payload that cannot be used."""


def _number(obj: dict, key: str):
    value = obj.get(key) if isinstance(obj, dict) else None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise BadDepth(f"{key} missing or not a finite number")
    return float(value)


def parse_depth(payload: bytes, shape: str) -> tuple[float | None, float]:
    """``(t_unix of the UUV's clock or None, depth_m)`` of one payload; raises :class:`BadDepth`."""
    try:
        obj = json.loads(payload)
    except (ValueError, UnicodeDecodeError):
        raise BadDepth("not JSON") from None
    except RecursionError:  # e.g. b"[[[[..." deeper than the interpreter's recursion limit
        raise BadDepth("JSON nested too deeply") from None
    if shape == "blueos":
        msg = obj.get("message") if isinstance(obj, dict) else None
        if isinstance(msg, dict) and msg.get("type", "VFR_HUD") != "VFR_HUD":
            raise BadDepth(f"message type {msg.get('type')!r} is not VFR_HUD")
        return None, -_number(msg, "alt")
    return _number(obj, "t"), _number(obj, "depth_m")


class DepthZenoh:
    """Worker subscribing to the UUV's depth; ``listeners`` get ``(t_unix, depth_m)`` of accepted samples."""

    def __init__(self, session: zenoh.Session, key: str, tel: Telemetry, shape: str = "skyfix",
                 listeners: list[Callable] | None = None):
        self.session = session
        self.key = key
        self.tel = tel
        self.shape = shape
        self.listeners = listeners or []
        self.received = 0
        self.bad = 0
        self.refused = 0
        self._throttle = Throttle()
        self.handoff: Handoff | None = None
        self.last_recv: float | None = None
        self.last_depth_m: float | None = None

    async def run(self) -> None:
        self.handoff = Handoff(asyncio.get_running_loop(), lambda item: self._on_payload(*item), HANDOFF_SAMPLES)
        await subscribe(self.session, self.key, self.handoff)

    def _on_payload(self, key: str, data: bytes, t_recv: float) -> None:
        self.received += 1
        try:
            t, depth = parse_depth(data, self.shape)
        except BadDepth as e:
            self.bad += 1
            if self._throttle(kind_of(str(e))):
                log.warning("depth on %s: %s: %r", key, e, data[:120])
            return
        if not self.tel.add_depth(t, depth, t_recv):
            self.refused += 1
            if self._throttle(kind_of(f"refused: {self.tel.refusal}")):
                log.warning("depth on %s refused (%s): t=%r depth_m=%r", key, self.tel.refusal, t, depth)
            return
        while self.tel.notices:
            log.warning("depth: %s", self.tel.notices.pop(0))
        self.last_recv, self.last_depth_m = t_recv, depth
        for listener in self.listeners:
            listener(t, depth, t_recv)

    def status(self, now: float) -> dict:
        age = None if self.last_recv is None else round(max(0.0, now - self.last_recv), 3)
        return {"key": self.key, "shape": self.shape, "received": self.received, "bad": self.bad,
                "refused": self.refused, "age_s": age, "depth_m": self.last_depth_m,
                "handoff": self.handoff.status() if self.handoff else None}

"""The UUV's depth over Zenoh as skyfix's own JSON (``--depth-source skyfix``).

``{"t": <UNIX s>, "depth_m": <m, positive down>}`` on the depth key (extra keys ignored), the same
shape as a session's ``depth.jsonl`` and what ``skyfix replay`` publishes. ``t`` is the UUV's own
clock (a vehicle computer without network may be minutes off): the telemetry aligns it by the
arrival times (:meth:`localizer.telemetry.Telemetry.add_depth`). ArduSub's own depth, over BlueOS's
Zenoh or a MAVLink link, is :mod:`.depth_ardusub`.

Zenoh's callback thread only copies the payload and hands it to the event loop
(:func:`~groundstation.runtime.zenoh_session.subscribe`, a bounded hand-off). A sample that moved faster than
the vehicle can dive is refused (:class:`localizer.depth.DepthGate`). A payload that does not parse
is logged in one line with the offending value and counted; the service keeps running.
"""

from __future__ import annotations

import asyncio
import json
import logging
import math
from collections.abc import Callable

import zenoh

from groundstation.live.registry import DepthInput, register
from groundstation.runtime.logs import Throttle, kind_of
from groundstation.runtime.threads import Handoff
from groundstation.runtime.zenoh_session import subscribe
from localizer.depth import DepthGate, DepthSample
from localizer.telemetry import Telemetry

log = logging.getLogger("skyfix.depth")

# samples received but not yet taken by the event loop (beyond: oldest dropped, counted)
HANDOFF_SAMPLES = 256


class BadDepth(ValueError):
    """A depth payload that cannot be used."""


def _number(obj: dict, key: str):
    value = obj.get(key) if isinstance(obj, dict) else None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise BadDepth(f"{key} missing or not a finite number")
    return float(value)


def parse_depth(payload: bytes) -> tuple[float, float]:
    """``(t_unix of the UUV's clock, depth_m)`` of one payload; raises :class:`BadDepth`."""
    try:
        obj = json.loads(payload)
    except (ValueError, UnicodeDecodeError):
        raise BadDepth("not JSON") from None
    except RecursionError:  # e.g. b"[[[[..." deeper than the interpreter's recursion limit
        raise BadDepth("JSON nested too deeply") from None
    return _number(obj, "t"), _number(obj, "depth_m")


class DepthZenoh:
    """Worker subscribing to the UUV's depth; ``listeners`` get ``(sample, t_recv)`` of accepted samples."""

    shape = "skyfix"

    def __init__(
        self,
        session: zenoh.Session,
        key: str,
        tel: Telemetry,
        gate: DepthGate | None = None,
        listeners: list[Callable] | None = None,
    ):
        self.session = session
        self.key = key
        self.tel = tel
        self.gate = gate or DepthGate()
        self.listeners = listeners or []
        self.received = 0
        self.bad = 0
        self.refused = 0
        self._throttle = Throttle()
        self.handoff: Handoff | None = None
        self.last_recv: float | None = None
        self.last_depth_m: float | None = None

    async def run(self) -> None:
        self.handoff = Handoff(
            asyncio.get_running_loop(), lambda item: self._on_payload(*item), HANDOFF_SAMPLES
        )
        await subscribe(self.session, self.key, self.handoff)

    def _refuse(self, key: str, why: str, t: float, depth: float) -> None:
        self.refused += 1
        if self._throttle(kind_of(f"refused: {why}")):
            log.warning("depth on %s refused (%s): t=%r depth_m=%r", key, why, t, depth)

    def _on_payload(self, key: str, data: bytes, t_recv: float) -> None:
        self.received += 1
        try:
            t, depth = parse_depth(data)
        except BadDepth as e:
            self.bad += 1
            if self._throttle(kind_of(str(e))):
                log.warning("depth on %s: %s: %r", key, e, data[:120])
            return
        sample = DepthSample(t, depth, math.nan, "skyfix", math.nan)
        why = self.gate.check(t, depth)
        while self.gate.notices:
            log.warning("depth: %s", self.gate.notices.pop(0))
        if why is not None:
            self._refuse(key, why, t, depth)
            return
        if not self.tel.add_depth(t, depth, t_recv):
            self._refuse(key, self.tel.refusal, t, depth)
            return
        while self.tel.notices:
            log.warning("depth: %s", self.tel.notices.pop(0))
        self.last_recv, self.last_depth_m = t_recv, depth
        for listener in self.listeners:
            listener(sample, t_recv)

    def status(self, now: float) -> dict:
        age = None if self.last_recv is None else round(max(0.0, now - self.last_recv), 3)
        t = self.tel.depth.last_t if self.last_recv is not None else None
        return {
            "key": self.key,
            "url": None,
            "shape": self.shape,
            "received": self.received,
            "bad": self.bad,
            "refused": self.refused,
            "jumps": self.gate.refused,
            "other": 0,
            "age_s": age,
            "t": None if t is None else round(t, 3),
            "depth_m": self.last_depth_m,
            "sigma_m": None,
            "source": None if self.last_recv is None else "skyfix",
            "vertical_speed_mps": None,
            "rates_hz": None,
            "rate_requests": None,
            "ardusub": None,
            "link": None,
            "handoff": self.handoff.status() if self.handoff else None,
        }


@register("depth", "skyfix", "skyfix JSON {t, depth_m} on --depth-key")
def build(depth: DepthInput) -> DepthZenoh:
    return DepthZenoh(depth.session, depth.options.depth_input_key, depth.tel, depth.gate)

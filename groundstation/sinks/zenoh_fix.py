"""Zenoh outputs: each fix as JSON, a 1 Hz health/status JSON, and a liveliness token.

Fix schema (``skyfix.fix/1``), one JSON object per processed frame on ``--fix-key``
(encoding ``application/json``, Zenoh timestamp set by the publisher)::

    {"schema": "skyfix.fix/1",
     "t": 1763800000.033,      # the frame's exposure time, UNIX seconds
     "frame": 1,               # running frame number of this run
     "status": "ok",           # or why there is no fix: lost, stale_attitude, no_depth, ...
     "lat": 59.9, "lon": 10.7, # WGS84 degrees of the UUV (null unless status is ok)
     "alt_amsl_m": -1.6,       # the UUV's altitude above mean sea level, metres
     "depth_m": 1.2,           # depth used, metres below the surface (positive down)
     "h_acc_m": 0.21,          # horizontal 1-sigma accuracy (DRMS), metres
     "v_acc_m": 0.5,           # vertical 1-sigma accuracy, metres
     "u": 960.2, "v": 540.8,   # the UUV's pixel in the frame (distorted, OpenCV convention)
     "north_m": 1.3, "east_m": -0.4,  # the UUV relative to the UAV's reported position, metres
     "confidence": null}       # the tracker's, 0..1, when it has one

Every number that is not available is ``null`` (JSON has no NaN).
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Callable

import zenoh

from localizer.fix import Fix

from ..zenoh_session import put_json

SCHEMA = "skyfix.fix/1"
_NUMBERS = ("lat", "lon", "alt_amsl_m", "depth_m", "h_acc_m", "v_acc_m", "u", "v", "north_m", "east_m", "confidence")


def _num(x: float):
    return float(x) if math.isfinite(x) else None


def fix_to_json(fix: Fix) -> dict:
    """The fix as a JSON-ready dict (schema above)."""
    out = {"schema": SCHEMA, "t": fix.t_unix, "frame": fix.frame, "status": fix.status}
    for name in _NUMBERS:
        out[name] = _num(getattr(fix, name))
    if not fix.ok:
        out["lat"] = out["lon"] = None
    return out


class ZenohFixSink:
    """Publishes every fix on ``key``; ``latest`` is the last one published (JSON-ready)."""

    def __init__(self, session: zenoh.Session, key: str):
        self.session = session
        self.key = key
        self.published = 0
        self.latest: dict | None = None
        self._pub = session.declare_publisher(key, encoding=zenoh.Encoding.APPLICATION_JSON)

    def on_fix(self, fix: Fix, info) -> None:
        self.latest = fix_to_json(fix)
        put_json(self._pub, self.latest, self.session)
        self.published += 1

    def close(self) -> None:
        self._pub.undeclare()


class ZenohStatus:
    """Worker publishing ``status()`` (a JSON-ready dict) on ``key`` every ``period_s``, with a liveliness token;
    ``latest`` is the last one published."""

    def __init__(self, session: zenoh.Session, key: str, alive_key: str, status: Callable[[float], dict],
                 period_s: float = 1.0):
        self.session = session
        self.key = key
        self.alive_key = alive_key
        self.status = status
        self.period_s = period_s
        self.latest: dict | None = None

    async def run(self) -> None:
        token = self.session.liveliness().declare_token(self.alive_key)
        pub = self.session.declare_publisher(self.key, encoding=zenoh.Encoding.APPLICATION_JSON)
        try:
            while True:
                now = time.time()
                self.latest = {"t": now, **self.status(now)}
                put_json(pub, self.latest, self.session)
                await asyncio.sleep(self.period_s)
        finally:
            pub.undeclare()
            token.undeclare()

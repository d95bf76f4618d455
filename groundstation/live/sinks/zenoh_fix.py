"""Zenoh outputs: each fix as JSON, a 1 Hz health/status JSON, and a liveliness token.

The messages are contracts (:mod:`groundstation.messages`, JSON Schema in
``groundstation/schemas/``): the fix message (``skyfix.fix/1``) on ``--fix-key``, one
per processed frame, and the status (``skyfix.status/1``) on ``--status-key``; both
with encoding ``application/json`` and a Zenoh timestamp set by the publisher.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable

import zenoh

from groundstation.messages import STATUS_SCHEMA, FixMessage
from groundstation.zenoh_session import put_json
from localizer.fix import Fix


def fix_to_json(fix: Fix) -> dict:
    """The fix message of a fix (see :class:`~groundstation.messages.FixMessage`)."""
    return FixMessage.of(fix).to_json()


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
                self.latest = {"schema": STATUS_SCHEMA, "t": now, **self.status(now)}
                put_json(pub, self.latest, self.session)
                await asyncio.sleep(self.period_s)
        finally:
            pub.undeclare()
            token.undeclare()

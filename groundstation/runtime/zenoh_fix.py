"""Zenoh outputs: each fix as JSON, a 1 Hz health/status JSON, and a liveliness token.

The messages are contracts (:mod:`groundstation.messages`, JSON Schema in
``groundstation/schemas/``): the fix message (``skyfix.fix/1``) on ``--fix-key``, one
per processed frame, and the status (``skyfix.status/1``) on ``--status-key``; both
with encoding ``application/json`` and a Zenoh timestamp set by the publisher.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable

import zenoh
from pydantic import BaseModel, ValidationError

from groundstation.messages import STATUS_SCHEMA, FixMessage, StatusMessage
from groundstation.runtime.zenoh_session import put_json
from localizer.fix import Fix

log = logging.getLogger("skyfix.status")


def fix_to_json(fix: Fix) -> dict:
    """The fix message of a fix (see :class:`~groundstation.messages.FixMessage`)."""
    return FixMessage.of(fix).to_json()


class ZenohFixSink:
    """Publishes every fix on ``key``; ``latest`` is the last one published (JSON-ready).

    Its publisher is declared at once (no fix waits for :meth:`run`) and undeclared by :meth:`close`, which
    :meth:`run` calls when it is cancelled (the service's output ``zenoh``)."""

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

    async def run(self) -> None:
        """Until cancelled; then the publisher is undeclared."""
        try:
            await asyncio.get_running_loop().create_future()
        finally:
            self.close()

    def status(self, now: float) -> dict:
        """The key and the fixes published on it."""
        return {"key": self.key, "published": self.published}

    def close(self) -> None:
        """Undeclare the publisher (once)."""
        if self._pub is not None:
            self._pub.undeclare()
            self._pub = None


class ZenohStatus:
    """Worker publishing ``status()`` (a JSON-ready dict) on ``key`` every ``period_s``, with a liveliness token;
    ``latest`` is the last one published.

    Each status is validated against its model (``model``: by default :class:`~groundstation.messages.StatusMessage`,
    the schema its readers rely on; ``schema``: its name and version) where it is assembled: one that does not fit is still published — the operator's view
    matters more than its shape — and the misfit is logged once per field and counted (:attr:`invalid`).
    """

    def __init__(
        self,
        session: zenoh.Session,
        key: str,
        alive_key: str,
        status: Callable[[float], dict],
        period_s: float = 1.0,
        model: type[BaseModel] = StatusMessage,
        schema: str = STATUS_SCHEMA,
    ):
        self.model = model
        self.schema = schema
        self.session = session
        self.key = key
        self.alive_key = alive_key
        self.status = status
        self.period_s = period_s
        self.latest: dict | None = None
        self.invalid = 0
        self._told: set[str] = set()

    def _check(self, status: dict) -> None:
        try:
            self.model.model_validate(status)
        except ValidationError as e:
            self.invalid += 1
            for err in e.errors():
                where = ".".join(str(x) for x in err["loc"])
                if where not in self._told:
                    self._told.add(where)
                    value = "" if err["type"] == "missing" else f" = {repr(err.get('input'))[:80]}"
                    log.warning(
                        "status: %s%s does not fit its schema: %s", where, value, err["msg"]
                    )

    async def run(self) -> None:
        token = self.session.liveliness().declare_token(self.alive_key)
        pub = self.session.declare_publisher(self.key, encoding=zenoh.Encoding.APPLICATION_JSON)
        try:
            while True:
                now = time.time()
                self.latest = {"schema": self.schema, "t": now, **self.status(now)}
                self._check(self.latest)
                put_json(pub, self.latest, self.session)
                await asyncio.sleep(self.period_s)
        finally:
            pub.undeclare()
            token.undeclare()

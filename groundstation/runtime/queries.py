"""Zenoh queryables of a skyfix service: its operator's commands and the late joiners' latest values.

:class:`ZenohControl` declares one queryable per command on ``<prefix>/<command>`` (:data:`COMMANDS`; what each
does is the live service's :mod:`groundstation.live.control`) answered by the service's ``handle(command,
payload)``, and one per ``latest`` key answering the latest JSON published there (``skyfix fuse`` declares only
these). A command that cannot be done is a Zenoh error reply ``{"error": "<one line>"}`` (:class:`ControlError`).
Zenoh calls back on its own threads: the callbacks only hand the query to the event loop
(``call_soon_threadsafe``), where it is answered and dropped.
"""

from __future__ import annotations

import asyncio
import functools
import json
import logging
import math
from collections.abc import Callable
from typing import Protocol

import zenoh

log = logging.getLogger("skyfix.control")

COMMANDS = ("select", "release", "acquire", "confirm", "status")
#: The commands that change what the service does: run only for a query on their exact key.
ACTIONS = ("select", "release", "acquire", "confirm")


class ControlError(ValueError):
    """A command that cannot be done; the message is one line naming the value."""


def jsonable(obj):
    """``obj`` with non-finite floats as None (JSON has no NaN) and tuples as lists."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    return obj


class Commands(Protocol):
    """What answers the commands: ``handle(command, payload)``, the answer's JSON-ready dict, or
    :class:`ControlError`."""

    async def handle(self, command: str, payload: bytes) -> dict: ...


class ZenohControl:
    """Worker declaring the command queryables under ``prefix`` and the late joiners' ones (``latest``:
    key → function giving the latest JSON-ready value published there, or None); ``control`` None: the late
    joiners' only (``skyfix fuse`` takes no commands)."""

    def __init__(
        self,
        session: zenoh.Session,
        control: Commands | None,
        prefix: str,
        latest: dict[str, Callable[[], dict | None]],
    ):
        self.session = session
        self.control = control
        self.prefix = prefix.rstrip("/")
        self.latest = latest
        self.answered = 0
        self.refused = 0
        self._tasks: set[asyncio.Task] = set()

    async def run(self) -> None:
        loop = asyncio.get_running_loop()

        def hand_over(handler):
            def on_query(query: zenoh.Query) -> None:  # Zenoh's thread: hand over only
                try:
                    loop.call_soon_threadsafe(handler, query)
                except RuntimeError:  # loop closed: shutting down
                    query.drop()

            return on_query

        queryables = [
            self.session.declare_queryable(
                f"{self.prefix}/{name}", hand_over(functools.partial(self._command, name))
            )
            for name in (COMMANDS if self.control else ())
        ]
        queryables += [
            self.session.declare_queryable(
                key, hand_over(functools.partial(self._latest, key, latest))
            )
            for key, latest in self.latest.items()
        ]
        try:
            await asyncio.Event().wait()
        finally:
            for task in self._tasks:
                task.cancel()
            await asyncio.gather(*self._tasks, return_exceptions=True)
            for q in queryables:
                q.undeclare()

    def _command(self, name: str, query: zenoh.Query) -> None:
        key = f"{self.prefix}/{name}"
        if name in ACTIONS and str(query.key_expr) != key:
            query.drop()  # a wildcard query (skyfix/**) does not run commands
            return
        payload = query.payload.to_bytes() if query.payload is not None else b""
        task = asyncio.create_task(self._answer(query, key, name, payload))
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def _answer(self, query: zenoh.Query, key: str, name: str, payload: bytes) -> None:
        with query:
            try:
                result = await self.control.handle(name, payload)
            except ControlError as e:
                self.refused += 1
                log.warning("command %s refused: %s", key, e)
                query.reply_err(
                    json.dumps({"error": str(e)}), encoding=zenoh.Encoding.APPLICATION_JSON
                )
                return
            except Exception as e:  # a bug in one command must not stop the service
                log.exception("command %s failed", key)
                query.reply_err(
                    json.dumps({"error": f"{name}: internal error: {e}"}),
                    encoding=zenoh.Encoding.APPLICATION_JSON,
                )
                return
            query.reply(
                key, json.dumps(result, allow_nan=False), encoding=zenoh.Encoding.APPLICATION_JSON
            )
            self.answered += 1

    def _latest(self, key: str, latest: Callable[[], dict | None], query: zenoh.Query) -> None:
        with query:
            value = latest()
            if value is not None:
                query.reply(
                    key,
                    json.dumps(jsonable(value), allow_nan=False),
                    encoding=zenoh.Encoding.APPLICATION_JSON,
                )

    def status(self) -> dict:
        return {"prefix": self.prefix, "answered": self.answered, "refused": self.refused}

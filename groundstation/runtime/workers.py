"""The service's workers in one place: each with its run, its stop stage, its status section and whether it is an input.

A worker is an object with ``async run()``; :meth:`Workers.add` declares the rest:

- ``stage``: when it is stopped — :data:`INPUTS` (the links in, the operator's commands
  and page) first, then :data:`PIPELINE`, then :data:`OUTPUTS` (the status, the
  recording), and :data:`LAST` (GPS_INPUT, whose last message says "no fix") once
  nothing feeds it;
- ``key`` and ``status``: the section of the service's status it fills, and the callable
  ``status(now)`` that fills it (by default the worker's own ``status(now)``);
- ``is_input``: the watchdog judges it (its status section is in :meth:`Workers.inputs`).

The service's status is :meth:`Workers.status`: every section in the order the
workers were added, plus the sections that are no worker's (:meth:`Workers.section`).
Adding an input is one :meth:`~Workers.add`. Stopping (:meth:`Workers.run`): each stage's
tasks cancelled and awaited before the next; a stage slower than :data:`STAGE_S` is logged.
"""

from __future__ import annotations

import asyncio
import json
import logging
import sys
from collections.abc import Awaitable, Callable, Coroutine
from dataclasses import dataclass

log = logging.getLogger("skyfix.run")

INPUTS, PIPELINE, OUTPUTS, LAST = range(4)
STAGE_S = 0.3  # a stage of the stop longer than this is logged


@dataclass(frozen=True)
class _Entry:
    worker: object
    stage: int
    key: str | None
    status: Callable[[float], dict] | None
    is_input: bool


class Workers:
    """The registry of the module doc."""

    def __init__(self):
        self._entries: list[_Entry] = []
        self._sections: list[tuple[str, Callable[[float], object]]] = []
        self._included: list[Workers] = []

    def add(
        self,
        worker,
        stage: int,
        key: str | None = None,
        status: Callable[[float], dict] | None = None,
        is_input: bool = False,
    ):
        """Declare ``worker``; returns it."""
        if key is not None and status is None:
            status = worker.status
        self._entries.append(_Entry(worker, stage, key, status, is_input))
        return worker

    def section(self, key: str, status: Callable[[float], object]) -> None:
        """A status section that is no worker's (the height, the process's usage)."""
        self._sections.append((key, status))

    def include(self, other: Workers) -> None:
        """Run ``other``'s workers with these, in the same stop stages (one UUV's of several); its status and inputs
        stay its own."""
        self._included.append(other)

    def inputs(self, now: float) -> dict:
        """The inputs' status sections (the watchdog's view)."""
        return {e.key: e.status(now) for e in self._entries if e.is_input}

    def status(self, now: float) -> dict:
        """Every section: the workers' in the order they were added, then the others."""
        out = {e.key: e.status(now) for e in self._entries if e.key is not None}
        out.update((key, status(now)) for key, status in self._sections)
        return out

    async def run(self, until: Awaitable) -> None:
        """Run every worker until ``until`` completes (or one fails), then stop them stage by stage."""
        async with asyncio.TaskGroup() as tg:
            entries = [*self._entries, *(e for other in self._included for e in other._entries)]
            tasks = [
                (e.stage, tg.create_task(e.worker.run(), name=type(e.worker).__name__))
                for e in entries
            ]
            await until
            log.info("stopping")
            loop = asyncio.get_running_loop()
            for stage in sorted({s for s, _ in tasks}):
                now = [t for s, t in tasks if s == stage]
                t0 = loop.time()
                for task in now:
                    task.cancel()
                await asyncio.wait(now)
                if loop.time() - t0 > STAGE_S:
                    log.warning(
                        "stopping %s took %.2f s",
                        ", ".join(t.get_name() for t in now),
                        loop.time() - t0,
                    )


async def stopped(stop: asyncio.Event, duration_s: float | None) -> None:
    """Until ``stop`` is set (a signal) or ``duration_s`` has passed (None: no limit)."""
    try:
        await asyncio.wait_for(stop.wait(), timeout=duration_s)
    except TimeoutError:
        pass


def run_to_end(
    command: str, main: Coroutine, errors: tuple[type[BaseException], ...], stats: str | None
) -> dict | None:
    """Run a service's ``main`` (returning its final status) to its end: the final status, also written to ``stats``
    (JSON) when given; or None after printing each of ``errors`` in one line as ``skyfix COMMAND: error: ...``."""
    final = None
    try:
        final = asyncio.run(main)
    except* errors as eg:  # a link that cannot be opened: one line each
        for e in eg.exceptions:
            print(f"skyfix {command}: error: {e}", file=sys.stderr)
    if final is not None and stats:
        with open(stats, "w") as f:
            json.dump(final, f, indent=1)
    return final

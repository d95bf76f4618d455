"""Slow preparations made before a test needs them: ``pytest.mark.ahead.with_args(prepare)``.

Some tests spend most of their time waiting for things that need little of the CPU (a freshly booted ArduSub's
warm-up, real-time flights and replays), others render a large session first. ``prepare(directory, background)``
starts such a preparation (a session rendered by ``skyfix sim``, an autopilot booting) and returns an object with
``close()``. ``tests/conftest.py`` calls it ahead, with ``background`` true: while the test before runs; with
``module_before=True``, from the first test of the module before (a preparation longer than one test: an
autopilot's warm-up); with ``at_start=True``, from the run's first test (of another module: a module run alone
prepares its own).
Background renders (:class:`Render`) take only CPU that no test wants; one not done when needed goes on at the
tests' priority (or, where this user may not raise it, is started again at it). The test takes it with :func:`take` (or :func:`taken`), made then and there
when nothing was prepared ahead (the test run alone, or first). What a test gets is made the same way either way;
only when differs.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from live_helpers import ROOT, skyfix

MARKER = "ahead"
_READY: dict[Callable, object] = {}  # prepare → what it prepared
_STARTED: set[Callable] = set()  # each is prepared once


def _threads(pid: int) -> Iterator[int]:
    """The threads of process ``pid`` and of its descendants (``/proc``)."""
    with contextlib.suppress(FileNotFoundError, ProcessLookupError):
        for task in Path(f"/proc/{pid}/task").iterdir():
            yield int(task.name)
            for child in (task / "children").read_text().split():
                yield from _threads(int(child))


class Render:
    """``skyfix sim SCENARIO --out OUT`` (log ``LOG``), in the background (Linux's idle scheduling class, ``chrt
    --idle 0``: it and its children run only on CPU time no other process wants) or not."""

    def __init__(self, scenario: Path, out: Path, log: Path, background: bool):
        self.cmd = skyfix("sim", str(scenario), "--out", str(out), "--quiet")
        self.out, self.log = out, log
        self.proc = self._start(["chrt", "--idle", "0", *self.cmd] if background else self.cmd)
        self.background = background

    def _start(self, cmd: list[str]) -> subprocess.Popen:
        """In a process group of its own: :meth:`close` ends its rendering processes and its encoder too."""
        with open(self.log, "w") as f:
            return subprocess.Popen(
                cmd,
                stdout=f,
                stderr=subprocess.STDOUT,
                cwd=ROOT,
                env=dict(os.environ, PYTHONUNBUFFERED="1"),
                start_new_session=True,
            )

    def wait(self, timeout_s: float) -> Path:
        """The session, once rendered. A background render still running (on a busy machine it may have had no CPU
        at all) goes on at the tests' priority, or, where this user may not raise it, is started again so."""
        if self.background and self.proc.poll() is None:
            try:
                for tid in _threads(self.proc.pid):
                    with contextlib.suppress(ProcessLookupError):
                        os.sched_setscheduler(tid, os.SCHED_OTHER, os.sched_param(0))
            except PermissionError:
                self.close()
                self.proc = self._start(self.cmd)
        self.background = False
        assert self.proc.wait(timeout_s) == 0, self.log.read_text()[-3000:]
        return self.out

    def close(self) -> None:
        if self.proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait()


class Renders(dict[str, Render]):
    """Renders by name, closed together."""

    def close(self) -> None:
        for r in self.values():
            r.close()


def _prepare(item: pytest.Item, prepare: Callable) -> None:
    _STARTED.add(prepare)
    directory = item.config._tmp_path_factory.mktemp(f"ahead_{prepare.__module__}", numbered=True)
    try:
        _READY[prepare] = prepare(directory, True)
    except (Exception, pytest.skip.Exception):  # noqa: BLE001, S110 - the test meets it again in take()
        pass


def _next_module(item: pytest.Item) -> list[pytest.Item]:
    """The tests of the module after ``item``'s, when ``item`` is the first of its module; else none."""
    items = item.session.items
    i = items.index(item)
    module = getattr(item, "module", None)
    if i > 0 and getattr(items[i - 1], "module", None) is module:
        return []
    modules = [getattr(other, "module", None) for other in items[i:]]
    after = next((m for m in modules if m is not module), None)
    return (
        [] if after is None else [o for o, m in zip(items[i:], modules, strict=True) if m is after]
    )


def prepare_ahead(item: pytest.Item, nextitem: pytest.Item | None) -> None:
    """Before ``item`` runs: the preparations of ``nextitem``; on the first test of a module those marked
    ``module_before`` of the next module; on the run's first test those marked ``at_start`` of the other modules.
    A failure (a missing binary: a skip) is left for the test to meet itself."""
    for other in _next_module(item):
        for mark in other.iter_markers(MARKER):
            if mark.kwargs.get("module_before") and mark.args[0] not in _STARTED:
                _prepare(other, mark.args[0])
    if item is item.session.items[0]:
        for other in item.session.items:
            for mark in other.iter_markers(MARKER):
                if (
                    mark.kwargs.get("at_start")
                    and getattr(other, "module", None) is not getattr(item, "module", None)
                    and mark.args[0] not in _STARTED
                ):
                    _prepare(other, mark.args[0])
    for mark in nextitem.iter_markers(MARKER) if nextitem is not None else ():
        if not mark.kwargs.get("at_start") and mark.args[0] not in _STARTED:
            _prepare(nextitem, mark.args[0])


def taken(prepare: Callable):
    """What ``prepare`` prepared ahead, or None."""
    return _READY.pop(prepare, None)


def take(prepare: Callable, tmp_path: Path):
    """What ``prepare`` prepared ahead, else what it prepares now (in ``tmp_path``)."""
    ready = taken(prepare)
    return prepare(tmp_path, False) if ready is None else ready


def close_unused() -> None:
    """Close what was prepared for a test that did not run (deselected, or the run stopped before it)."""
    while _READY:
        _READY.popitem()[1].close()

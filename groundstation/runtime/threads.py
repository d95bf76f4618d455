"""The service's own threads and how their work reaches the event loop.

- :class:`Handoff`: items crossing from a thread into the loop (MAVLink messages, video
  frames, Zenoh samples) go into a bounded deque; one ``call_soon_threadsafe`` wakes the
  loop for a whole batch, and when the loop falls behind the oldest items are dropped and
  counted (``dropped``), never an unbounded pile of callbacks.
- :class:`Supervised`: a thread that owns a link or a reader runs its body under
  supervision: an unexpected exception (a bug, not the link's own I/O errors, which the
  body handles) is logged in one line (the kind: exception type and where it was raised;
  the same kind again only every 100th time) and the body restarts after a back-off
  (:data:`RESTART_S` doubling to :data:`RESTART_MAX_S`, back to the start once it ran
  :data:`STEADY_S`); ``restarts`` and ``failure`` go into the owner's status.
- :func:`in_thread`: a blocking call in a daemon thread of its own, awaited from the loop.
  Cancelling the await abandons the thread instead of waiting for it (a TCP connect or a
  thread join cannot be interrupted), so a stop never waits for I/O; the thread ends by itself.
- :func:`start_opencv_workers`: OpenCV's worker threads started by the service's own thread, at its priority.
- :func:`realtime`: the service's threads under Linux's round-robin realtime policy; :func:`not_realtime` takes a
  thread or process of background work back out of it, and :data:`OUTSIDE_REALTIME` starts processes outside it
  and at the normal nice value at most (multiprocessing's resource tracker too: :func:`in_background`).
"""

from __future__ import annotations

import asyncio
import logging
import os
import threading
import time
import traceback
from collections import deque
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from contextlib import suppress
from multiprocessing import resource_tracker
from multiprocessing.context import SpawnContext, SpawnProcess

import numpy as np

from groundstation.runtime.logs import Throttle

log = logging.getLogger("skyfix.threads")

RESTART_S = 0.25
RESTART_MAX_S = 5.0
STEADY_S = 10.0


class Handoff:
    """Thread → event loop: :meth:`put` on any thread, ``consume(item)`` on the loop, at most ``maxlen`` waiting."""

    def __init__(self, loop: asyncio.AbstractEventLoop, consume: Callable, maxlen: int):
        self.loop = loop
        self.consume = consume
        self.maxlen = maxlen
        self.dropped = 0
        self.handed = 0
        self._items: deque = deque()
        self._lock = threading.Lock()
        self._scheduled = False
        self.closed = False

    def put(self, item) -> None:
        with self._lock:
            if len(self._items) >= self.maxlen:
                self._items.popleft()
                self.dropped += 1
            self._items.append(item)
            if self._scheduled:
                return
            self._scheduled = True
        try:
            self.loop.call_soon_threadsafe(self._drain)
        except RuntimeError:  # the loop is closed: shutting down
            pass

    def _drain(self) -> None:
        with self._lock:
            items, self._items = self._items, deque()
            self._scheduled = False
        for item in items:
            if self.closed:
                return
            self.handed += 1
            self.consume(item)

    def close(self) -> None:
        """Hand nothing more over (the worker stopped; its thread may still be finishing)."""
        self.closed = True

    def status(self) -> dict:
        return {"handed": self.handed, "dropped": self.dropped}


def failure_kind(e: BaseException) -> str:
    """An exception's kind: its type and the innermost place it was raised (``ValueError at pipeline.py:123``)."""
    tb = traceback.extract_tb(e.__traceback__)
    where = f" at {tb[-1].filename.rsplit('/', 1)[-1]}:{tb[-1].lineno}" if tb else ""
    return f"{type(e).__name__}{where}"


class Supervised:
    """``body(stop)`` in a daemon thread named ``name``, restarted after an unexpected exception (see the module doc).

    ``body`` returns when ``stop`` (a :class:`threading.Event`) is set or its work is done.
    """

    def __init__(self, name: str, body: Callable[[threading.Event], None]):
        self.name = name
        self.body = body
        self.stop = threading.Event()
        self.restarts = 0
        self.failure: str | None = None
        self._throttle = Throttle(first=1, every=100)
        self.thread = threading.Thread(target=self._run, name=name, daemon=True)

    def start(self) -> None:
        self.thread.start()

    def _run(self) -> None:
        wait_s = RESTART_S
        while not self.stop.is_set():
            t_start = time.monotonic()
            try:
                self.body(self.stop)
                return
            except Exception as e:  # noqa: BLE001 - any bug: one line, then the body again
                kind = failure_kind(e)
                self.failure = f"{kind}: {e}"
                self.restarts += 1
                if time.monotonic() - t_start >= STEADY_S:
                    wait_s = RESTART_S
                n = self._throttle(kind)
                if n:
                    log.error(
                        "%s thread failed (%s, #%d); restarting in %.2f s",
                        self.name,
                        self.failure,
                        n,
                        wait_s,
                    )
                self.stop.wait(wait_s)
                wait_s = min(2.0 * wait_s, RESTART_MAX_S)

    def join(self, timeout_s: float) -> bool:
        """Set ``stop`` and wait up to ``timeout_s`` for the thread; True if it ended."""
        self.stop.set()
        if self.thread.ident is not None:
            self.thread.join(timeout_s)
        return not self.thread.is_alive()

    def status(self) -> dict:
        return {"restarts": self.restarts, "failure": self.failure}


async def in_thread(fn: Callable, *args, name: str = "skyfix-io"):
    """``fn(*args)`` in a daemon thread of its own; its result or exception. Cancelling abandons the thread."""
    loop = asyncio.get_running_loop()
    done = loop.create_future()

    def settle(ok: bool, value) -> None:
        if not done.done():
            (done.set_result if ok else done.set_exception)(value)

    def main() -> None:
        try:
            result, ok = fn(*args), True
        except BaseException as e:  # noqa: BLE001 - handed to the awaiting task
            result, ok = e, False
        try:
            loop.call_soon_threadsafe(settle, ok, result)
        except RuntimeError:  # the loop is gone: nobody waits any more
            pass

    threading.Thread(target=main, name=name, daemon=True).start()
    return await done


def start_opencv_workers() -> None:
    """Start OpenCV's worker threads now, from the calling thread (the service's, at its priority).

    OpenCV starts its pool of worker threads at the first call that splits its work, in the thread that makes it,
    and a new thread takes the nice value of the thread that starts it. A low-priority thread of the service (the
    page's feed encoder, at nice 10) that came first would leave every frame's OpenCV work (the tracker's, the
    decoded frame's conversion) waiting for nice-10 workers, which beside busy programs get a core seldom. The
    latency estimate's thread used to (``bench/live_latency.py``'s per-nice line: nice-10 threads waiting for a core
    more than one thread's whole time). A 1080p downscale splits its work whatever the pool's size.
    """
    import cv2  # here: this module's other users (the MAVLink link, Zenoh, the fuse service) need no OpenCV

    cv2.resize(np.zeros((1080, 1920), np.uint8), (960, 540), interpolation=cv2.INTER_AREA)


def realtime(priority: int) -> tuple[bool, str]:
    """The calling thread under Linux's round-robin realtime policy (``SCHED_RR``) at ``priority`` (1: the lowest),
    and with it every thread and process it starts from now on (a new thread takes its creator's policy); whether it
    got it, and a line saying what it runs under.

    A realtime thread that wakes takes a core from the programs of the normal policy at once, whatever their nice
    values and their sessions' shares; one that never sleeps would keep a core, and the kernel's realtime throttling
    (``/proc/sys/kernel/sched_rt_runtime_us``: 95 % of each second) leaves the rest of the system the remainder.
    Without the privilege (root, ``CAP_SYS_NICE`` or an ``RLIMIT_RTPRIO`` of at least ``priority``: the unit's
    ``LimitRTPRIO``) the thread stays as it was and the line says so. Background work leaves it: a thread by
    :func:`not_realtime`, a process by starting outside it (:data:`OUTSIDE_REALTIME`).
    """
    nice = os.getpriority(os.PRIO_PROCESS, 0)
    try:
        os.sched_setscheduler(0, os.SCHED_RR, os.sched_param(priority))
    except (
        OSError,
        AttributeError,
    ) as e:  # no privilege; a priority beyond the policy's; no such call (not Linux)
        why = getattr(e, "strerror", None) or "no sched_setscheduler on this system"
        return False, (
            f"scheduling: not realtime (SCHED_RR priority {priority} refused: {why}; the unit's LimitRTPRIO "
            f"allows it): nice {nice}"
        )
    # multiprocessing's resource tracker, a process started by the thread that first makes a pool's lock or a shared
    # frame (a realtime one: realtime itself): started now, as background work
    in_background(resource_tracker.ensure_running)
    return (
        True,
        f"scheduling: SCHED_RR priority {priority} (realtime, round-robin); its background work not realtime",
    )


def not_realtime() -> None:
    """The calling thread back under the normal policy, at the nice value it had: for background work started by a
    realtime thread (:func:`realtime`), before it lowers its priority further; a no-op where there is no realtime
    policy to leave."""
    if hasattr(os, "sched_getscheduler") and os.sched_getscheduler(0) in (
        os.SCHED_RR,
        os.SCHED_FIFO,
    ):
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))


#: Background processes (the measuring processes, the side jobs) work this many nice levels below the service
#: (:func:`background_nice`): at the unit's ``Nice=-10``, nice 0; they yield the CPU to decoding and tracking.
BACKGROUND_NICE = 10


def _start_background() -> None:
    """The calling thread (one that starts a background process, which takes its policy and nice value) out of the
    realtime policy and at the normal nice value (0) at most: not at the service's raised priority (Linux: a thread
    is a task; elsewhere the nice value stays)."""
    not_realtime()
    with suppress(AttributeError, OSError):
        tid = threading.get_native_id()
        os.setpriority(os.PRIO_PROCESS, tid, max(os.getpriority(os.PRIO_PROCESS, tid), 0))


def background_nice() -> int:
    """In a background process started by :func:`in_background`: the nice value it works at, :data:`BACKGROUND_NICE`
    levels below its parent's (the service's main thread) and never below the one it started at (at most 19)."""
    parent = os.getpriority(os.PRIO_PROCESS, os.getppid())
    return max(os.getpriority(os.PRIO_PROCESS, 0), min(19, parent + BACKGROUND_NICE))


def in_background(fn: Callable, *args):
    """``fn(*args)`` (a process's start) in a short-lived thread outside the realtime policy and at the normal nice
    value at most (:func:`_start_background`), its result: the process starts there, its interpreter's start and
    imports included, while the calling thread keeps its policy and nice value."""
    with ThreadPoolExecutor(
        1, thread_name_prefix="skyfix-spawn", initializer=_start_background
    ) as spawner:
        return spawner.submit(fn, *args).result()


class _SpawnedOutsideRealtime(SpawnProcess):
    @staticmethod
    def _Popen(process_obj):  # multiprocessing's hook for a process's start: the spawn itself
        return in_background(SpawnProcess._Popen, process_obj)


class _OutsideRealtime(SpawnContext):
    Process = _SpawnedOutsideRealtime


#: multiprocessing's spawn context (a ``ProcessPoolExecutor``'s ``mp_context``), its processes started by a thread of
#: their own that left the realtime policy and the service's negative nice value first (:func:`in_background`): a new
#: process takes the policy and nice value of the thread that starts it, and one that left them in its own first call
#: would run its interpreter's start and imports at the service's priority, at each start and each restart. The
#: thread that asks (its pool's) keeps its own. The process's first call sets the nice value it works at
#: (:func:`background_nice`).
OUTSIDE_REALTIME = _OutsideRealtime()

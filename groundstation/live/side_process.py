"""A live side job's process: the work of the live mosaic's painter (:mod:`.mosaic_live`), the search for a
surveyed marker (:mod:`.reference_live`) and the bottom's tracking and fit (:mod:`.bottom_live`) done outside the
service's interpreter.

Their work is Python and NumPy. In a thread of the service at a low priority it held the interpreter's lock while it
waited for a core beside busy programs, and every frame's thread waited with it (``bench/gil_inversion.py``: a
nice-10 thread's Python made the frame thread miss slots). In a process of its own (:class:`SideProcess`) it takes a
core's time, never the service's lock: the service's thread only hands the frame over (into shared memory,
:class:`~groundstation.height_from_size.SharedFrame`: a copy with the lock released, not a pickle into a pipe) and
waits for the answer.

The process (:func:`start_side_process`) is 10 nice levels below the service and at least at nice
:data:`~groundstation.live.ui.feed.ENCODER_NICE`, as the threads were: the side jobs yield the CPU to the fixes and
to every program beside them; it ends with the service (its parent-death signal, even on a ``kill -9``). Its state
(the painter's grid, the bottom's window) is made by the job's ``start`` at each start of the process. A process
that dies (a crash, killed) is one line in the log and a new one, its state started again; the call it took is
lost (:class:`ProcessLost`). :meth:`SideProcess.close` ends it at once (a fit in progress is not waited for).
"""

from __future__ import annotations

import logging
import os
import threading
from collections.abc import Callable
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool

import numpy as np

from groundstation.height_from_size import SharedFrame, shared_image, start_measuring_process
from groundstation.live.ui.feed import ENCODER_NICE
from groundstation.runtime.threads import OUTSIDE_REALTIME

log = logging.getLogger("skyfix.side")

#: A frame in shared memory as the process reads it (:meth:`SharedFrame.put`): the block's name, shape, dtype.
FrameRef = tuple[str, tuple[int, ...], str]


class ProcessLost(RuntimeError):
    """The side job's process ended while it worked on a call (logged once, a new one started)."""


def start_side_process() -> None:
    """The process: :func:`start_measuring_process` (the service's nice + 10, ending with it), and at least at nice
    :data:`~groundstation.live.ui.feed.ENCODER_NICE`: the fixes' CPU comes first and the laptop's other programs'
    too."""
    start_measuring_process()
    os.setpriority(os.PRIO_PROCESS, 0, max(os.getpriority(os.PRIO_PROCESS, 0), ENCODER_NICE))


def _started(start: Callable, args: tuple) -> None:
    """The process: the job's ``start(*args)`` (its state, its imports)."""
    start(*args)


def on_frame(fn: Callable, frame: FrameRef, *args):
    """The process: ``fn(image, *args)`` of the frame :meth:`SharedFrame.put` put in."""
    return fn(shared_image(frame), *args)


class SideProcess:
    """One side job's process (see the module doc): ``start(*args)`` runs in it first (each time it starts; module
    functions, as the calls' ``fn``); :meth:`call` and :meth:`call_on` any thread's, one at a time each."""

    def __init__(self, name: str, start: Callable, *args):
        self.name = name
        self.restarts = 0  # processes started again after one ended
        self._start = (start, args)
        # one frame at a time: its caller hands over the next once this one is done
        self._shared = SharedFrame()
        self._lock = threading.Lock()
        self._closed = False
        #: the process's start (its ``start`` done): a future
        self._pool, self.started = self._begin()

    def _begin(self) -> tuple[ProcessPoolExecutor, Future]:
        pool = ProcessPoolExecutor(1, mp_context=OUTSIDE_REALTIME, initializer=start_side_process)
        # it starts and imports now, not at the first call
        return pool, pool.submit(_started, *self._start)

    def call(self, fn: Callable, *args):
        """``fn(*args)`` in the process, waited for; :class:`ProcessLost` when the process ended meanwhile."""
        pool = self._pool
        try:
            return pool.submit(fn, *args).result()
        except RuntimeError as e:  # BrokenProcessPool, or the pool shut down by close()
            if not (isinstance(e, BrokenProcessPool) or self._closed):
                raise
            self._restart(pool)
            raise ProcessLost(f"{self.name}: its process ended") from None

    def call_on(self, fn: Callable, image: np.ndarray, *args):
        """``fn(image, *args)`` in the process, the image handed over in shared memory (one caller at a time)."""
        with self._lock:
            if self._closed:
                raise ProcessLost(f"{self.name}: stopped")
            frame = self._shared.put(image)
        return self.call(on_frame, fn, frame, *args)

    def _restart(self, broken: ProcessPoolExecutor) -> None:
        with self._lock:
            if self._closed or broken is not self._pool:  # stopping, or another caller restarted it
                return
            self.restarts += 1
            log.error("%s: its process ended; a new one started (#%d)", self.name, self.restarts)
            broken.shutdown(wait=False, cancel_futures=True)
            self._pool, self.started = self._begin()

    def close(self) -> None:
        """End the process now, started or still starting: a call it works on or waits for ends in
        :class:`ProcessLost`, not waited for."""
        with self._lock:
            self._closed = True
            # the pool's own processes (Python 3.14's terminate_workers()); the pool sees them end
            for process in list((self._pool._processes or {}).values()):
                process.terminate()
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._shared.close()

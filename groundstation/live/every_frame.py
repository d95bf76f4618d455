"""A frame every so many seconds of video for a side job of the live service (the live mosaic's painter,
:mod:`.mosaic_live`; the search for a surveyed marker, :mod:`.reference_live`; the bottom's tracking,
:mod:`.bottom_live`).

:meth:`EveryFrame.on_frame` (a frame listener, on the event loop) takes a frame once ``every_s`` seconds of video
have passed since the last one taken, computes its camera pose from the telemetry there is then
(:func:`localizer.pose.uav_pose`) and hands the image and the pose to ``work`` in a thread of its own, at the
service's priority: ``work`` hands the frame to the job's process (:class:`groundstation.live.side_process.SideProcess`,
at a low priority) and waits for it, the interpreter's lock released (a low-priority thread of the service that held
the lock kept the frames' threads waiting while it waited for a core). A frame that comes due while ``work`` is still
busy with the one before is skipped and counted (``skipped``): the job takes the CPU the rest of the service leaves.
A frame without a pose (no telemetry yet, a camera under the surface) is counted (``no_pose``) and not worked on.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from groundstation.live.side_process import ProcessLost
from localizer.pose import CameraPose, uav_pose

log = logging.getLogger(__name__)


class EveryFrame:
    """``work(image, pose)`` on a frame every ``every_s`` s of video (see the module doc); ``name`` names its thread
    and its errors in the log."""

    def __init__(
        self,
        cal,
        tel,
        every_s: float,
        work: Callable[[np.ndarray, CameraPose], None],
        name: str,
    ):
        self.cal, self.tel, self.every_s, self.work, self.name = cal, tel, every_s, work, name
        #: ``adjust(pose)`` (on the loop) the pose the work gets, when set: the pose another estimate corrected
        self.adjust: Callable[[CameraPose], CameraPose] | None = None
        self.skipped = 0  # frames due while the work was busy
        self.no_pose = 0  # frames due without a camera pose
        self._busy = False
        self._last_t = -math.inf
        self._thread = ThreadPoolExecutor(1, thread_name_prefix=name)

    def on_frame(self, frame) -> None:
        if frame.t_unix - self._last_t < self.every_s:
            return
        if self._busy:
            self.skipped += 1
            return
        self._last_t = frame.t_unix
        pose = uav_pose(self.cal, self.tel, frame.t_unix)
        if pose.status[0] != "ok" or not pose.height_m[0] > 0:
            self.no_pose += 1
            return
        if self.adjust is not None:
            pose = self.adjust(pose)
        self._busy = True
        self._thread.submit(self.work, frame.image, pose).add_done_callback(self._done)

    def _done(self, done) -> None:
        self._busy = False
        # a process lost is logged where it is started again
        if done.exception() is not None and not isinstance(done.exception(), ProcessLost):
            log.error("%s: a frame could not be worked on: %s", self.name, done.exception())

    def close(self) -> None:
        self._thread.shutdown(wait=True, cancel_futures=True)

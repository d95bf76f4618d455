"""OpenCV's worker threads keep the service's priority (:func:`groundstation.runtime.threads.start_opencv_workers`): a thread
of the service at nice 10 that runs OpenCV (the page's feed encoder) must not start the pool that every frame's
OpenCV work then waits for. Each case in a fresh interpreter: OpenCV starts its pool once per process."""

from __future__ import annotations

import json
import os
import subprocess
import sys

SCRIPT = """
import json, sys, threading
from pathlib import Path
import numpy as np
from groundstation.live.ui.feed import encode_jpeg, lower_priority
from groundstation.runtime.threads import start_opencv_workers

if sys.argv[1] == "started":
    start_opencv_workers()
low = []
def encode():
    lower_priority()
    low.append(threading.get_native_id())
    encode_jpeg(np.zeros((1080, 1920, 3), np.uint8), 960, 80)
thread = threading.Thread(target=encode)
thread.start()
thread.join()
nices = [
    int((task / "stat").read_text().rsplit(")", 1)[1].split()[16])
    for task in Path("/proc/self/task").iterdir()
    if int(task.name) not in low
]
print(json.dumps(sorted(set(nices))))
"""


def thread_nices(case: str) -> list[int]:
    """The nice values of a fresh interpreter's threads (the low-priority one left out) after it ran ``case``."""
    out = subprocess.run(
        [sys.executable, "-c", SCRIPT, case], capture_output=True, text=True, check=True
    )
    return json.loads(out.stdout)


def test_opencv_workers_started_by_the_service_keep_its_priority():
    base = os.getpriority(os.PRIO_PROCESS, 0)  # the fresh interpreter's, inherited
    assert thread_nices("started") == [base]
    # the case it guards against: started by the nice-10 thread's OpenCV call, the workers stay at nice 10
    assert thread_nices("not started") == sorted({base, 10})

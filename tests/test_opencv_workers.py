"""OpenCV's worker threads keep the service's priority (:func:`groundstation.runtime.threads.start_opencv_workers`): a thread
of the service at nice 10 that runs OpenCV (the page's feed encoder) must not start the pool that every frame's
OpenCV work then waits for. Each case in a fresh interpreter: OpenCV starts its pool once per process."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

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


REALTIME = """
import json, os, resource, sys, threading
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from groundstation.live.ui.feed import lower_priority
from groundstation.runtime.threads import OUTSIDE_REALTIME, realtime, start_opencv_workers

def scheduling(stat):
    fields = Path(stat).read_text().rsplit(")", 1)[1].split()
    return [int(fields[38]), int(fields[37]), int(fields[16])]  # policy, realtime priority, nice

if sys.argv[1] == "refused":
    if os.geteuid() == 0:
        os.setuid(65534)  # root may always; nobody without an RLIMIT_RTPRIO may not
    resource.setrlimit(resource.RLIMIT_RTPRIO, (0, 0))
else:
    soft, hard = resource.getrlimit(resource.RLIMIT_RTPRIO)
    if os.geteuid() != 0 and hard != resource.RLIM_INFINITY and hard < 1:
        print(json.dumps(None))  # no privilege to grant it here
        sys.exit()
    if os.geteuid() != 0:
        resource.setrlimit(resource.RLIMIT_RTPRIO, (1, hard))
if sys.argv[1] == "granted" and os.geteuid() == 0:
    os.setpriority(os.PRIO_PROCESS, 0, -10)  # the unit's Nice=-10
before = {t.name for t in Path("/proc/self/task").iterdir()}  # numpy's BLAS threads: started at its import
granted, line = realtime(1)
out = {"granted": granted, "line": line, "main": scheduling("/proc/thread-self/stat")}
if granted:
    start_opencv_workers()
    low = []
    def background():
        lower_priority()
        low.append((threading.get_native_id(), scheduling("/proc/thread-self/stat")))
    thread = threading.Thread(target=background)
    thread.start()
    thread.join()
    low_id, out["low"] = low[0]
    started = [t for t in Path("/proc/self/task").iterdir() if t.name not in before | {str(low_id)}]
    out["threads"] = sorted({tuple(scheduling(t / "stat")) for t in started}) if started else None
    # the measuring process's policy as its first code of ours sees it: before the initializer leaves the policy
    # (nothing else changes it after the spawn), so its interpreter's start and imports ran under it too
    at_start = "import os; os.environ['AT_START'] = f'{os.sched_getscheduler(0)} {os.getpriority(os.PRIO_PROCESS, 0)}'"
    measuring = "from groundstation.height_from_size import start_measuring_process; start_measuring_process()"
    with ProcessPoolExecutor(1, OUTSIDE_REALTIME, exec, (f"{at_start}; {measuring}", {})) as pool:
        policy = pool.submit(os.sched_getscheduler, 0).result(60)
        nice = pool.submit(os.getpriority, os.PRIO_PROCESS, 0).result(60)
        out["process at start"] = [int(x) for x in pool.submit(os.getenv, "AT_START").result(60).split()]
        out["process"] = [policy, nice]
    out["main after the spawn"] = scheduling("/proc/thread-self/stat")  # the thread that asked keeps its policy
    # multiprocessing's resource tracker (the pool's locks and queues are registered with it): a process too
    from multiprocessing import resource_tracker
    out["resource tracker"] = scheduling(f"/proc/{resource_tracker._resource_tracker._pid}/stat")
out["nice"] = os.getpriority(os.PRIO_PROCESS, 0)
print(json.dumps(out))
"""


def realtime_case(case: str) -> dict | None:
    out = subprocess.run(
        [sys.executable, "-c", REALTIME, case], capture_output=True, text=True, check=True
    )
    return json.loads(out.stdout.splitlines()[-1])


def test_realtime_takes_the_services_threads_and_leaves_its_background_out():
    """``--realtime-priority 1`` (deploy/field.toml) at the unit's nice -10 (where root may): the thread that asks,
    and the threads it starts after (OpenCV's workers), run SCHED_RR 1; the page's encoder thread, a measuring process
    and multiprocessing's resource tracker leave it (SCHED_OTHER; the encoder and the measuring process 10 nice levels
    lower: a realtime background would take the cores the fixes and the laptop's other programs need), the processes
    from their start, at the normal nice value at most: their interpreter's start and imports too."""
    got = realtime_case("granted")
    if got is None:
        pytest.skip("no privilege for SCHED_RR here (not root, RLIMIT_RTPRIO 0)")
    nice = got["nice"]
    rr = [os.SCHED_RR, 1, nice]
    assert nice == (-10 if os.geteuid() == 0 else os.getpriority(os.PRIO_PROCESS, 0))
    assert got["granted"] and got["main"] == rr and "SCHED_RR priority 1" in got["line"]
    assert got["low"] == [os.SCHED_OTHER, 0, 10]
    assert got["threads"] == [rr]
    # started at the normal nice at most (not the service's -10), working 10 levels below the service
    assert got["process at start"] == [os.SCHED_OTHER, max(nice, 0)]
    assert got["process"] == [os.SCHED_OTHER, min(nice + 10, 19)]
    assert got["resource tracker"] == [os.SCHED_OTHER, 0, max(nice, 0)]
    assert got["main after the spawn"] == rr


def test_realtime_refused_is_one_line_and_the_service_runs_as_before():
    got = realtime_case("refused")
    assert not got["granted"] and got["main"][0] == os.SCHED_OTHER
    assert got["line"].startswith("scheduling: not realtime (SCHED_RR priority 1 refused: ")
    assert "\n" not in got["line"]

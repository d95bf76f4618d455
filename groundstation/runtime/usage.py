"""The service's own CPU and memory use, for the status (``process``)."""

from __future__ import annotations

import os
import time
from collections import deque

WINDOW_S = 5.0


def rss_mb() -> float | None:
    """This process's resident memory (MB), from /proc (None where there is none)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (OSError, ValueError, IndexError):
        return None


class Usage:
    """CPU (% of one core, all threads, over the last :data:`WINDOW_S`) and resident memory of this process."""

    def __init__(self, window_s: float = WINDOW_S):
        self.window_s = window_s
        self._samples: deque[tuple[float, float]] = deque(maxlen=1000)  # (wall, CPU seconds)

    def status(self, now: float) -> dict:
        self._samples.append((now, time.process_time()))
        while len(self._samples) > 2 and now - self._samples[1][0] >= self.window_s:
            self._samples.popleft()
        (t0, c0), (t1, c1) = self._samples[0], self._samples[-1]
        cpu = 100.0 * (c1 - c0) / (t1 - t0) if t1 - t0 >= 0.5 else None
        rss = rss_mb()
        return {
            "cpu_pct": None if cpu is None else round(cpu, 1),
            "rss_mb": None if rss is None else round(rss, 1),
        }

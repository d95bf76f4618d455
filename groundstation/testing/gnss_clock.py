"""A station clock stepped against GNSS time, sample by sample (SYSTEM_TIME at 2 Hz), for
tests/test_gnss_clock_step.py and bench/gnss_clock_steps.py."""

from __future__ import annotations

import pytest

from localizer.telemetry import Telemetry

T0 = 1_750_000_000.0
HZ = 2.0
AHEAD_S = 0.32  # the station clock ahead of GNSS time, plus the link's delay


def feed(tel: Telemetry, k0: int, k1: int, step_s: float, bad: dict | None = None) -> list:
    """SYSTEM_TIME samples k0..k1-1 with the station clock stepped by ``step_s``; ``bad``: sample → a GNSS time
    that far off (a wrong time_unix_usec). The offset after each."""
    out = []
    for k in range(k0, k1):
        gnss = T0 + k / HZ
        unix = gnss + (bad or {}).get(k, 0.0)
        assert tel.add_system_time(
            100_000 + round(k * 1000 / HZ), round(unix * 1e6), gnss + AHEAD_S + step_s
        )
        out.append(tel.station_minus_gnss_s)
    return out


def moved_and_followed(step_s: float) -> tuple[int, int, Telemetry]:
    """Samples after the step until the offset first moved, and until it was the new one; the telemetry."""
    tel = Telemetry()
    feed(tel, 0, 60, 0.0)
    after = feed(tel, 60, 200, step_s)
    moved = next(i for i, x in enumerate(after) if abs(x - AHEAD_S) > 1.0)
    followed = next(
        i for i, x in enumerate(after) if x == pytest.approx(AHEAD_S + step_s, abs=0.01)
    )
    return moved, followed, tel

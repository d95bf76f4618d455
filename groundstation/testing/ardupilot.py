"""ArduPilot's own judgement of what skyfix sends it, written from its source (not from skyfix's), for the tests and
the benches."""

from __future__ import annotations

import numpy as np


def ardupilot_gps_unhealthy(t_recv_s) -> str | None:
    """Why ArduPilot would call a MAVLink GPS fed at these receive times (s) unhealthy, or None.

    Written from AP_GPS (``update_instance`` and ``is_healthy``), not from skyfix: a gap over 245 ms
    counts as delayed, two delayed in a row are unhealthy, and the mean gap, low-pass filtered with
    0.98/0.02 over gaps under 2 s, must stay under 215 ms. One late message (a loaded machine
    not scheduling a process for a few hundred ms) is allowed, as the firmware allows it.
    """
    delayed, average_ms = 0, 0.0
    for i, gap_ms in enumerate(np.diff(np.asarray(t_recv_s, dtype=float)) * 1000.0):
        delayed = delayed + 1 if gap_ms > 245.0 else 0
        if gap_ms < 2000.0:
            average_ms = gap_ms if average_ms <= 0 else 0.98 * average_ms + 0.02 * gap_ms
        if delayed >= 2:
            return (
                f"two gaps over 245 ms in a row, the second {gap_ms:.0f} ms, after message {i + 1}"
            )
        if average_ms >= 215.0:
            return f"mean gap {average_ms:.0f} ms after message {i + 1}"
    return None

"""Hostile input through the live service, the fast part of ``bench/fuzz.py``: 5 000 MAVLink datagrams and 500
depth payloads (random bytes, mutated frames with and without recomputed CRCs, absurd values, other systems and
components, the boot clock and the UUV's clock jumping) mixed into a replay of a bundled session, compared with
the same replay alone. The service must survive, count every rejection where it belongs (the counters add up),
lose no valid MAVLink frame to the garbage around it, send no GPS_INPUT that used a refused (poisoned) value,
and not leak memory. The checks are :func:`fuzz.check`'s; ``bench/fuzz.py`` runs 100 000 and 10 000.
"""

from __future__ import annotations

import sys

from live_helpers import ROOT

sys.path.insert(0, str(ROOT / "bench"))
import fuzz


def test_hostile_input_is_refused_and_counted(tmp_path):
    figures, failed = fuzz.fuzz_and_check(
        ROOT / "sim_fixtures" / "bundled" / "oblique_2m", tmp_path, 5_000, 500
    )
    print(
        {
            k: figures.get(k)
            for k in (
                "counts",
                "bad_data",
                "garbage_datagrams",
                "valid_gps_input",
                "frames_lost_to_load",
                "max_error_m",
                "rss_mb",
                "baseline_rss_mb",
                "gates",
            )
        }
    )
    assert not failed, "\n".join(failed)
    assert (
        sum(figures["by_kind"]["mavlink"].values()) == 5_000
        and sum(figures["by_kind"]["depth"].values()) == 500
    )

"""A step of the station clock seen against GNSS time (SYSTEM_TIME's time_unix_usec): the station-minus-GNSS offset
that gives each fix its GNSS time (t_gnss, GPS_INPUT's time) follows the step within two SYSTEM_TIME samples, the
step counted; one bad sample moves nothing. Before, the median of the last 31 samples kept the old offset for 16
samples after a -10 s step (8 s at 2 Hz: GPS_INPUT's time 10 s off while the fixes were valid again).

The autopilot sends SYSTEM_TIME at 2 Hz (ArduPilot's default stream rate); the station clock is 0.3 s ahead of GNSS
time and the link's delay 20 ms. A -10 s step of the station clock (NTP) maps the telemetry onto the new scale at
once (localizer.clock.ClockMap: our own clock stepped back); a +10 s step once the clock map's window has passed it
(until then the telemetry is stale and no fix is made)."""

from __future__ import annotations

import pytest

from groundstation.testing.gnss_clock import AHEAD_S, feed, moved_and_followed
from localizer.telemetry import Telemetry


def test_a_forward_step_is_followed_within_two_samples_of_the_telemetry_moving(monkeypatch):
    """+10 s: the telemetry's scale (the clock map's minimum) moves once its window has passed the step; from then
    the fixes are made again, and their GNSS time follows within two samples. The control, every sample into the
    median as before: the new offset some 14 samples (7 s) later, fixes 10 s off in GNSS time meanwhile."""
    moved, followed, tel = moved_and_followed(10.0)
    print(f"+10 s: the offset moved {moved} samples after the step, the new one {followed - moved} after that; "
          f"steps {tel.gnss_clock_steps} ({tel.last_gnss_clock_step_s:+.2f} s)")  # fmt: skip
    assert followed == moved  # the old offset, then the new: nothing between
    assert tel.gnss_clock_steps == 1 and tel.last_gnss_clock_step_s == pytest.approx(10.0, abs=0.01)
    assert any("stepped +10.00 s against GNSS time" in n for n in tel.notices)
    monkeypatch.setattr("localizer.telemetry.GNSS_STEP_S", float("inf"))
    _, followed_before, _ = moved_and_followed(10.0)
    print(
        f"control: the new offset {followed_before} samples after the step ({followed_before - followed} later)"
    )
    assert followed_before - followed >= 12


def test_a_backward_step_is_followed_at_once():
    """-10 s: the clock map takes the station clock stepping back at once (a new clock segment), and the offset
    starts again from the next sample; the notice says the station clock stepped, not that the autopilot
    rebooted."""
    moved, followed, tel = moved_and_followed(-10.0)
    assert moved == followed == 0
    # said as what it is: the autopilot's boot time went on
    assert any(n.startswith("the station clock stepped back") for n in tel.notices)
    assert not any("rebooted" in n for n in tel.notices), tel.notices


def test_one_bad_sample_moves_nothing():
    tel = Telemetry()
    feed(tel, 0, 60, 0.0)
    after = feed(tel, 60, 80, 0.0, bad={65: 10.0, 70: -7.0})
    assert after == pytest.approx([AHEAD_S] * 20, abs=0.01) and tel.gnss_clock_steps == 0

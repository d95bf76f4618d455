"""Clocks onto the station clock: least-delay alignment, drift, reboots, TIMESYNC round trips."""

import numpy as np
import pytest

from localizer.clock import OK, OUTLIER, RESTART, STEP, ClockMap, Median, RoundTrip


def test_least_delay_offset_and_its_window():
    """arrival − source: the offset plus each sample's delay; the map keeps the least within its window."""
    c = ClockMap(window_s=10.0)
    with pytest.raises(LookupError):
        c.to_arrival(1.0)
    off = 1_700_000_000.0
    delays = [0.080, 0.030, 0.120, 0.021, 0.045]
    for i, d in enumerate(delays):
        c.add(100.0 + i, off + 100.0 + i + d)
    assert c.offset_s == pytest.approx(off + 0.021, abs=1e-9)
    assert float(c.to_arrival(102.5)) == pytest.approx(off + 102.521, abs=1e-9)
    for i in range(
        20
    ):  # 20 s later the 21 ms sample has left the window: the least delay now is 40 ms
        c.add(110.0 + i, off + 110.0 + i + 0.040 + 0.01 * (i % 3))
    assert c.offset_s == pytest.approx(off + 0.040, abs=1e-9)
    assert c.segments == 0


def test_window_follows_a_drifting_clock():
    """A source clock running 200 ppm slow, received with 30–60 ms delays: the map stays within the
    drift over one window plus nothing else."""
    rng = np.random.default_rng(3)
    c = ClockMap(window_s=5.0)
    errs = []
    for k in range(2000):
        t = 1000.0 + 0.1 * k  # true time = station time
        source = t * (1 - 200e-6)
        c.add(source, t + 0.03 + rng.exponential(0.01))
        if k > 100:
            errs.append(float(c.to_arrival(source)) - 0.03 - t)
    assert max(abs(e) for e in errs) < 200e-6 * 5.0 + 0.002


def test_reboot_and_station_clock_step_start_new_segments():
    c = ClockMap(reboot_s=1.0, confirm=3, confirm_s=0.25)
    for i in range(10):
        assert c.add(600.0 + 0.1 * i, 2000.0 + 0.1 * i + 0.02) == OK
    assert c.offset_s == pytest.approx(1400.02)
    assert c.add(600.95, 2001.02) == OK  # 0.05 s back (reordered): not a reboot
    # boot clock back by 599 s: a reboot once samples agree for 0.25 s
    assert [c.add(2.0 + 0.1 * i, 2003.02 + 0.1 * i) for i in range(4)] == [OUTLIER] * 3 + [RESTART]
    assert c.segments == 1 and c.last_restart == (pytest.approx(600.95), 2.0)
    assert c.reboots == 1
    assert c.offset_s == pytest.approx(2001.02)
    # the station clock stepped back 13 s (NTP): our own clock, at once
    assert c.add(3.0, 1990.0) == RESTART
    assert c.segments == 2 and c.offset_s == pytest.approx(1987.0)
    assert c.reboots == 1  # the boot clock went on: the station's step is no reboot of the source


def test_stray_times_do_not_move_the_clock():
    """Single samples 5 s to an hour off, back or ahead, between good ones: not used, no segment, offset kept."""
    rng = np.random.default_rng(5)
    c = ClockMap(reboot_s=1.0, early_s=0.25, confirm=3)
    off = 1_700_000_000.0
    results = []
    for i in range(400):
        source = 100.0 + 0.02 * i
        results.append(c.add(source, off + source + 0.03 + rng.exponential(0.01)))
        if i % 2:
            stray = source + rng.choice([-1, 1]) * rng.uniform(5.0, 3600.0)
            assert c.add(stray, off + source + 0.04) == OUTLIER
    assert set(results) == {OK} and c.segments == 0 and c.outliers == 200
    assert c.offset_s == pytest.approx(off + 0.03, abs=0.005)


def test_a_burst_of_agreeing_strays_is_not_a_reboot():
    """Ten frames at once with the same made-up boot time, then the old clock again: no reboot."""
    c = ClockMap(confirm=3, confirm_s=0.3)
    for i in range(10):
        c.add(600.0 + 0.1 * i, 2000.0 + 0.1 * i)
    assert [c.add(0.001, 2001.0 + 0.001 * k) for k in range(10)] == [OUTLIER] * 10
    assert c.add(601.0, 2001.01) == OK and c.segments == 0 and c.candidates == 0


def test_a_clock_that_steps_ahead_is_followed_after_confirmation():
    """A UUV computer's clock synchronised mid-run (+40 s): three samples on the new clock, then it is used."""
    c = ClockMap(early_s=0.25, confirm=3, confirm_s=0.25)
    for i in range(10):
        assert c.add(1000.0 + 0.1 * i, 5000.0 + 0.1 * i) == OK
    assert [c.add(1041.0 + 0.1 * i, 5001.0 + 0.1 * i) for i in range(5)] == [OUTLIER] * 3 + [
        STEP,
        OK,
    ]
    assert c.offset_s == pytest.approx(3960.0) and c.segments == 0


def test_one_way_delay_from_the_least_delays_each_way():
    """Requests up with 20–90 ms delays, the autopilot's messages down with 20–70 ms: the least delays are
    20 ms both ways, and their mean is found although no single exchange had 20 ms both ways."""
    rt = RoundTrip(window_s=30.0)
    down = ClockMap(window_s=30.0)
    station_minus_boot = 1_700_000_000.0 - 412.0
    ups = [0.05, 0.02, 0.09, 0.03]
    downs = [0.07, 0.04, 0.02, 0.05]
    for i, (up, dn) in enumerate(zip(ups, downs)):
        sent = 1_700_000_100.0 + i
        remote = sent + up - station_minus_boot  # the autopilot's boot clock at receipt
        assert rt.add(remote, sent, sent + up + dn)
        # a message it sends 0.5 s later
        down.add(remote + 0.5, remote + 0.5 + station_minus_boot + dn)
    assert rt.round_trip_s == pytest.approx(0.06)  # the fastest exchange: 20 ms up but 40 ms down
    # float64 UNIX seconds: ~0.2 µs
    assert rt.one_way_delay_s(down) == pytest.approx(0.02, abs=1e-6)
    assert not rt.add(5.0, 100.0, 99.0)  # came back before it left
    assert not rt.add(5.0, 100.0, 103.0)  # 3 s round trip: not an answer to this request
    assert rt.exchanges == 4


def test_median_resists_outliers():
    m = Median(n=11)
    assert m.value is None
    for i in range(11):
        m.add(50.0 if i in (3, 7) else 2.5)
    assert m.value == 2.5

"""The height of the UAV above the water: the EKF height's error estimated from GNSS altitudes, a rangefinder
and other absolute heights, checked against hand-worked Kalman updates and the sigma growth the model states."""

import math

import numpy as np
import pytest

from localizer import gnss
from localizer.calibration import Calibration
from localizer.height import (
    AGREE_SIGMAS,
    CONFLICT_AFTER,
    CONFLICT_HOLD_S,
    DRIFT_RATE_TAU_S,
    DRIFT_REFERENCE_S,
    GATE_SIGMAS,
    GNSS_WHITE,
    ekf_height_error,
    ekf_height_m,
    rangefinder_height_m,
    rangefinder_sigma_m,
    share,
    status,
    take_notices,
)
from localizer.height_noise import NOISE_FLOOR_M, WALK_FLOOR
from localizer.pose import camera_pose
from localizer.telemetry import Telemetry

T0 = 1_763_800_000.0
BOOT0_S = 250.0  # the autopilot has been up for 250 s at T0
TRUE_H = 20.0  # the reported position's true height above the water
SURFACE = 12.0  # the water's altitude (m AMSL)
TAKEOFF = 1.5  # the take-off point above the water


def cal(amsl=False, **uncertainty):
    water = {"surface_amsl_m": SURFACE} if amsl else {"takeoff_height_above_surface_m": TAKEOFF}
    return Calibration.from_dict(
        {
            "camera": {
                "width": 1920,
                "height": 1080,
                "fx": 1664.0,
                "fy": 1664.0,
                "cx": 959.5,
                "cy": 539.5,
                "distortion": [0.0, 0.0, 0.0, 0.0, 0.0],
            },
            "mount": {"attitude_source": "fixed", "fixed_rpy_deg": [0.0, -90.0, 0.0]},
            "water": water,
            "uncertainty": uncertainty,
        }
    )


def telemetry(
    duration_s=20.0, ekf_error=lambda tau: 0.0, keep_s=None, rate_hz=10.0, roll=0.0, pitch=0.0
):
    """ATTITUDE and GLOBAL_POSITION_INT from T0 (received the instant they are sampled): the EKF's heights are
    the true ones plus ``ekf_error(tau)`` (both alt and relative_alt, as a barometer's drift)."""
    tel = Telemetry(keep_s=keep_s)
    feed(tel, 0.0, duration_s, ekf_error, rate_hz, roll, pitch)
    return tel


def feed(tel, tau0, tau1, ekf_error=lambda tau: 0.0, rate_hz=10.0, roll=0.0, pitch=0.0):
    for i in range(round(tau0 * rate_hz), int(tau1 * rate_hz) + 1):
        tau = i / rate_hz
        t, ms = T0 + tau, round((BOOT0_S + tau) * 1000)
        err = ekf_error(tau)
        tel.add_attitude(ms, roll, pitch, 0.0, (0.0, 0.0, 0.0), t)
        tel.add_position(
            ms, 47.0, 8.0, SURFACE + TRUE_H + err, TRUE_H - TAKEOFF + err, (0.0, 0.0, 0.0), t
        )


def gps(tel, tau, alt, v_acc=0.0, fix=3, vdop=math.nan):
    """A GPS_RAW_INT at T0 + tau (its time since boot, as ArduPilot stamps it)."""
    t = T0 + tau
    assert tel.add_gps_raw(
        round((BOOT0_S + tau) * 1e6), fix, alt, 0.0, v_acc, math.nan, vdop, math.nan, t
    )


def at(c, tel, tau):
    a = ekf_height_error(c.water, c.sigmas, tel, T0 + np.atleast_1d(tau))
    return a.bias_m, a.sigma_m, a.source


def walk(seconds, c):
    """The variance of the barometer's drift ``seconds`` after its reference, as the model states it: a rate of
    autocovariance σ²·exp(−|u − v|/τ) integrated over [0, T]², σ such that 10 minutes give baro_drift_10min_m."""

    def integral(T):  # ∫∫ exp(−|u − v|/τ) du dv over [0, T]²
        return (
            2.0
            * DRIFT_RATE_TAU_S
            * (T - DRIFT_RATE_TAU_S * (1.0 - math.exp(-T / DRIFT_RATE_TAU_S)))
        )

    return c.sigmas.baro_drift_10min_m**2 * integral(seconds) / integral(DRIFT_REFERENCE_S)


# --- conversions --------------------------------------------------------------------------------------


def test_a_tilted_rangefinder_reads_long():
    """Looking down the body's z axis: the slant range times cos(roll)·cos(pitch) (that axis's down component)."""
    assert rangefinder_height_m(10.0, 0.0, 0.0) == 10.0
    roll, pitch = math.radians(8.0), math.radians(-5.0)
    axis_down = math.cos(roll) * math.cos(pitch)  # R_ned_from_body[2, 2] for Z-Y-X Euler angles
    assert rangefinder_height_m(12.0 / axis_down, roll, pitch) == pytest.approx(12.0, abs=1e-12)
    assert rangefinder_sigma_m(3.0) == pytest.approx(math.hypot(0.05, 0.03))


def test_gnss_sigmas_follow_what_the_receiver_says():
    assert gnss.horizontal_sigma_m(3, 0.9, 1.2) == 0.9  # h_acc given: the receiver's own
    assert gnss.horizontal_sigma_m(3, math.nan, 1.2) == pytest.approx(1.2 * 1.8)  # HDOP × UERE(3D)
    # RTK fixed, HDOP unknown: 1
    assert gnss.horizontal_sigma_m(6, math.nan, math.nan) == pytest.approx(0.012)
    assert gnss.horizontal_sigma_m(4, math.nan, 0.8) == pytest.approx(0.8 * 1.2)
    assert math.isnan(gnss.horizontal_sigma_m(1, math.nan, 0.8))  # no fix
    assert gnss.vertical_sigma_m(3, 2.2, 1.0) == 2.2
    assert gnss.vertical_sigma_m(3, math.nan, math.nan) == pytest.approx(gnss.TYPICAL_VDOP * 1.8)
    assert gnss.vertical_sigma_m(6, math.nan, 1.3) == pytest.approx(1.3 * 0.012)
    assert math.isnan(gnss.vertical_sigma_m(2, 0.5, 1.3))  # a 2D fix has no altitude


def test_the_uavs_horizontal_sigma_in_the_pose_follows_gps_raw_int():
    c, tel = cal(), telemetry(duration_s=3.0)
    times = T0 + np.array([1.0, 2.0])
    # no GPS_RAW_INT: a plain GNSS assumed
    assert np.allclose(camera_pose(c, tel, times).sigma_uav_m, 1.5)
    for k in range(30):  # a DOP-only receiver (h_acc 0): HDOP 0.9 × the 3D fix's 1.8 m
        tel.add_gps_raw(0, 3, SURFACE + TRUE_H, 0.0, 0.0, 0.9, 1.4, math.nan, T0 + k * 0.1)
    assert np.allclose(camera_pose(c, tel, times).sigma_uav_m, 0.9 * 1.8)


# --- the barometer alone ---------------------------------------------------------------------------------


def test_without_measurements_the_sigma_grows_from_the_reference():
    """No GNSS altitude, no rangefinder: height_m when the reference was set (the boot: no arming seen), then the
    drift at a wandering rate, baro_drift_10min_m after 10 minutes; the estimate is the EKF's height itself."""
    c, tel = cal(), telemetry()
    bias, sigma, source = at(c, tel, [0.0, 10.0])
    assert np.all(bias == 0.0) and set(source) == {"takeoff"}
    for tau, s in zip((0.0, 10.0), sigma):
        assert s == pytest.approx(math.sqrt(0.3**2 + walk(BOOT0_S + tau, c)), rel=1e-9)
    # an arming seen in the HEARTBEATs sets the take-off reference again (ArduPilot sets home then)
    tel.add_heartbeat(False, T0 + 1.0)
    tel.add_heartbeat(True, T0 + 2.0)
    _, sigma, _ = at(c, tel, [1.5, 2.0, 12.0])
    assert sigma[0] == pytest.approx(math.sqrt(0.3**2 + walk(BOOT0_S + 1.5, c)), rel=1e-9)
    assert sigma[1] == pytest.approx(0.3, rel=1e-9)
    assert sigma[2] == pytest.approx(math.sqrt(0.3**2 + walk(10.0, c)), rel=1e-9)
    # the amsl reference (the EKF origin's, at boot) does not move at arming; the water level's sigma adds
    ca = cal(amsl=True, surface_amsl_m=0.2)
    _, sigma, source = at(ca, tel, [12.0])
    assert sigma[0] == pytest.approx(
        math.sqrt(0.3**2 + 0.2**2 + walk(BOOT0_S + 12.0, ca)), rel=1e-9
    )
    assert source[0] == "amsl"


# --- GNSS altitudes ----------------------------------------------------------------------------------------


def test_one_rtk_altitude_with_a_known_water_level_is_a_kalman_update():
    """amsl reference: an RTK altitude measures the EKF altitude's error e (z = g − e); the height's error
    b = e + s keeps the water level's own sigma. One update, worked by hand."""
    ca = cal(amsl=True, surface_amsl_m=0.01)
    tel = telemetry(ekf_error=lambda tau: 1.0)  # the barometer reads 1 m high
    gps(tel, 5.0, SURFACE + TRUE_H, v_acc=0.02, fix=6)
    bias, sigma, source = at(ca, tel, 5.0)
    pe = 0.3**2 + walk(BOOT0_S + 5.0, ca)  # the prior of e at that time
    pg, r = (1 - GNSS_WHITE**2) * 0.02**2, (GNSS_WHITE * 0.02) ** 2 + 1e-6
    z = -1.0  # GNSS altitude − EKF altitude
    assert bias[0] == pytest.approx(-z * pe / (pe + pg + r), rel=1e-9)
    assert sigma[0] == pytest.approx(math.sqrt(0.01**2 + pe * (pg + r) / (pe + pg + r)), rel=1e-9)
    assert source[0] == "gnss_rtk"


def test_rtk_follows_the_barometers_drift_to_centimetres():
    ca = cal(amsl=True, surface_amsl_m=0.01)
    tel = telemetry(duration_s=120.0, ekf_error=lambda tau: 0.4 + 0.01 * tau)  # 0.4 → 1.6 m
    for k in range(600):
        gps(tel, k * 0.2, SURFACE + TRUE_H, v_acc=0.025, fix=6)
    tau = np.arange(10.0, 120.0, 1.0)
    bias, sigma, source = at(ca, tel, tau)
    assert np.abs(bias - (0.4 + 0.01 * tau)).max() < 0.02
    assert np.all(sigma < 0.04) and set(source) == {"gnss_rtk"}


def test_take_off_reference_follows_the_gnss_trend_not_its_offset():
    """Without the water's altitude a GNSS altitude gives only the change since the first: a barometer that
    drifts 0.5 m while the GNSS altitude stays is followed; an offset of the GNSS altitude is not."""
    c = cal()
    tel = telemetry(duration_s=300.0, ekf_error=lambda tau: 0.5 * tau / 300.0)
    for k in range(300):
        gps(tel, k * 1.0, SURFACE + TRUE_H + 7.0, v_acc=0.05)  # 7 m off: irrelevant
    bias, sigma, source = at(c, tel, [0.0, 299.0])
    assert bias[0] == pytest.approx(0.0, abs=0.01)
    assert bias[1] == pytest.approx(0.5, abs=0.06)
    assert sigma[1] > 0.3 and set(source) == {
        "baro+gnss"
    }  # the take-off height's own 0.3 m stays unknown


@pytest.mark.parametrize("amsl", [False, True])
def test_a_white_rtk_noise_does_not_move_the_height_and_a_drift_is_followed(amsl):
    """RTK altitudes at 5 Hz with 2 cm of white noise (the receiver claiming v_acc 2 cm) beside a barometer that
    drifts 0.4 m in 2 minutes: the barometer carries the short term (the height moves less than 1 cm from one
    GNSS altitude to the next), the GNSS altitudes its drift (followed to about a centimetre)."""
    c = cal(amsl=amsl, surface_amsl_m=0.01)
    drift = lambda tau: tau / 300.0
    tel = telemetry(duration_s=120.0, ekf_error=drift)
    noise = np.random.default_rng(7).normal(0.0, 0.02, 600)
    for k in range(600):
        gps(tel, k * 0.2 + 0.1, SURFACE + TRUE_H + noise[k], v_acc=0.02, fix=6)
    tau = np.arange(20.0, 120.0, 0.2)  # one answer between each two GNSS altitudes
    bias, sigma, source = at(c, tel, tau)
    err = bias - drift(tau)
    # was 2.1 cm: the height followed each message's noise
    assert np.sqrt(np.mean(np.diff(err) ** 2)) < 0.003
    # was 1.7 cm RMS: worse than one message
    assert np.sqrt(np.mean(err**2)) < 0.01 and np.abs(err).max() < 0.03
    assert np.mean(np.abs(err) <= 2 * sigma) >= 0.95
    assert set(source) == {"gnss_rtk" if amsl else "baro+gnss_rtk"}


def test_a_wandering_barometer_is_followed_by_rtk_altitudes_not_by_a_plain_fix():
    """A barometer that wanders 10 cm back and forth over 20 s (prop wash, gusts) beside GNSS altitudes with 2 cm of
    white noise: RTK altitudes (take-off reference) show the wander, and the height follows it (its changes: the
    level before the wander was seen stays the take-off's), the sigma covering what is left; a plain fix's metres
    cannot see it and barely move the height."""
    c = cal()
    wander = lambda tau: 0.1 * math.sin(2.0 * math.pi * tau / 20.0)
    noise = np.random.default_rng(3).normal(0.0, 0.02, 300)
    tau = np.arange(15.0, 60.0, 0.2)
    truth = np.array([wander(t) for t in tau])
    for fix, v_acc in ((6, 0.02), (3, 4.0)):
        tel = telemetry(duration_s=60.0, ekf_error=wander)
        for k in range(300):
            gps(tel, k * 0.2 + 0.1, SURFACE + TRUE_H + noise[k], v_acc=v_acc, fix=fix)
        bias, sigma, _ = at(c, tel, tau)
        err = bias - truth
        if fix == 6:  # was 6.6 cm (the barometer's own): its 600-s drift cannot follow a wander
            assert np.std(err) < 0.25 * np.std(truth)
            assert np.mean(np.abs(err) <= 2 * sigma) >= 0.95
        else:
            assert np.abs(bias).max() < 0.01


# --- absolute heights and the cross-check --------------------------------------------------------------


def test_one_absolute_height_is_a_kalman_update():
    c, tel = cal(), telemetry()
    # the EKF reads 0.8 m high by this measurement
    assert tel.add_height("size", T0 + 4.0, TRUE_H - 0.8, 0.2)
    bias, sigma, source = at(c, tel, [3.9, 4.0])
    pb = 0.3**2 + walk(BOOT0_S + 4.0, c)
    assert bias[0] == 0.0 and source[0] == "takeoff"  # causal: not before its time
    assert bias[1] == pytest.approx(0.8 * pb / (pb + 0.04), rel=1e-9)
    assert sigma[1] == pytest.approx(math.sqrt(pb * 0.04 / (pb + 0.04)), rel=1e-9)
    assert source[1] == "size"


def test_a_source_that_disagrees_is_not_used_and_widens_the_sigma():
    """A lidar reading the seafloor: 6 sigma off, refused; the third in a row makes it disagree: one line, and
    the sigma covers both; once refused it is taken back only within AGREE_SIGMAS, not as soon as it is inside
    the gate."""
    c = cal(height_m=1.0, baro_drift_10min_m=0.0, baro_wander_m=0.0)  # a barometer that holds
    tel = telemetry(duration_s=60.0)
    for k, off in enumerate((6.0, 6.1, 4.0, 4.1)):  # metres below what the EKF says: 6σ, 6σ, 4σ, 4σ
        assert tel.add_height("rangefinder", T0 + 1.0 + k, TRUE_H + off, 0.01)
    bias, sigma, source = at(c, tel, [4.5, 4.0 + CONFLICT_HOLD_S + 0.5])
    # none used: 4σ is inside the gate, not within 3σ
    assert bias[0] == 0.0 and source[0] == "takeoff"
    assert sigma[0] == pytest.approx(math.hypot(1.0, 4.1 / 2))
    # the disagreement counts until CONFLICT_HOLD_S after its last reading
    assert sigma[1] == pytest.approx(1.0)
    notices = take_notices(tel)
    assert (
        len(notices) == 1
        and "rangefinder gives 24.00" in notices[0]
        and "4.0 sigma apart" in notices[0]
    )
    assert tel.add_height("rangefinder", T0 + 20.0, TRUE_H + 2.0, 0.01)  # 2σ: agrees again, used
    bias, _, source = at(c, tel, 20.0)
    assert bias[0] == pytest.approx(-2.0, abs=1e-3) and source[0] == "rangefinder"
    assert take_notices(tel) == [
        "height: rangefinder agrees with the estimate again (2.0 sigma): used"
    ]
    # a fresh estimator takes the 4σ reading at once
    tel2 = telemetry(duration_s=10.0)
    tel2.add_height("rangefinder", T0 + 1.0, TRUE_H + 4.0, 0.01)
    assert at(c, tel2, 1.0)[0][0] == pytest.approx(-4.0, abs=1e-3)
    assert AGREE_SIGMAS < 4.0 < GATE_SIGMAS and CONFLICT_AFTER == 3


def test_one_glitch_is_refused_quietly():
    c = cal(height_m=1.0, baro_drift_10min_m=0.0, baro_wander_m=0.0)  # a barometer that holds
    tel = telemetry(duration_s=10.0)
    for k, off in enumerate((0.0, 20.0, 0.0)):
        tel.add_height("rangefinder", T0 + 1.0 + k, TRUE_H + off, 0.01)
    bias, sigma, _ = at(c, tel, [2.5, 3.5])
    # not widened; the next one used
    assert sigma[0] < 0.01 and bias[1] == pytest.approx(0.0, abs=1e-6)
    assert take_notices(tel) == []


def test_late_measurements_are_fused_in_time_order():
    """Measurements arriving after later ones (the UUV's size is measured after its frame) give the same
    estimate as if they had come in order: the filter re-runs from just before them."""
    c = cal()

    def feed(tel, order):
        for kind, k in order:
            if kind == "gps":
                gps(tel, k * 0.5, SURFACE + TRUE_H, v_acc=0.3)
            else:
                tel.add_height("size", T0 + k * 0.5 + 0.25, TRUE_H, 0.15)

    in_order = telemetry(ekf_error=lambda tau: 0.6)
    feed(in_order, [(kind, k) for k in range(30) for kind in ("gps", "size")])
    late = telemetry(ekf_error=lambda tau: 0.6)
    feed(late, [("gps", k) for k in range(30)])
    at(c, late, 10.0)  # answered before the size measurements came
    feed(late, [("size", k) for k in range(30)])
    tau = np.arange(0.0, 15.0, 0.25)
    a, b = at(c, in_order, tau), at(c, late, tau)
    assert np.allclose(a[0], b[0], atol=1e-12) and np.allclose(a[1], b[1], atol=1e-12)
    assert list(a[2]) == list(b[2]) and a[0][-1] == pytest.approx(0.6, abs=0.1)


def test_live_history_is_bounded_without_changing_the_answers():
    c = cal()
    full, live = Telemetry(), Telemetry(keep_s=20.0)
    for tel in (full, live):
        for k in range(400):  # 200 s as it comes, live asked at every step
            feed(tel, k * 0.5, k * 0.5 + 0.4)
            gps(tel, k * 0.5 + 0.2, SURFACE + TRUE_H + 0.001 * k, v_acc=0.1)
            at(c, tel, k * 0.5 + 0.3)
    est = live.height_estimator
    assert len(est._entries) < 100 and est._base[0] > T0 + 100
    a, b = at(c, full, [190.3, 199.5]), at(c, live, [190.3, 199.5])
    assert np.allclose(a[0], b[0], atol=1e-9) and np.allclose(a[1], b[1], atol=1e-9)


def test_status_says_what_measured_the_height():
    c, tel = cal(), telemetry()
    tel.add_heartbeat(False, T0)
    tel.add_heartbeat(True, T0 + 1.0)
    tel.add_height("rangefinder", T0 + 5.0, TRUE_H, 0.05)
    for k in range(3):  # the third in a row: it disagrees
        tel.add_height("rangefinder", T0 + 17.0 + k, TRUE_H + 9.0, 0.05)
    s = status(c.water, c.sigmas, tel)
    assert s["reference"] == "takeoff" and s["reference_set_at"] == "arming" and s["armed"] is True
    # covers both: hypot(its own sigma, 9 m / 2), in millimetres (its own, 5 cm 15 s after the lidar, adds < 1 mm)
    assert s["since_reference_s"] == pytest.approx(19.0, abs=0.01) and s["sigma_m"] >= 4.5
    assert at(c, tel, 20.0)[1][0] > 4.5
    assert s["ekf_height_m"] == pytest.approx(TRUE_H) and s["source"] == "rangefinder"
    rf = s["sources"]["rangefinder"]
    assert (rf["used"], rf["refused"]) == (1, 3) and rf["disagrees_m"] == pytest.approx(
        -9.0, abs=0.01
    )


def test_a_copy_of_the_telemetry_goes_its_own_way():
    """The live latency estimate works on a copy of the telemetry: the estimator's copy is cheap but separate."""
    import copy

    c, tel = cal(), telemetry(duration_s=30.0, ekf_error=lambda tau: 0.7)
    for k in range(10):
        tel.add_height("rangefinder", T0 + k, TRUE_H, 0.05)
    before = at(c, tel, [5.0, 25.0])
    twin = copy.deepcopy(tel)
    for k in range(10, 20):  # only the original hears these: 3 m off
        tel.add_height("rangefinder", T0 + k, TRUE_H - 3.0, 0.05)
    gps(tel, 4.5, SURFACE + TRUE_H, v_acc=0.2)  # late, before them all: the original re-runs
    after_twin, after = at(c, twin, [5.0, 25.0]), at(c, tel, [5.0, 25.0])
    assert np.array_equal(after_twin[0], before[0]) and np.array_equal(after_twin[1], before[1])
    assert not np.allclose(after[1], before[1]) and take_notices(twin) == []


def test_a_filter_is_shared_only_with_a_telemetry_that_gives_it_the_same_inputs():
    """The UUVs of one video each have a copy of the UAV's telemetry: the filter one ran is shared with a copy that
    reads the same (the same answers and notices, not run again), never with one that differs in any input."""
    import copy

    c, tel = cal(), telemetry(duration_s=30.0, ekf_error=lambda tau: 0.7)
    tel.height_two_sided = True
    for k in range(10):  # the last ones 3 m off: refused, a notice
        tel.add_height("rangefinder", T0 + k, TRUE_H - (3.0 if k > 5 else 0.0), 0.05)
    gps(tel, 4.5, SURFACE + TRUE_H, v_acc=0.2)
    twins = [copy.deepcopy(tel) for _ in range(6)]
    fresh = [at(c, copy.deepcopy(twin), [5.0, 25.0]) for twin in twins[:1]]
    reference = at(c, tel, [5.0, 25.0])
    notices = take_notices(copy.deepcopy(tel))
    assert notices and not share(tel, tel)  # it has its own
    twins[1].add_height(
        "rangefinder", T0 + 12.0, TRUE_H, 0.05
    )  # one input differs in each of these
    twins[2].add_attitude(round((BOOT0_S + 31.0) * 1000), 0.0, 0.0, 0.0, (0.0, 0.0, 0.0), T0 + 31.0)
    feed(twins[3], 30.1, 30.1)
    twins[4].arm_times.append(T0 + 1.0)
    twins[5].height_two_sided = False
    assert [share(twin, tel) for twin in twins] == [True, False, True, False, False, False]
    assert twins[0].height_estimator is not tel.height_estimator
    assert twins[2].height_estimator is not None  # ATTITUDE is none of the filter's inputs
    shared = at(c, twins[0], [5.0, 25.0])
    for got in (shared, fresh[0]):
        assert all(np.array_equal(a, b) for a, b in zip(got, reference))
    assert take_notices(twins[0]) == notices
    assert twins[1].height_estimator is None and twins[3].height_estimator is None


# --- offline: the whole recording, both ways -------------------------------------------------------------


def test_offline_a_height_uses_the_measurements_after_it_too():
    """One absolute height at 4 s, offline: the height at 3.9 s is the Gaussian conditioning on it worked by hand
    (the EKF height's errors at 3.9 and 4 s share the take-off's 0.3 m and the drift since the boot); at 4 s and
    after, nothing comes later: the filter's answer. Live (the default) it is not used before its time."""
    c, tel = cal(), telemetry()
    assert tel.add_height("size", T0 + 4.0, TRUE_H - 0.8, 0.2)
    live = at(c, tel, [3.9, 4.0, 9.0])
    tel.height_two_sided = True
    bias, sigma, _ = at(c, tel, [3.9, 4.0, 9.0])
    t1, t2 = BOOT0_S + 3.9, BOOT0_S + 4.0
    p1, p2 = 0.3**2 + walk(t1, c), 0.3**2 + walk(t2, c)
    p12 = 0.3**2 + (walk(t1, c) + walk(t2, c) - walk(t2 - t1, c)) / 2.0
    assert live[0][0] == 0.0
    assert bias[0] == pytest.approx(0.8 * p12 / (p2 + 0.04), rel=1e-6)
    assert sigma[0] == pytest.approx(math.sqrt(p1 - p12**2 / (p2 + 0.04)), rel=1e-6)
    assert np.allclose(bias[1:], live[0][1:], atol=1e-12)
    assert np.allclose(sigma[1:], live[1][1:], atol=1e-12)


def test_offline_a_wandering_barometer_is_followed_from_the_first_seconds():
    """The wander of test_a_wandering_barometer... from the first GNSS altitude: live, the height follows the
    barometer until the GNSS altitudes have shown the wander moves (about 4 s); offline every second of it uses the
    altitudes after it too: less than half the error in the first 10 s, still under a centimetre from frame to frame
    and within its 2-sigma. A plain fix's metres move it no more than live; without GNSS altitudes both agree."""
    c = cal()
    wander = lambda tau: 0.1 * math.sin(2.0 * math.pi * tau / 20.0)
    noise = np.random.default_rng(3).normal(0.0, 0.02, 300)
    tau = np.arange(0.0, 60.0, 1.0 / 30.0)
    truth = np.array([wander(t) for t in tau])
    for fix, v_acc in ((6, 0.02), (3, 4.0), (None, None)):
        tel = telemetry(duration_s=60.0, ekf_error=wander)
        for k in range(300 if fix else 0):
            gps(tel, k * 0.2 + 0.1, SURFACE + TRUE_H + noise[k], v_acc=v_acc, fix=fix)
        live = at(c, tel, tau)
        tel.height_two_sided = True
        bias, sigma, _ = at(c, tel, tau)
        err, err_live = bias - truth, live[0] - truth
        if fix == 6:
            early = tau < 10.0
            assert np.std(err[early]) < 0.5 * np.std(err_live[early])  # 3.0 -> 0.9 cm
            assert np.std(err) < np.std(err_live) and np.abs(np.diff(bias)).max() < 0.01
            assert np.mean(np.abs(err - err.mean()) <= 2 * sigma) >= 0.95
        elif fix == 3:
            assert np.abs(bias).max() < 0.01
        else:
            assert np.array_equal(bias, live[0]) and np.allclose(sigma, live[1], rtol=1e-12)


# --- the EKF height's white noise --------------------------------------------------------------------------------


def noisy(height, noise_m, velocity=True, duration_s=40.0, seed=5, rate_hz=10.0):
    """GLOBAL_POSITION_INT at ``rate_hz`` with a known smooth true height ``height(tau)`` (m above the water), its
    vertical velocity (``velocity``: True its derivative, else a function of tau or None) and ``noise_m`` of white
    noise on both heights."""
    tel = Telemetry()
    tau = np.arange(0.0, duration_s, 1.0 / rate_hz)
    white = np.random.default_rng(seed).normal(0.0, noise_m, len(tau))
    for k, tk in enumerate(tau):
        t, ms = T0 + tk, round((BOOT0_S + tk) * 1000)
        h = height(tk)
        climb = (height(tk + 1e-4) - height(tk - 1e-4)) / 2e-4 if velocity is True else None
        climb = velocity(tk) if callable(velocity) else climb
        tel.add_attitude(ms, 0.0, 0.0, 0.0, (0.0, 0.0, 0.0), t)
        v = None if climb is None else (0.0, 0.0, -climb)
        tel.add_position(ms, 47.0, 8.0, SURFACE + h + white[k], h - TAKEOFF + white[k], v, t)
    return tel


def heights(c, tel, tau):
    """The estimated height above the water (the EKF's − its estimated error) at T0 + ``tau``, and its 1-sigma."""
    t = T0 + tau
    a = ekf_height_error(c.water, c.sigmas, tel, t)
    return ekf_height_m(c.water, tel, t) - a.bias_m, a.sigma_m


@pytest.mark.parametrize("two_sided", [False, True])
def test_the_ekf_heights_white_noise_is_not_passed_through(two_sided):
    """3 cm of white noise on every GLOBAL_POSITION_INT height of a drone climbing and descending 3 m (up to 0.9 m/s):
    with the EKF's vertical velocity the height follows the climb without lag, its noise taken out. The local-level
    filter's steady state with the walk at its floor (q = WALK_FLOOR·R) moves the level by P⁻/√(P⁻ + R) ≈ 0.1·√R
    per message (P⁻ = (q + √(q² + 4qR))/2): from frame to frame (30 Hz) at most that (times 2 for the
    measured R and q); passed through, the steps would be 1.4 cm. Its error stays within its 2-sigma."""
    c, R = cal(height_m=0.1), 0.03**2
    climb = lambda tau: TRUE_H + 3.0 * math.sin(2.0 * math.pi * tau / 20.0)
    tel = noisy(climb, 0.03)
    tel.height_two_sided = two_sided
    tau = np.arange(5.0, 39.0, 1.0 / 30.0)  # after 5 s: R and q measured
    h, sigma = heights(c, tel, tau)
    err = h - np.array([climb(t) for t in tau])
    q = WALK_FLOOR * R
    P = (q + math.sqrt(q * q + 4.0 * q * R)) / 2.0
    assert np.sqrt(np.mean(np.diff(err) ** 2)) < 2.0 * P / math.sqrt(P + R)  # 0.6 cm
    assert np.sqrt(np.mean(err**2)) < math.sqrt(P)  # the level's predicted sigma: 1 cm
    # no lag: as much above as below over the climbs and the descents
    assert abs(np.mean(err)) < 0.005
    assert np.mean(np.abs(err) <= 2.0 * sigma) >= 0.95


def test_without_a_vertical_velocity_a_climb_is_not_lagged():
    """No velocity in GLOBAL_POSITION_INT: the climb shows as motion, not noise; the heights are not smoothed over
    (their error is the white noise, about the climb's mean 0), and a steady hover's noise is still taken out."""
    c = cal(height_m=0.1)
    tau = np.arange(5.0, 39.0, 1.0 / 30.0)
    climb = lambda t: TRUE_H + 3.0 * math.sin(2.0 * math.pi * t / 20.0)
    h, _ = heights(c, noisy(climb, 0.03, velocity=None), tau)
    err = h - np.array([climb(t) for t in tau])
    assert np.sqrt(np.mean(err**2)) < 0.04 and abs(np.mean(err)) < 0.005
    h, _ = heights(c, noisy(lambda t: TRUE_H, 0.03, velocity=None), tau)
    assert np.sqrt(np.mean(np.diff(h) ** 2)) < 0.005


def test_an_ekf_height_that_steps_is_followed_at_once():
    """The EKF's height jumps 0.5 m (a reset, home set again) with no velocity to say so: the height steps with it at
    its message, not over seconds; the noise is taken out before and after."""
    c = cal(height_m=0.1)
    step = lambda t: TRUE_H + (0.5 if t >= 20.0 else 0.0)
    tel = noisy(step, 0.03, velocity=lambda t: 0.0)
    tau = np.arange(5.0, 39.0, 1.0 / 30.0)
    h, _ = heights(c, tel, tau)
    err = h - np.array([step(t) for t in tau])
    settled = (tau <= 19.9) | (
        tau >= 20.0
    )  # between the messages before and at the step: the EKF's own
    assert np.abs(err[settled]).max() < 0.06 and np.sqrt(np.mean(err[settled] ** 2)) < 0.02


def test_millimetres_of_noise_are_left_as_they_are():
    """An EKF height with 1 mm of noise (its messages' own millimetres) is used as it comes, to the bit (the
    sessions without noise keep their positions.csv); 3 cm of it is taken out."""
    c, tau = cal(height_m=0.1), np.arange(5.0, 39.0, 1.0 / 30.0)
    for noise_m in (0.001, 0.03):
        a = ekf_height_error(c.water, c.sigmas, noisy(lambda t: TRUE_H, noise_m), T0 + tau)
        assert np.all(a.bias_m == 0.0) == (noise_m < NOISE_FLOOR_M)

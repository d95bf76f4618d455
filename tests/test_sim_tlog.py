"""The generated uav.tlog: real MAVLink 2 that pymavlink parses, at the stated rates, telling the truth."""

import struct

import numpy as np
import pytest

from groundstation.mavlink.ingest import mavutil
from localizer.attitude import euler_to_R, quat_to_R
from sim_fixtures.bundle import BUNDLED, BUNDLED_DIR, SCENARIOS
from sim_fixtures.motion import Motion
from sim_fixtures.scenario import load_scenario
from sim_fixtures.tlog import Clock

RATES = {
    "ATTITUDE": 50.0,
    "GLOBAL_POSITION_INT": 10.0,
    "SYSTEM_TIME": 1.0,
    "HEARTBEAT": 1.0,
    "GPS_RAW_INT": 5.0,
    "TIMESYNC": 1.0,
}
GIMBAL = {
    "gimbal_device": "GIMBAL_DEVICE_ATTITUDE_STATUS",
    "mount_orientation": "MOUNT_ORIENTATION",
}


def read_records(path):
    """(record time µs, raw frame) pairs split by hand from the tlog bytes."""
    data = path.read_bytes()
    out, i = [], 0
    while i < len(data):
        (t_us,) = struct.unpack(">Q", data[i : i + 8])
        assert data[i + 8] == 0xFD, "MAVLink 2 start byte"
        length = data[i + 9]
        size = 10 + length + 2 + (13 if data[i + 10] & 1 else 0)
        out.append((t_us, data[i + 8 : i + 8 + size]))
        i += 8 + size
    return out


@pytest.fixture(scope="module", params=BUNDLED)
def tlog(request):
    sc = load_scenario(SCENARIOS / f"{request.param}.toml")
    conn = mavutil().mavlink_connection(
        str(BUNDLED_DIR / sc.name / "uav.tlog"), dialect="ardupilotmega"
    )
    msgs = []
    while (m := conn.recv_msg()) is not None:
        msgs.append(m)
    conn.close()
    return sc, msgs


def test_every_record_parses_and_times_are_receive_times(tlog):
    sc, msgs = tlog
    records = read_records(BUNDLED_DIR / sc.name / "uav.tlog")
    assert len(records) == len(msgs) and not any(m.get_type() == "BAD_DATA" for m in msgs)
    t_rec = np.array([r[0] for r in records])
    assert np.all(np.diff(t_rec) >= 0)
    assert np.allclose([m._timestamp for m in msgs], t_rec / 1e6, atol=1e-6, rtol=0)
    clock = Clock.of(sc)
    timed = [(m._timestamp, m.time_boot_ms) for m in msgs if hasattr(m, "time_boot_ms")]
    station = sc.clock.station_offset_s  # record times are on the station's clock
    delay = np.array([t - (clock.boot_epoch_us + ms * 1000) / 1e6 - station for t, ms in timed])
    assert (
        delay.min() >= sc.link.delay_s and np.median(delay) < sc.link.delay_s + 5 * sc.link.jitter_s
    )
    assert np.std(delay) > 0.2 * sc.link.jitter_s  # there is jitter


def test_rates(tlog):
    sc, msgs = tlog
    span = sc.telemetry.lead_s + sc.duration_s + 1.0
    rates = dict(RATES)
    if sc.mount.attitude_source in GIMBAL:
        rates[GIMBAL[sc.mount.attitude_source]] = 20.0
    kinds = {m.get_type() for m in msgs}
    assert kinds == set(rates)
    for kind, hz in rates.items():
        of_kind = [m for m in msgs if m.get_type() == kind]
        n = len(of_kind)
        boot = np.array([m.time_boot_ms for m in of_kind if hasattr(m, "time_boot_ms")])
        assert abs(n / span - hz) <= 0.1 * hz + 1.0 / span, (kind, n)
        if len(boot) > 1:
            assert np.all(np.diff(boot) > 0)
            assert abs(np.median(np.diff(boot)) - 1000 / hz) <= 0.15 * 1000 / hz


def test_system_time_matches_boot_clock(tlog):
    sc, msgs = tlog
    clock = Clock.of(sc)
    for m in msgs:
        if m.get_type() == "SYSTEM_TIME":
            assert m.time_unix_usec == clock.boot_epoch_us + 1000 * m.time_boot_ms


def test_values_are_the_true_state_at_time_boot_ms(tlog):
    sc, msgs = tlog
    motion, clock = Motion(sc), Clock.of(sc)
    att = [m for m in msgs if m.get_type() == "ATTITUDE"]
    tau = clock.tau_s([m.time_boot_ms for m in att])
    R_true = motion.uav_rpy(tau)
    R_true = euler_to_R(R_true[:, 0], R_true[:, 1], R_true[:, 2])
    R_msg = euler_to_R(*np.array([[m.roll, m.pitch, m.yaw] for m in att]).T)
    assert np.abs(R_msg - R_true).max() < 1e-6  # float32
    # rates: the body's angular velocity, R(t)ᵀ·dR/dt, by finite differences of the true attitude
    h = 1e-4
    rpy0, rpy1 = motion.uav_rpy(tau - h), motion.uav_rpy(tau + h)
    dR = (euler_to_R(*rpy1.T) - euler_to_R(*rpy0.T)) / (2 * h)
    W = np.einsum("nji,njk->nik", R_true, dR)  # skew-symmetric [ω]×
    pqr = np.array([[m.rollspeed, m.pitchspeed, m.yawspeed] for m in att])
    assert np.abs(pqr - np.column_stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]])).max() < 1e-6
    kind = GIMBAL.get(sc.mount.attitude_source)
    if kind is None:
        return
    gim = [m for m in msgs if m.get_type() == kind]
    tau = clock.tau_s([m.time_boot_ms for m in gim])
    yaw_uav = motion.uav_rpy(tau)[:, 2]
    if kind == "MOUNT_ORIENTATION":
        rpy = np.radians([[m.roll, m.pitch, m.yaw] for m in gim])
        R_msg = euler_to_R(rpy[:, 0], rpy[:, 1], rpy[:, 2] + yaw_uav)
    else:
        R_q = quat_to_R(np.array([m.q for m in gim]))
        earth = {m.flags & 96 for m in gim}
        assert earth == {64 if sc.mount.gimbal_frame == "earth" else 32}
        R_msg = R_q if sc.mount.gimbal_frame == "earth" else euler_to_R(0.0, 0.0, yaw_uav) @ R_q
    assert np.abs(R_msg - motion.R_ned_from_gimbal(tau)).max() < 1e-5

"""ArduSub in the loop: ``skyfix sim`` → ``skyfix replay`` → ``skyfix run`` → GPS_INPUT → ArduPilot's real
ArduSub firmware (SITL), watched from another of its serial ports.

The binary is ``$SKYFIX_ARDUSUB``, else ``../shared/tools/ardusub/ardusub`` next to the project; without
either the test is skipped. ArduPilot's ``sub.parm`` must lie next to the binary
(``deploy/build_ardusub.sh`` builds both). Timeline, all waits on conditions:

1. ``skyfix sim`` renders a small scenario (320×180, :data:`DURATION_S` s, the UUV hidden during
   :data:`OCCLUSION_S`) while ArduSub boots in a scratch directory (``-I N`` with free ports); both are started
   while the test before runs (``tests/ahead.py``), the render on otherwise idle CPU.
2. An observer (the test, a GCS on SERIAL0) requests GPS_RAW_INT at 20 Hz and GLOBAL_POSITION_INT and
   EKF_STATUS_REPORT at 10 Hz. ArduSub forwards the GPS_INPUT it gets from SERIAL1 to the observer
   (broadcast routing), so one clock stamps what the autopilot received and what it reported.
3. Once the session exists and ArduSub has been up :data:`WARMUP_S` s (a freshly booted EKF3 learns its
   gyro biases before it uses a GPS), ``skyfix run --gps-input tcp:127.0.0.1:SERIAL1`` and then
   ``skyfix replay`` of the session start.

Checked: GPS_RAW_INT mirrors the fixes (3D, lat/lon as sent); EKF3 takes them as its absolute horizontal
position before the occlusion; GLOBAL_POSITION_INT follows them (:data:`GPI_MEDIAN_M`, :data:`GPI_MAX_M`);
the tracker loss is a no-fix in GPS_RAW_INT within 0.5 s of skyfix sending fix_type 1; the fix comes back
when the UUV does. The figures (alignment time, latencies, distances, durations) are printed.
"""

from __future__ import annotations

import csv
import itertools
import math
import socket
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
from ardusub_sitl import ArduSub, Prepared, ardusub_files, render_and_boot
from live_helpers import free_port, replay_shift, skyfix, start, stop, wait_for
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

pytestmark = pytest.mark.sitl

LAT, LON, SURFACE_AMSL_M = 63.4400, 10.4000, 0.40  # the scenario's [site]; ArduSub's --home
DURATION_S = 42.0
OCCLUSION_S = (30.0, 33.0)  # the UUV is hidden (session seconds from the first frame)
# ArduSub's uptime before the replay starts (its README: start it ~30 s before the fixes)
WARMUP_S = 30.0
NO_FIX_MAX_S = 0.5  # issue 11: GPS_RAW_INT shows the loss within 0.5 s of skyfix sending fix_type 1
# GLOBAL_POSITION_INT against the last fix ArduSub received, from 2 s after EKF3 took the GPS to the loss.
# The simulated sub sits still, so its IMU contradicts every move of the (moving, ≤ 0.35 m/s) UUV's fixes:
# EKF3 then trails them, weighing each by max(EK3_POSNE_M_NSE = 0.5 m, h_acc). Half a metre (that noise
# setting) bounds the median; a metre the worst sample. Field numbers need a moving vehicle.
GPI_SETTLE_S = 2.0
GPI_MEDIAN_M = 0.5
GPI_MAX_M = 1.0

EKF_POS_HORIZ_ABS = 16
FIX_3D = 3

SCENARIO = f"""
name = "sitl_ardusub"
description = "Like occlusion.toml, longer and small: the UUV hidden from {OCCLUSION_S[0]} s to {OCCLUSION_S[1]} s"
seed = 16
duration_s = {DURATION_S}
occlusions = [[{OCCLUSION_S[0]}, {OCCLUSION_S[1]}]]

[site]
lat_deg = {LAT}
lon_deg = {LON}
surface_amsl_m = {SURFACE_AMSL_M}

[camera]
width = 320
height = 180

[mount]
attitude_source = "gimbal_device"
gimbal_frame = "earth"
pitch_deg = -80.0
yaw_deg = 200.0

[uav]
height_m = 9.0
yaw_deg = 190.0

[uuv]
depth_m = 1.3

[render]
crf = 28
glint = 0.6
sun_azimuth_deg = 200.0
sun_elevation_deg = 62.0
"""


def distance_m(lat1, lon1, lat2, lon2):
    """Horizontal distance (m) between degE7 positions a few metres apart (equirectangular)."""
    r = 6_371_000.0
    dn = np.radians((np.asarray(lat1) - np.asarray(lat2)) * 1e-7) * r
    de = np.radians((np.asarray(lon1) - np.asarray(lon2)) * 1e-7) * r * math.cos(math.radians(LAT))
    return np.hypot(dn, de)


def first(items, pred):
    return next((x for x in items if pred(x)), None)


def latest_before(items, t):
    """The last ``(t_i, m)`` of a time-ordered list with ``t_i <= t``."""
    out = None
    for ti, m in items:
        if ti > t:
            break
        out = (ti, m)
    return out


def prepare(tmp: Path, background: bool) -> Prepared:
    binary, sub_parm = ardusub_files()
    sitl = ArduSub(binary, sub_parm, tmp / "ardusub", home=(LAT, LON, SURFACE_AMSL_M, 0.0))
    return render_and_boot(tmp, {"session": SCENARIO}, sitl, background)


@pytest.mark.ahead.with_args(prepare)
def test_ardusub_sitl_takes_skyfix_gps_input(prepared):
    tmp_path, sitl = prepared.dir, prepared.boot.sitl
    binary = sitl.binary
    t_test = time.time()
    session = tmp_path / "session"
    procs: list[subprocess.Popen] = []
    mav, video = free_port(), free_port()
    zenoh_ep = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    try:
        prepared.boot.ready()
        obs = sitl.observer
        for msg_id, hz in (
            (mavlink2.MAVLINK_MSG_ID_GPS_RAW_INT, 20.0),
            (mavlink2.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 10.0),
            (mavlink2.MAVLINK_MSG_ID_EKF_STATUS_REPORT, 10.0),
        ):
            obs.request_interval(msg_id, hz)
        prepared.renders["session"].wait(600)
        t_ready = time.time()
        gen_s = t_ready - prepared.t_start
        wait_for(
            lambda: sitl.boot_s() >= WARMUP_S or not sitl.alive(), 180, f"ArduSub up {WARMUP_S:g} s"
        )
        assert sitl.alive(), sitl.tail()
        boot_at_replay = sitl.boot_s()

        run_cmd = skyfix(
            "run",
            "--calibration",
            str(session / "session.toml"),
            "--mavlink",
            f"udpin:127.0.0.1:{mav}",
            "--video",
            f"udp://127.0.0.1:{video}",
            "--video-latency-ms",
            "55",
            "--zenoh-listen",
            zenoh_ep,
            "--gps-input",
            f"tcp:127.0.0.1:{sitl.ports['serial1']}",
            "--duration-s",
            str(DURATION_S + 240),
        )
        run = start(run_cmd, tmp_path / "run.log")
        procs.append(run)
        wait_for(
            lambda: len(obs.of("GPS_INPUT")) >= 5 or run.poll() is not None,
            60,
            "skyfix's GPS_INPUT reaching ArduSub (forwarded to the observer)",
        )
        assert run.poll() is None, (tmp_path / "run.log").read_text()[-3000:]
        replay = start(
            skyfix(
                "replay",
                str(session),
                "--mavlink-out",
                f"udpout:127.0.0.1:{mav}",
                "--video-out",
                f"udp://127.0.0.1:{video}",
                "--zenoh-connect",
                zenoh_ep,
                "--uuv-listen",
                "",
                "--tail-s",
                "2",
            ),
            tmp_path / "replay.log",
        )
        procs.append(replay)
        replay.wait(DURATION_S + 120)
        t_end = time.time()
        stop(run)
        assert sitl.alive(), sitl.tail()
    finally:
        for p in procs:
            stop(p, 5.0)
        sitl.stop()
    logs = {name: (tmp_path / f"{name}.log").read_text()[-3000:] for name in ("run", "replay")}
    assert replay.returncode == 0, logs["replay"]
    assert run.returncode == 0, logs["run"]

    shift = replay_shift(tmp_path / "replay.log")
    with open(session / "video_frames.csv") as f:
        t_frame0 = float(next(csv.DictReader(f))["t"])
    occ0, occ1 = (shift + t_frame0 + s for s in OCCLUSION_S)

    texts = [(t, m.text) for t, m in obs.of("STATUSTEXT")]
    gin = [(t, m) for t, m in obs.of("GPS_INPUT") if t <= t_end]
    raw = obs.of("GPS_RAW_INT")
    gpi = obs.of("GLOBAL_POSITION_INT")
    ekf = obs.of("EKF_STATUS_REPORT")
    why = f"\nrun.log:\n{logs['run']}\nArduSub:\n{sitl.tail()}\nSTATUSTEXT: {[s for _, s in texts]}"
    assert any("GPS 1: detected MAV" in s for _, s in texts), why
    assert {(m.get_srcSystem(), m.get_srcComponent()) for _, m in gin} == {(245, 220)}
    gin3 = [(t, m) for t, m in gin if m.fix_type == FIX_3D]
    assert len(gin3) > 100, f"{len(gin3)} 3D fixes sent{why}"
    t_first_fix = gin3[0][0]

    # EKF3 aligns on the fixes: absolute horizontal position (and says so), before the occlusion
    aligned = first(ekf, lambda x: x[0] > t_first_fix and x[1].flags & EKF_POS_HORIZ_ABS)
    assert aligned is not None, f"EKF3 never reported EKF_POS_HORIZ_ABS{why}"
    t_aligned = aligned[0]
    using = first(texts, lambda x: "EKF3 IMU0 is using GPS" in x[1])
    assert using is not None, why
    assert t_aligned < occ0, (
        f"EKF3 aligned {t_aligned - occ0:.1f} s after the occlusion began "
        f"(first fix {t_first_fix - occ0:.1f} s){why}"
    )

    # GPS_RAW_INT mirrors the fixes: every 3D report is a GPS_INPUT of the last second, to 1e-7°
    raw3 = [(t, m) for t, m in raw if t > t_first_fix and m.fix_type == FIX_3D]
    assert len(raw3) > 100
    mismatched, exact_latest = [], 0
    for t, m in raw3:
        recent = [g for tg, g in gin3 if t - 1.0 <= tg <= t]
        if not any(abs(g.lat - m.lat) <= 1 and abs(g.lon - m.lon) <= 1 for g in recent):
            mismatched.append((round(t - t_first_fix, 2), m.lat, m.lon))
        exact_latest += bool(recent) and (recent[-1].lat, recent[-1].lon) == (m.lat, m.lon)
    assert not mismatched, f"GPS_RAW_INT 3D fixes not among the GPS_INPUT sent: {mismatched[:5]}"
    assert all(m.satellites_visible >= 6 for _, m in raw3)

    # the tracker loss: the first switch from 3D to no-fix skyfix sent around the occlusion
    loss = None
    for (_, a), (t1, b) in itertools.pairwise(gin):
        if a.fix_type == FIX_3D and b.fix_type == 1 and occ0 - 0.5 <= t1 <= occ1:
            loss = (t1, b)
            break
    assert loss is not None, f"no 3D → no-fix switch in GPS_INPUT during the occlusion{why}"
    t_loss_fwd, loss_msg = loss
    # when skyfix sent it: its arrival at the observer (through ArduSub), or earlier when the no-fix message's
    # time_usec says so (skyfix stamps a no-fix with its send time): the earlier, the stricter the latency
    t_stamp = loss_msg.time_usec / 1e6
    t_loss_sent = min(t_loss_fwd, t_stamp) if 0.0 <= t_loss_fwd - t_stamp <= 1.0 else t_loss_fwd
    no_fix = first(raw, lambda x: x[0] > t_loss_sent and x[1].fix_type < FIX_3D)
    assert no_fix is not None, f"GPS_RAW_INT never left 3D after the loss{why}"
    no_fix_s = no_fix[0] - t_loss_sent

    # recovery: the first 3D fix skyfix sent after the loss, mirrored by GPS_RAW_INT
    resume = first(gin3, lambda x: x[0] > t_loss_fwd)
    assert resume is not None, f"skyfix never sent a 3D fix after the occlusion{why}"
    t_resume = resume[0]
    held = [
        round(t - t_loss_sent, 2)
        for t, m in raw
        if no_fix[0] <= t < t_resume and m.fix_type == FIX_3D
    ]
    assert not held, f"GPS_RAW_INT showed a 3D fix during the loss at {held[:5]} s"
    recovered = first(raw, lambda x: x[0] > t_resume and x[1].fix_type == FIX_3D)
    assert recovered is not None, f"GPS_RAW_INT never showed a 3D fix again{why}"
    recovery_s = recovered[0] - t_resume
    ekf_during_loss = [m.flags & EKF_POS_HORIZ_ABS for t, m in ekf if t_loss_sent <= t <= t_resume]

    # GLOBAL_POSITION_INT follows the fixes, from shortly after alignment to the loss, while skyfix sends fixes
    d = []
    for t, m in gpi:
        if (
            t_aligned + GPI_SETTLE_S <= t < t_loss_sent
            and latest_before(gin, t)[1].fix_type == FIX_3D
        ):
            ref = latest_before(gin3, t)
            d.append(float(distance_m(m.lat, m.lon, ref[1].lat, ref[1].lon)))
    d = np.array(d)
    assert len(d) >= 30, f"{len(d)} GLOBAL_POSITION_INT samples between alignment and the loss"

    print(f"\nArduSub SITL: {binary}, instance ports {sitl.ports}")
    print(
        f"session ready {gen_s:.1f} s after its render began ({DURATION_S:g} s, 320x180), {t_ready - t_test:.1f} s "
        f"into the test; replay started at ArduSub uptime {boot_at_replay:.1f} s; test {time.time() - t_test:.1f} s in all"
    )
    print(
        f"EKF3 alignment: EKF_POS_HORIZ_ABS {t_aligned - t_first_fix:.2f} s after the first 3D GPS_INPUT "
        f"('is using GPS' at {using[0] - t_first_fix:.2f} s), {occ0 - t_aligned:.1f} s before the occlusion"
    )
    print(
        f"GPS_RAW_INT mirror: {len(raw3)} 3D reports, all equal to a GPS_INPUT of the last second "
        f"({exact_latest / len(raw3):.1%} to the latest one); {len(gin3)} 3D GPS_INPUT of {len(gin)}"
    )
    print(
        f"GLOBAL_POSITION_INT vs last fix: {len(d)} samples, median {np.median(d):.3f} m, "
        f"p95 {np.percentile(d, 95):.3f} m, max {d.max():.3f} m"
    )
    print(
        f"no-fix: GPS_RAW_INT fix_type {no_fix[1].fix_type} {no_fix_s * 1000:.0f} ms after skyfix sent fix_type 1 "
        f"(forwarded copy {(no_fix[0] - t_loss_fwd) * 1000:.0f} ms; loss {t_loss_fwd - occ0:+.2f} s from the "
        f"occlusion); EKF_POS_HORIZ_ABS kept through the {t_resume - t_loss_sent:.1f} s loss: "
        f"{all(ekf_during_loss)}"
    )
    print(
        f"recovery: GPS_RAW_INT 3D {recovery_s * 1000:.0f} ms after the first 3D GPS_INPUT "
        f"({t_resume - occ1:+.2f} s from the occlusion's end)"
    )

    assert no_fix_s <= NO_FIX_MAX_S, (
        f"GPS_RAW_INT no-fix {no_fix_s:.3f} s after skyfix sent fix_type 1"
    )
    assert np.median(d) <= GPI_MEDIAN_M and d.max() <= GPI_MAX_M, (
        f"GLOBAL_POSITION_INT vs fixes: median {np.median(d):.3f} m, max {d.max():.3f} m"
    )
    assert (recovered[1].lat, recovered[1].lon) in {
        (g.lat, g.lon) for tg, g in gin3 if tg <= recovered[0]
    }

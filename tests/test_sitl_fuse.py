"""Two drones over one UUV, live: two ``skyfix run`` services → ``skyfix fuse`` → GPS_INPUT → ArduSub's SITL.

``skyfix sim`` renders the same dive (same seed, same UUV, same clocks) seen by two drones at once (320×180 at
15 fps: two services, two replays and ArduSub share this machine's two cores): drone a at
9 m with its camera 80° down, drone b at 13 m looking 60° down from another side. Two ``skyfix replay`` stream them
in step (one ``--shift-s``), re-encoded as cameras send them (no B-frames) and sent
:data:`CAMERA_LATENCY_MS` after exposure, drone b's video cut for :data:`CUT_S` seconds; drone a's replay publishes the UUV's
depth, which both services read. The services publish their fixes on ``skyfix/uuv/rov1/drone/{a,b}/fix`` and send
no GPS_INPUT; the fuser subscribes to both through a Zenoh router and alone sends GPS_INPUT to ArduSub (SERIAL1),
which forwards it to the test's observer on SERIAL0.

Checked: the fused fixes' error against the truth is below the better drone's over the time both were fused; every
GPS_INPUT comes from the fuser; through drone b's cut GPS_INPUT stays 3D and healthy by ArduPilot's rule
(AP_GPS: no two gaps over 245 ms in a row, mean gap under 215 ms) and GPS_RAW_INT stays 3D; the fuser uses a
alone during the cut and b again after it; a late joiner gets the fused fix from the fuser's queryable.
"""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import zenoh
from ardusub_sitl import ArduSub, Prepared, ardusub_files, render_and_boot
from live_helpers import (
    SUBSCRIBER,
    as_camera_sends_it,
    free_port,
    read_jsonl,
    skyfix,
    start,
    stop,
    truth_errors_m,
    wait_for,
)
from pymavlink.dialects.v20 import ardupilotmega as mavlink2
from test_fusion import DRONE_SCENARIO, DRONES
from test_zenoh_security import ROUTER

from groundstation.testing.ardupilot import ardupilot_gps_unhealthy

pytestmark = pytest.mark.sitl

LAT, LON, SURFACE_AMSL_M = 63.4400, 10.4000, 0.40
# the scenarios' first frame (their default start_unix), station clock = true time
START_UNIX = 1763800000.0
DURATION_S = 36.0
CUT_S = (14.0, 10.0)  # drone b's video is cut from 14 s after its session's start, for 10 s
LEAD_S = 2.0  # the sessions' telemetry starts this long before their first frame (the scenarios' default lead_s)
# glass to first packet of the replayed cameras, configured as such in the services
CAMERA_LATENCY_MS = 55
WARMUP_S = 30.0  # ArduSub's uptime before the fixes (its README)
FIX_3D = 3
# the scenario of tests/test_fusion.py, smaller and slower (two services, two replays and ArduSub share this
# machine's two cores), longer, at ArduSub's home
SCENARIO_EXTRA = (
    f"duration_s = {DURATION_S}\nfps = 15.0\nstart_unix = {START_UNIX}\n"
    f"site = {{ lat_deg = {LAT}, lon_deg = {LON}, surface_amsl_m = {SURFACE_AMSL_M} }}\n"
    "camera = { width = 320, height = 180 }\nrender = { crf = 28 }\n"
)


def scenario(name: str, height: float, yaw: float, pitch: float, gimbal_yaw: float) -> str:
    text = DRONE_SCENARIO.format(
        name=name, height=height, yaw=yaw, pitch=pitch, gimbal_yaw=gimbal_yaw
    )
    assert "duration_s = 20.0\n" in text
    return text.replace("duration_s = 20.0\n", SCENARIO_EXTRA)


ROUTER_CONFIG = """{{ mode: "router", listen: {{ endpoints: ["tcp/127.0.0.1:{port}"] }},
  scouting: {{ multicast: {{ enabled: false }} }} }}"""


def prepare(tmp: Path, background: bool) -> Prepared:
    binary, sub_parm = ardusub_files()
    sitl = ArduSub(binary, sub_parm, tmp / "ardusub", home=(LAT, LON, SURFACE_AMSL_M, 0.0))
    scenarios = {f"session_{d}": scenario(d, *view) for d, view in DRONES.items()}
    return render_and_boot(tmp, scenarios, sitl, background)


@pytest.mark.ahead.with_args(prepare)
def test_two_drones_fused_into_one_gps_input_through_a_cut(prepared):
    tmp_path, sitl = prepared.dir, prepared.boot.sitl
    sessions = {d: tmp_path / f"session_{d}" for d in DRONES}
    procs: list[subprocess.Popen] = []
    port = free_port(socket.SOCK_STREAM)
    ep = f"tcp/127.0.0.1:{port}"
    (tmp_path / "router.json5").write_text(ROUTER_CONFIG.format(port=port))
    zlog = tmp_path / "zenoh.jsonl"
    late = None
    try:
        router = subprocess.Popen(
            [sys.executable, "-c", ROUTER, str(tmp_path / "router.json5")],
            stdout=subprocess.PIPE,
            text=True,
        )
        procs.append(router)
        assert router.stdout.readline().strip() == "ready"
        prepared.boot.ready()
        obs = sitl.observer
        for msg_id, hz in (
            (mavlink2.MAVLINK_MSG_ID_GPS_RAW_INT, 20.0),
            (mavlink2.MAVLINK_MSG_ID_EKF_STATUS_REPORT, 5.0),
        ):
            obs.request_interval(msg_id, hz)
        procs.append(
            start(
                [sys.executable, "-c", SUBSCRIBER, ep, "skyfix/uuv/rov1/**", str(zlog)],
                tmp_path / "sub.log",
            )
        )
        fuser = start(
            skyfix(
                "fuse",
                "--uuv",
                "rov1",
                "--source",
                "a",
                "--source",
                "b",
                "--zenoh-connect",
                ep,
                "--gps-input",
                f"tcp:127.0.0.1:{sitl.ports['serial1']}",
                "--stats",
                str(tmp_path / "fuse.json"),
                "--duration-s",
                "600",
            ),
            tmp_path / "fuse.log",
        )
        procs.append(fuser)
        for d in DRONES:
            as_camera_sends_it(prepared.renders[f"session_{d}"].wait(600) / "video.mp4")
        truth = {d: (sessions[d] / "truth.csv").read_text() for d in DRONES}
        assert truth["a"] == truth["b"], "the two drones must see the same dive"
        ports = {d: (free_port(), free_port()) for d in DRONES}
        services = {}
        for d, (mav, video) in ports.items():
            services[d] = start(
                skyfix(
                    "run",
                    "--calibration",
                    str(sessions[d] / "session.toml"),
                    "--mavlink",
                    f"udpin:127.0.0.1:{mav}",
                    "--video",
                    f"udp://127.0.0.1:{video}",
                    "--video-latency-ms",
                    str(CAMERA_LATENCY_MS),
                    "--zenoh-connect",
                    ep,
                    "--fix-key",
                    f"skyfix/uuv/rov1/drone/{d}/fix",
                    "--status-key",
                    f"skyfix/drone/{d}/status",
                    "--alive-key",
                    f"skyfix/drone/{d}/alive",
                    "--control-prefix",
                    f"skyfix/drone/{d}/cmd",
                    "--no-ui",
                    "--height-from-size",
                    "off",
                    "--gps-input",
                    "none",
                    "--duration-s",
                    "600",
                ),
                tmp_path / f"run_{d}.log",
            )
            procs.append(services[d])
        for d, s in services.items():
            wait_for(
                lambda s=s, d=d: (
                    "skyfix run: UAV" in (tmp_path / f"run_{d}.log").read_text()
                    or s.poll() is not None
                ),
                60,
                f"drone {d}'s service",
            )
            assert s.poll() is None, (tmp_path / f"run_{d}.log").read_text()[-3000:]
        wait_for(
            lambda: sitl.boot_s() >= WARMUP_S or not sitl.alive(), 180, f"ArduSub up {WARMUP_S:g} s"
        )
        assert sitl.alive(), sitl.tail()
        # the sessions start 2 s before their first frame (the telemetry's lead); 15 s for two replays to start
        shift = time.time() + 15.0 - (START_UNIX - LEAD_S)
        replays = {}
        for d, (mav, video) in ports.items():
            extra = ("--cut", f"video:{CUT_S[0]}:{CUT_S[1]}", "--depth-key", "") if d == "b" else ()
            replays[d] = start(
                skyfix(
                    "replay",
                    str(sessions[d]),
                    "--mavlink-out",
                    f"udpout:127.0.0.1:{mav}",
                    "--video-out",
                    f"udp://127.0.0.1:{video}",
                    "--zenoh-connect",
                    ep,
                    "--uuv-listen",
                    "",
                    "--shift-s",
                    str(shift),
                    "--video-delay-ms",
                    str(CAMERA_LATENCY_MS),
                    "--tail-s",
                    "1",
                    *extra,
                ),
                tmp_path / f"replay_{d}.log",
            )
            procs.append(replays[d])
        for d, r in replays.items():
            assert r.wait(DURATION_S + 120) == 0, (tmp_path / f"replay_{d}.log").read_text()[-3000:]
        t_end = time.time()
        # a console joining late (a client of the router, which routes its query): the fused fix from the queryable
        late = zenoh.open(
            zenoh.Config.from_json5(
                json.dumps(
                    {
                        "mode": "client",
                        "connect": {"endpoints": [ep]},
                        "scouting": {"multicast": {"enabled": False}},
                    }
                )
            )
        )
        replies = [r.ok for r in late.get("skyfix/uuv/rov1/fix", timeout=10.0) if r.ok is not None]
        for s in services.values():
            stop(s)
        stop(fuser)
        assert sitl.alive(), sitl.tail()
    finally:
        if late is not None:
            late.close()
        for p in procs:
            stop(p, 5.0)
        sitl.stop()
    logs = {
        name: (tmp_path / f"{name}.log").read_text()[-3000:] for name in ("fuse", "run_a", "run_b")
    }
    assert fuser.returncode == 0, logs["fuse"]
    assert all(s.returncode == 0 for s in services.values()), logs

    records = read_jsonl(zlog)
    by_key = {}
    for r in records:
        by_key.setdefault(r["key"], []).append(json.loads(r["payload"]) | {"t_recv": r["t_recv"]})
    fused = [f for f in by_key.get("skyfix/uuv/rov1/fix", []) if f["status"] == "ok"]
    drone = {
        d: [f for f in by_key.get(f"skyfix/uuv/rov1/drone/{d}/fix", []) if f["status"] == "ok"]
        for d in DRONES
    }
    assert len(fused) > 200 and all(len(v) > 100 for v in drone.values()), {
        k: len(v) for k, v in by_key.items()
    }
    stats = json.loads((tmp_path / "fuse.json").read_text())
    session = sessions["a"]

    def errors(fixes):
        return truth_errors_m(
            session,
            np.array([f["t"] for f in fixes]) - shift,
            [f["lat"] for f in fixes],
            [f["lon"] for f in fixes],
        )

    # both drones fused: from b's first ok fix + 2 s (its gate's confirmation) to its cut, and after it is back
    cut0 = START_UNIX - LEAD_S + shift + CUT_S[0]
    cut1 = cut0 + CUT_S[1]
    b_t = np.array([f["t"] for f in drone["b"]])
    both = [(b_t[0] + 2.0, cut0), (cut1 + 3.0, b_t[-1])]

    def within(fixes, spans):
        return [f for f in fixes if any(a <= f["t"] <= b for a, b in spans)]

    mae = {
        name: float(np.mean(errors(within(fixes, both))))
        for name, fixes in (("fused", fused), ("a", drone["a"]), ("b", drone["b"]))
    }
    mae_all = {
        name: float(np.mean(errors(fixes))) for name, fixes in (("fused", fused), *drone.items())
    }

    # GPS_INPUT at ArduSub: only the fuser's, 3D and healthy through b's cut
    gin = [(t, m) for t, m in obs.of("GPS_INPUT") if t <= t_end]
    assert {(m.get_srcSystem(), m.get_srcComponent()) for _, m in gin} == {(245, 220)}
    gin3 = [(t, m) for t, m in gin if m.fix_type == FIX_3D]
    assert len(gin3) > 150, f"{len(gin3)} 3D GPS_INPUT of {len(gin)}"
    span = [(t, m) for t, m in gin if cut0 - 2.0 <= t <= cut1 + 2.0]
    no_fix = [round(t - cut0, 2) for t, m in span if m.fix_type != FIX_3D]
    unhealthy = ardupilot_gps_unhealthy([t for t, _ in span])
    raw = [(t, m) for t, m in obs.of("GPS_RAW_INT") if cut0 <= t <= cut1]
    raw_lost = [round(t - cut0, 2) for t, m in raw if m.fix_type < FIX_3D]
    # during the cut the fuser fused a alone; b was used again after it
    fused_cut = [f for f in fused if cut0 + 1.0 <= f["t"] <= cut1 - 1.0]
    a_by_t = {round(f["t"], 3): f for f in drone["a"]}
    same_as_a = sum(
        round(f["t"], 3) in a_by_t and abs(f["lat"] - a_by_t[round(f["t"], 3)]["lat"]) < 1e-9
        for f in fused_cut
    )
    after = [f for f in fused if f["t"] > cut1 + 3.0]
    b_after = sum(
        not (round(f["t"], 3) in a_by_t and abs(f["lat"] - a_by_t[round(f["t"], 3)]["lat"]) < 1e-9)
        for f in after
    )
    src = stats["fusion"]["sources"]
    print(
        f"\nfused MAE {mae['fused']:.4f} m vs drone a {mae['a']:.4f} m, drone b {mae['b']:.4f} m while both were "
        f"fused; over every fix: fused {mae_all['fused']:.4f}, a {mae_all['a']:.4f}, b {mae_all['b']:.4f}"
    )
    print(
        f"fixes: fused {len(fused)}, a {len(drone['a'])}, b {len(drone['b'])}; GPS_INPUT {len(gin)} "
        f"({len(gin3)} 3D); during b's {CUT_S[1]:g} s cut: {len(span)} GPS_INPUT, no-fix at {no_fix[:5]}, "
        f"GPS_RAW_INT {len(raw)} reports, below 3D at {raw_lost[:5]}; {same_as_a} of {len(fused_cut)} fused "
        f"fixes in the cut are a's own, {b_after} of {len(after)} after it are not"
    )
    for name, fixes in (("fused", fused), *drone.items()):  # exposure → at the subscriber
        age = np.array([f["t_recv"] - f["t"] for f in fixes])
        print(
            f"age of {name} fixes: p50 {np.percentile(age, 50):.3f} p90 {np.percentile(age, 90):.3f} "
            f"max {age.max():.3f} s"
        )
    print(
        f"fuser: {json.dumps({k: {x: v[x] for x in ('received', 'used', 'rejected', 'refused')} for k, v in src.items()})}"
    )
    assert not no_fix, f"GPS_INPUT left 3D during b's cut at {no_fix} s"
    assert unhealthy is None, (
        f"GPS_INPUT through b's cut: ArduPilot would call it unhealthy: {unhealthy}"
    )
    assert raw and not raw_lost, f"GPS_RAW_INT left 3D during b's cut at {raw_lost} s"
    assert fused_cut and same_as_a >= 0.9 * len(fused_cut), (
        f"{same_as_a} of {len(fused_cut)} fused in the cut are a's"
    )
    assert b_after >= 0.9 * len(after) > 0, (
        f"only {b_after} of {len(after)} fused fixes after b's cut are not a's own"
    )
    assert (
        src["skyfix/uuv/rov1/drone/b/fix"]["used"] > 0
        and src["skyfix/uuv/rov1/drone/a/fix"]["used"] > 0
    )
    assert mae["fused"] < min(mae["a"], mae["b"]), mae
    assert len(replies) == 1 and json.loads(replies[0].payload.to_bytes())["status"] in (
        "ok",
        "disagree",
    )

"""Two UUVs in one live video: ``skyfix replay`` of the generated ``two_uuvs_crossing`` session (each UUV's depth on
its own Zenoh key) → one ``skyfix run`` with two ``[[uuv]]`` tables → an independent Zenoh subscriber and one
pymavlink endpoint per UUV's autopilot.

Checked per UUV, against its own truth (``truth.csv``, ``uuvs/uuv2/truth.csv``): its fixes on its own key and the
valid GPS_INPUT at its own endpoint are within 0.05 m MAE, and each one is nearer its own UUV than the other
(no identity swap: GPS_INPUT names no vehicle, so each link must carry only its own); GPS_INPUT stays healthy by
ArduPilot's rule; each UUV's status is on its own key and fits the status schema. A config giving two UUVs one
GPS_INPUT link is refused in one line.
"""

from __future__ import annotations

import json
import shutil
import socket
import subprocess
import sys
import threading
import time
import tomllib

import numpy as np
import pytest
from jsonschema import Draft202012Validator
from live_helpers import (
    ROOT,
    SUBSCRIBER,
    ardupilot_gps_unhealthy,
    free_port,
    read_jsonl,
    replay_shift,
    skyfix,
    start,
    stop,
    truth_errors_m,
    wait_for,
)

from groundstation.contracts import GROUNDSTATION
from groundstation.mavlink.ingest import (
    mavutil,  # pymavlink, set to MAVLink 2 before its first import
)
from sim_fixtures.generate import generate
from sim_fixtures.scenario import load_scenario

SCENARIO = ROOT / "sim_fixtures" / "scenarios" / "two_uuvs_crossing.toml"
IDS = ("uuv1", "uuv2")
MIN_SHARE = 0.6  # of the frames with a fix: see test_live_e2e.MIN_SHARE

pytestmark = pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="needs the ffmpeg CLI")


class GpsEndpoint:
    """A UUV autopilot's MAVLink endpoint on loopback: every GPS_INPUT it receives, with its receive time."""

    def __init__(self):
        self.port = free_port()
        self.received: list[tuple[float, dict]] = []
        self._conn = mavutil().mavlink_connection(f"udpin:127.0.0.1:{self.port}")
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._listen, daemon=True)
        self._thread.start()

    def _listen(self) -> None:
        while not self._stop.is_set():
            msg = self._conn.recv_match(type="GPS_INPUT", blocking=True, timeout=0.2)
            if msg is not None:
                self.received.append((time.time(), msg.to_dict()))

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5)
        self._conn.close()


def own_and_other_errors_m(session, uuv_id, t_session, lat, lon):
    """Each position's distance (m) to its own UUV's truth and to the other UUV's, and the two truths' distance."""
    folders = {"uuv1": session, "uuv2": session / "uuvs" / "uuv2"}
    other = "uuv2" if uuv_id == "uuv1" else "uuv1"
    own = truth_errors_m(folders[uuv_id], t_session, lat, lon)
    far = truth_errors_m(folders[other], t_session, lat, lon)
    t1 = np.genfromtxt(folders[uuv_id] / "truth.csv", delimiter=",", names=True)
    apart = truth_errors_m(folders[other], t_session, np.interp(t_session, t1["t"], t1["lat"]),
                           np.interp(t_session, t1["t"], t1["lon"]))
    return own, far, apart


def run_toml(tmp_path, session, ports: dict, endpoints: dict) -> str:
    boxes = {"uuv1": tomllib.loads((session / "session.toml").read_text())["tracker"]["init_bbox"],
             "uuv2": tomllib.loads((session / "uuvs" / "uuv2" / "uuv.toml").read_text())["tracker"]["init_bbox"]}
    text = (f'calibration = "{session / "session.toml"}"\nmavlink = "udpin:127.0.0.1:{ports["mav"]}"\n'
            f'video = "udp://127.0.0.1:{ports["video"]}"\nvideo_latency_ms = 0\n'
            f'zenoh_listen = ["tcp/127.0.0.1:{ports["zenoh"]}"]\nduration_s = 34\n'
            f'stats = "{tmp_path / "stats.json"}"\n')
    for uuv_id in IDS:
        text += (f'\n[[uuv]]\nid = "{uuv_id}"\ndepth_key = "test/{uuv_id}/depth"\n'
                 f'gps_input = "udpout:127.0.0.1:{endpoints[uuv_id].port}"\ninit_bbox = {boxes[uuv_id]}\n')
    return text


def test_two_uuvs_in_one_video_each_with_its_own_fixes_and_gps_input(tmp_path):
    session = generate(load_scenario(SCENARIO), tmp_path / "s").session
    ports = {"mav": free_port(), "video": free_port(), "zenoh": free_port(socket.SOCK_STREAM)}
    endpoints = {uuv_id: GpsEndpoint() for uuv_id in IDS}
    config = tmp_path / "run.toml"
    config.write_text(run_toml(tmp_path, session, ports, endpoints))
    zenoh_ep = f"tcp/127.0.0.1:{ports['zenoh']}"
    replay_cmd = skyfix("replay", str(session), "--mavlink-out", f"udpout:127.0.0.1:{ports['mav']}",
                        "--video-out", f"udp://127.0.0.1:{ports['video']}", "--zenoh-connect", zenoh_ep,
                        "--depth-key", "test/uuv1/depth", "--uuv-depth-key", "uuv2=test/uuv2/depth",
                        "--uuv-listen", "", "--tail-s", "1.5")
    sub_out = tmp_path / "zenoh.jsonl"
    procs = []
    try:
        procs.append(start(skyfix("run", "--config", str(config)), tmp_path / "run.log"))
        procs.append(start([sys.executable, "-c", SUBSCRIBER, zenoh_ep, "skyfix/**", str(sub_out)],
                           tmp_path / "sub.log"))
        wait_for(lambda: {r["key"] for r in read_jsonl(sub_out)} >= {f"skyfix/uuv/{i}/status" for i in IDS}, 20,
                 "both UUVs' status on Zenoh")
        replay = start(replay_cmd, tmp_path / "replay.log")
        procs.append(replay)
        replay.wait(40)
        stop(procs[0])
        stop(procs[1])
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()
        for e in endpoints.values():
            e.close()
    run_log = (tmp_path / "run.log").read_text()
    assert procs[0].returncode == 0, run_log[-3000:]
    assert replay.returncode == 0, (tmp_path / "replay.log").read_text()[-3000:]
    shift = replay_shift(tmp_path / "replay.log")
    n_frames = len((session / "video_frames.csv").read_text().splitlines()) - 1
    samples = read_jsonl(sub_out)
    status_schema = Draft202012Validator(json.loads(GROUNDSTATION.path_of("status").read_text()))
    for uuv_id in IDS:
        fixes = [json.loads(s["payload"]) for s in samples if s["key"] == f"skyfix/uuv/{uuv_id}/fix"]
        ok = [f for f in fixes if f["status"] == "ok"]
        assert len(ok) >= MIN_SHARE * n_frames, (uuv_id, len(ok), {f["status"] for f in fixes}, run_log[-3000:])
        own, other, apart = own_and_other_errors_m(session, uuv_id, np.array([f["t"] for f in ok]) - shift,
                                                   [f["lat"] for f in ok], [f["lon"] for f in ok])
        print(f"{uuv_id} Zenoh: {len(fixes)} fixes, {len(ok)} ok, MAE {own.mean():.4f} m, max {own.max():.4f} m, "
              f"nearest approach of the two {apart.min():.3f} m")
        assert own.mean() <= 0.05, (uuv_id, own.mean(), own.max())
        assert (own < other).all(), f"{uuv_id}: {(own >= other).sum()} fixes nearer the other UUV"

        status = [json.loads(s["payload"]) for s in samples if s["key"] == f"skyfix/uuv/{uuv_id}/status"]
        bad = [e.message for m in status for e in status_schema.iter_errors(m)]
        assert not bad, bad[0]
        assert status[-1]["depth"]["received"] > 0 and status[-1]["pipeline"]["processed"] > 0

        received = endpoints[uuv_id].received
        t_recv = np.array([t for t, _ in received])
        unhealthy = ardupilot_gps_unhealthy(t_recv[(t_recv > t_recv[0] + 1.0)])
        assert unhealthy is None, f"{uuv_id}: ArduPilot would call GPS_INPUT unhealthy: {unhealthy}"
        valid = [g for _, g in received if g["fix_type"] == 3]
        assert len(valid) >= 0.5 * len(received), (uuv_id, len(valid), len(received))
        to_station = status[-1]["uav"]["clocks"]["station_minus_gnss_s"] or 0.0
        own, other, _ = own_and_other_errors_m(session, uuv_id,
                                               np.array([g["time_usec"] / 1e6 for g in valid]) + to_station - shift,
                                               [g["lat"] / 1e7 for g in valid], [g["lon"] / 1e7 for g in valid])
        print(f"{uuv_id} GPS_INPUT: {len(received)} messages, {len(valid)} valid, MAE {own.mean():.4f} m")
        assert own.mean() <= 0.05 and (own < other).all(), (uuv_id, own.mean(), (own >= other).sum())


def test_two_uuvs_on_one_gps_input_link_is_refused(tmp_path):
    """GPS_INPUT names no vehicle: two UUVs on one link would each take the other's position too."""
    config = tmp_path / "run.toml"
    config.write_text(f'calibration = "{ROOT / "sim_fixtures" / "bundled" / "nadir_hover" / "session.toml"}"\n'
                      '[[uuv]]\nid = "a"\ndepth_key = "a/depth"\ngps_input = "udpout:127.0.0.1:14601"\n'
                      '[[uuv]]\nid = "b"\ndepth_key = "b/depth"\ngps_input = "udpout:127.0.0.1:14601"\n')
    out = subprocess.run(skyfix("run", "--config", str(config), "--no-ui"), capture_output=True, text=True,
                         cwd=ROOT, timeout=60, check=False)
    assert out.returncode == 2
    assert out.stderr.strip().splitlines()[-1].endswith(
        "uuv[1].gps_input = 'udpout:127.0.0.1:14601': also uuv[0]'s (a): each UUV has its own"), out.stderr

"""Two UUVs in one live video: ``skyfix replay`` of the generated ``two_uuvs_crossing`` session (each UUV's depth on
its own Zenoh key) → one ``skyfix run`` with two ``[[uuv]]`` tables → an independent Zenoh subscriber and one
pymavlink endpoint per UUV's autopilot.

Checked per UUV, against its own truth (``truth.csv``, ``uuvs/uuv2/truth.csv``): its fixes on its own key and the
valid GPS_INPUT at its own endpoint are within 0.05 m MAE, and each one is nearer its own UUV than the other
(no identity swap: GPS_INPUT names no vehicle, so each link must carry only its own); GPS_INPUT stays healthy by
ArduPilot's rule; each UUV's status is on its own key and fits the status schema; the run's recording holds both
UUVs (the second in ``uuvs/uuv2/``), each located from its own recorded track within 0.05 m. A config giving two
UUVs one GPS_INPUT link is refused in one line.

The operator's page of such a run (a run of its own): ``/api/status`` has both UUVs; the WebSocket's hello, state
and video packets carry both (ids, colours, tracks, gates, each one's box on the one JPEG); a command naming no
UUV is refused naming the ids; ``release`` with ``"uuv": "uuv2"`` releases uuv2 alone (its fixes and GPS_INPUT
stop, uuv1's go on); uuv2 selected on uuv1's vehicle: both UUVs' fixes ``same_vehicle`` and uuv1's GPS_INPUT no
fix until uuv2 is released again; in a headless Chromium (when there is one) the page shows a row, a label and a track per
UUV, and "Await target" for the UUV picked with the key 2 applies to uuv2.
"""

from __future__ import annotations

import asyncio
import json
import re
import shutil
import socket
import struct
import subprocess
import sys
import time
import tomllib
import urllib.error
import urllib.request
from urllib.parse import urlsplit

import numpy as np
import pytest
from jsonschema import Draft202012Validator
from live_helpers import (
    ROOT,
    SUBSCRIBER,
    GpsInputEndpoint,
    as_camera_sends_it,
    free_port,
    read_jsonl,
    replay_shift,
    skyfix,
    start,
    stop,
    truth_errors_m,
    ui_url,
    wait_for,
)
from ui_browser import available, chromium

from groundstation.contracts import GROUNDSTATION
from groundstation.live.ui.palette import PALETTE
from groundstation.offline.process import process_session
from groundstation.session.read import load_session, uuv_ids
from groundstation.testing.ardupilot import ardupilot_gps_unhealthy

IDS = ("uuv1", "uuv2")

pytestmark = pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="needs the ffmpeg CLI")

#: Share of the frames each UUV must get a fix in, at the least: live_helpers.MIN_SHARE's, halved for two trackers
#: a frame (0.27 seen with the suite alone on a busy 2-core machine; 0.67-0.74 on a quiet one)
TWO_SHARE = 0.15


def own_and_other_errors_m(session, uuv_id, t_session, lat, lon):
    """Each position's distance (m) to its own UUV's truth and to the other UUV's, and the two truths' distance."""
    folders = {"uuv1": session, "uuv2": session / "uuvs" / "uuv2"}
    other = "uuv2" if uuv_id == "uuv1" else "uuv1"
    own = truth_errors_m(folders[uuv_id], t_session, lat, lon)
    far = truth_errors_m(folders[other], t_session, lat, lon)
    t1 = np.genfromtxt(folders[uuv_id] / "truth.csv", delimiter=",", names=True)
    apart = truth_errors_m(
        folders[other],
        t_session,
        np.interp(t_session, t1["t"], t1["lat"]),
        np.interp(t_session, t1["t"], t1["lon"]),
    )
    return own, far, apart


@pytest.fixture(scope="module")
def crossing(tmp_path_factory, two_uuvs_crossing):
    """The generated two_uuvs_crossing session (a copy of the run's, ``tests/conftest.py``), its video as a camera
    sends it, shared by this module's runs."""
    session = tmp_path_factory.mktemp("crossing") / "s"
    shutil.copytree(two_uuvs_crossing, session)
    as_camera_sends_it(session / "video.mp4")
    return session


def run_toml(tmp_path, session, ports: dict, endpoints: dict, record=None) -> str:
    boxes = {
        "uuv1": tomllib.loads((session / "session.toml").read_text())["tracker"]["init_bbox"],
        "uuv2": tomllib.loads((session / "uuvs" / "uuv2" / "uuv.toml").read_text())["tracker"][
            "init_bbox"
        ],
    }
    text = (
        f'calibration = "{session / "session.toml"}"\nmavlink = "udpin:127.0.0.1:{ports["mav"]}"\n'
        f'video = "udp://127.0.0.1:{ports["video"]}"\nvideo_latency_ms = 0\n'
        f'zenoh_listen = ["tcp/127.0.0.1:{ports["zenoh"]}"]\nduration_s = 34\n'
        f'stats = "{tmp_path / "stats.json"}"\n' + (f'record = "{record}"\n' if record else "")
    )
    for uuv_id in IDS:
        text += (
            f'\n[[uuv]]\nid = "{uuv_id}"\ndepth_key = "test/{uuv_id}/depth"\n'
            f'gps_input = "udpout:127.0.0.1:{endpoints[uuv_id].port}"\ninit_bbox = {boxes[uuv_id]}\n'
        )
    return text


class TwoUuvRun:
    """``skyfix run --config`` with two ``[[uuv]]`` tables (its page on a free port), a Zenoh subscriber to
    ``skyfix/**`` in its own process, a GPS_INPUT endpoint per UUV; ``with`` it: the replay of ``session`` has
    started and both UUVs' status has come. :meth:`finish` waits for the replay and stops the run."""

    def __init__(self, tmp_path, session, record=None):
        self.tmp, self.session = tmp_path, session
        ports = {"mav": free_port(), "video": free_port(), "zenoh": free_port(socket.SOCK_STREAM)}
        self.endpoints = {uuv_id: GpsInputEndpoint() for uuv_id in IDS}
        config = tmp_path / "run.toml"
        config.write_text(run_toml(tmp_path, session, ports, self.endpoints, record))
        self.zenoh_ep = f"tcp/127.0.0.1:{ports['zenoh']}"
        self.run_cmd = skyfix("run", "--config", str(config))
        self.replay_cmd = skyfix(
            "replay",
            str(session),
            "--mavlink-out",
            f"udpout:127.0.0.1:{ports['mav']}",
            "--video-out",
            f"udp://127.0.0.1:{ports['video']}",
            "--zenoh-connect",
            self.zenoh_ep,
            "--depth-key",
            "test/uuv1/depth",
            "--uuv-depth-key",
            "uuv2=test/uuv2/depth",
            "--uuv-listen",
            "",
            "--tail-s",
            "1.5",
        )
        self.sub_out = tmp_path / "zenoh.jsonl"
        self.procs: list[subprocess.Popen] = []

    def __enter__(self):
        try:
            self.run = start(self.run_cmd, self.tmp / "run.log")
            self.procs.append(self.run)
            self.procs.append(
                start(
                    [
                        sys.executable,
                        "-c",
                        SUBSCRIBER,
                        self.zenoh_ep,
                        "skyfix/**",
                        str(self.sub_out),
                    ],
                    self.tmp / "sub.log",
                )
            )
            wait_for(
                lambda: (
                    {r["key"] for r in read_jsonl(self.sub_out)}
                    >= {f"skyfix/uuv/{i}/status" for i in IDS}
                ),
                20,
                "both UUVs' status on Zenoh",
            )
            self.replay = start(self.replay_cmd, self.tmp / "replay.log")
            self.procs.append(self.replay)
        except BaseException:
            self.__exit__()
            raise
        return self

    def finish(self) -> None:
        """Wait for the replay's end, stop the run and the subscriber; both exited cleanly."""
        self.replay.wait(40)
        stop(self.procs[0])
        stop(self.procs[1])
        assert self.run.returncode == 0, self.run_log()[-3000:]
        assert self.replay.returncode == 0, (self.tmp / "replay.log").read_text()[-3000:]

    def __exit__(self, *exc) -> None:
        for p in self.procs:
            if p.poll() is None:
                p.kill()
                p.wait()
        for e in self.endpoints.values():
            e.close()

    def run_log(self) -> str:
        return (self.tmp / "run.log").read_text()

    def fixes(self, uuv_id: str) -> list[dict]:
        """The UUV's fixes the subscriber received, with their receive time."""
        return [
            json.loads(s["payload"]) | {"t_recv": s["t_recv"]}
            for s in read_jsonl(self.sub_out)
            if s["key"] == f"skyfix/uuv/{uuv_id}/fix"
        ]


def test_two_uuvs_in_one_video_each_with_its_own_fixes_and_gps_input(tmp_path, crossing):
    session = crossing
    with TwoUuvRun(tmp_path, session, record=tmp_path / "recorded") as run:
        run.finish()
    endpoints, run_log = run.endpoints, run.run_log()
    shift = replay_shift(tmp_path / "replay.log")
    n_frames = len((session / "video_frames.csv").read_text().splitlines()) - 1
    samples = read_jsonl(run.sub_out)
    status_schema = Draft202012Validator(json.loads(GROUNDSTATION.path_of("status").read_text()))
    for uuv_id in IDS:
        fixes = [
            json.loads(s["payload"]) for s in samples if s["key"] == f"skyfix/uuv/{uuv_id}/fix"
        ]
        ok = [f for f in fixes if f["status"] == "ok"]
        assert len(ok) >= TWO_SHARE * n_frames, (
            uuv_id,
            len(ok),
            {f["status"] for f in fixes},
            run_log[-3000:],
        )
        assert not [
            f for f in fixes if f["status"] == "same_vehicle"
        ]  # passing 0.3 m apart: two vehicles
        own, other, apart = own_and_other_errors_m(
            session,
            uuv_id,
            np.array([f["t"] for f in ok]) - shift,
            [f["lat"] for f in ok],
            [f["lon"] for f in ok],
        )
        print(
            f"{uuv_id} Zenoh: {len(fixes)} fixes, {len(ok)} ok, MAE {own.mean():.4f} m, max {own.max():.4f} m, "
            f"nearest approach of the two {apart.min():.3f} m"
        )
        assert own.mean() <= 0.05, (uuv_id, own.mean(), own.max())
        assert (own < other).all(), f"{uuv_id}: {(own >= other).sum()} fixes nearer the other UUV"

        status = [
            json.loads(s["payload"]) for s in samples if s["key"] == f"skyfix/uuv/{uuv_id}/status"
        ]
        bad = [e.message for m in status for e in status_schema.iter_errors(m)]
        assert not bad, bad[0]
        assert status[-1]["depth"]["received"] > 0 and status[-1]["pipeline"]["processed"] > 0

        received = endpoints[uuv_id].received
        t_recv = np.array([t for t, _ in received])
        unhealthy = ardupilot_gps_unhealthy(t_recv[(t_recv > t_recv[0] + 1.0)])
        assert unhealthy is None, f"{uuv_id}: ArduPilot would call GPS_INPUT unhealthy: {unhealthy}"
        valid = [g for _, g in received if g["fix_type"] == 3]
        # valid as the UUV's gates accepted (test_live_e2e.py): refused only while confirming, for age, or while the
        # two came near and were not told apart yet (exchanged: localizer/exchange.py); all arrived
        sent = status[-1]["gps_input"]
        refused = {reason: n for reason, n in sent["gates"]["rejected"].items() if n}
        assert set(refused) <= {"unconfirmed", "age", "exchanged"}, (
            uuv_id,
            refused,
            sent["gates"]["last_refusal"],
        )
        assert sent["gates"]["accepted"] >= 10 and len(valid) >= max(
            10, 0.9 * sent["sent_valid"]
        ), (uuv_id, len(valid), sent["sent_valid"], sent["gates"]["accepted"])
        to_station = status[-1]["uav"]["clocks"]["station_minus_gnss_s"] or 0.0
        own, other, _ = own_and_other_errors_m(
            session,
            uuv_id,
            np.array([g["time_usec"] / 1e6 for g in valid]) + to_station - shift,
            [g["lat"] / 1e7 for g in valid],
            [g["lon"] / 1e7 for g in valid],
        )
        print(
            f"{uuv_id} GPS_INPUT: {len(received)} messages, {len(valid)} valid, MAE {own.mean():.4f} m"
        )
        assert own.mean() <= 0.05 and (own < other).all(), (
            uuv_id,
            own.mean(),
            (own >= other).sum(),
        )

    # the recording holds both UUVs as the reader reads them; each, processed from its own track, is where it was
    rec = tmp_path / "recorded"
    assert uuv_ids(rec) == IDS
    for uuv_id in IDS:
        recorded = load_session(rec, uuv=uuv_id)
        assert len(recorded.telemetry.depth) > 100 and recorded.calibration.init_bbox is not None
        fixes = process_session(recorded, use_track=True)
        good = fixes.status == "ok"
        own, other, _ = own_and_other_errors_m(
            session, uuv_id, fixes.t_unix[good] - shift, fixes.lat[good], fixes.lon[good]
        )
        print(f"{uuv_id} recorded: {good.sum()} fixes from its track.csv, MAE {own.mean():.4f} m")
        assert good.sum() >= TWO_SHARE * n_frames and own.mean() <= 0.05 and (own < other).all(), (
            uuv_id
        )


def test_two_uuvs_on_one_gps_input_link_is_refused(tmp_path):
    """GPS_INPUT names no vehicle: two UUVs on one link would each take the other's position too."""
    config = tmp_path / "run.toml"
    config.write_text(
        f'calibration = "{ROOT / "sim_fixtures" / "bundled" / "nadir_hover" / "session.toml"}"\n'
        '[[uuv]]\nid = "a"\ndepth_key = "a/depth"\ngps_input = "udpout:127.0.0.1:14601"\n'
        '[[uuv]]\nid = "b"\ndepth_key = "b/depth"\ngps_input = "udpout:127.0.0.1:14601"\n'
    )
    out = subprocess.run(
        skyfix("run", "--config", str(config), "--no-ui"),
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=60,
        check=False,
    )
    assert out.returncode == 2
    assert (
        out.stderr.strip()
        .splitlines()[-1]
        .endswith(
            "uuv[1].gps_input = 'udpout:127.0.0.1:14601': also uuv[0]'s (a): each UUV has its own"
        )
    ), out.stderr


def _http(url: str, body: dict | None = None) -> tuple[int, dict]:
    """GET ``url`` (or POST ``body`` as JSON): the status code and the JSON answer."""
    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(
        url,
        data=data,
        headers={"Content-Type": "application/json"} if data else {},
        method="GET" if data is None else "POST",
    )
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read())


async def _page_messages(base: str, timeout_s: float = 15.0) -> tuple[dict, dict, dict]:
    """What the page's WebSocket sends: its hello, a state message, and the overlay of a video packet on which both
    UUVs are tracked (``ok``)."""
    import aiohttp

    async with (
        aiohttp.ClientSession() as http,
        http.ws_connect(base.replace("http", "ws") + "/ws") as ws,
    ):
        hello = json.loads((await ws.receive(timeout=15)).data)
        state = overlay = None
        end = time.monotonic() + timeout_s
        while (state is None or overlay is None) and time.monotonic() < end:
            msg = await ws.receive(timeout=max(0.1, end - time.monotonic()))
            if msg.type == aiohttp.WSMsgType.TEXT:
                state = json.loads(msg.data)
            elif msg.type == aiohttp.WSMsgType.BINARY:
                n = struct.unpack(">I", msg.data[:4])[0]
                o = json.loads(msg.data[4 : 4 + n])
                assert msg.data[4 + n : 4 + n + 2] == b"\xff\xd8"  # one JPEG
                if all(u["status"] == "ok" for u in o.get("uuvs", ())):
                    overlay = o
        return hello, state, overlay


def test_the_page_shows_and_commands_each_uuv(tmp_path, crossing):
    with TwoUuvRun(tmp_path, crossing) as run:
        url = ui_url(tmp_path / "run.log")
        base = f"http://127.0.0.1:{urlsplit(url).port}"
        wait_for(
            lambda: all(sum(f["status"] == "ok" for f in run.fixes(i)) >= 30 for i in IDS),
            20,
            "ok fixes of both UUVs",
        )

        # GET /api/status: the first UUV's status as with one, and each UUV's own sections
        code, status = _http(base + "/api/status")
        assert code == 200 and set(status["uuvs"]) == set(IDS), status.keys()
        assert status["target"]["state"] == "tracking" and status["uav"]["received"] > 0
        for uuv_id in IDS:
            own = status["uuvs"][uuv_id]
            assert own["target"]["state"] == "tracking" and own["fix"]["status"] == "ok", (
                uuv_id,
                own["target"],
            )
            assert own["depth"]["key"] == f"test/{uuv_id}/depth" and "uav" not in own
        assert (
            status["uuvs"]["uuv1"]["fix"]["frame"] == status["fix"]["frame"]
            or status["fix"]["frame"] > 0
        )

        # the WebSocket: both UUVs in the hello, the state and on one JPEG
        hello, state, overlay = asyncio.run(_page_messages(base))
        assert [(u["id"], u["colour"]) for u in hello["uuvs"]] == list(
            zip(IDS, PALETTE[:2], strict=True)
        )
        assert state and state["type"] == "state" and set(state["status"]["uuvs"]) == set(IDS)
        assert [u["id"] for u in state["uuvs"]] == list(IDS)
        assert all(u["gate"] and u["gate"]["state"] for u in state["uuvs"]), state["uuvs"]
        assert overlay is not None, "no video packet with both UUVs ok"
        assert [(u["id"], u["colour"]) for u in overlay["uuvs"]] == list(
            zip(IDS, PALETTE[:2], strict=True)
        )
        boxes = [u["box"] for u in overlay["uuvs"]]
        assert all(b and len(b) == 4 for b in boxes) and boxes[0] != boxes[1], boxes
        # the first UUV's, as with one
        assert overlay["status"] == "ok" and overlay["box"] == boxes[0]

        # a command must name its UUV
        code, answer = _http(base + "/api/release", {})
        assert code == 400 and "several UUVs (uuv1, uuv2)" in answer["error"], answer
        code, answer = _http(base + "/api/release", {"uuv": "uuv9"})
        assert (
            code == 400
            and answer["error"] == 'release: uuv = "uuv9": not a UUV of this run (uuv1, uuv2)'
        )
        code, answer = _http(base + "/api/select", {"uuv": "uuv2", "box": [1, 2]})
        assert (
            code == 400 and answer["error"] == "select: box = [1, 2]: expected 4 finite numbers"
        ), answer

        code, answer = _http(base + "/api/release", {"uuv": "uuv2"})
        t_released = time.time()
        assert (
            code == 200 and answer["uuv"] == "uuv2" and answer["target"]["state"] == "released"
        ), answer
        wait_for(
            lambda: sum(f["t_recv"] > t_released + 0.5 for f in run.fixes("uuv2")) >= 10,
            10,
            "uuv2's fixes after the release",
        )
        code, status = _http(base + "/api/status")
        assert status["uuvs"]["uuv2"]["target"]["state"] == "released"
        assert (
            status["uuvs"]["uuv1"]["target"]["state"] == "tracking"
            and status["target"]["state"] == "tracking"
        )

        # uuv2 selected on uuv1's vehicle (as a tracker re-locking onto the other would): neither gives a fix, and
        # GPS_INPUT says no fix to both; uuv2 released again, uuv1's fixes come back
        t_same = time.time()
        box1 = _http(base + "/api/status")[1]["uuvs"]["uuv1"]["target"]["box"]
        code, answer = _http(base + "/api/select", {"uuv": "uuv2", "box": box1})
        # the answer waits for the box's check over its first frames: taken, the vehicle tracked
        assert code == 200 and answer["target"]["state"] == "tracking", answer
        wait_for(
            lambda: all(
                len(run.fixes(i)) > 3
                and {f["status"] for f in run.fixes(i)[-3:]} == {"same_vehicle"}
                for i in IDS
            ),
            10,
            lambda: (
                f"both UUVs' fixes same_vehicle (last: {[[f['status'] for f in run.fixes(i)[-3:]] for i in IDS]})"
            ),
        )
        t_both = time.time()
        wait_for(
            lambda: [g["fix_type"] for _, g in run.endpoints["uuv1"].received[-3:]] == [1, 1, 1],
            10,
            "uuv1's GPS_INPUT no fix",
        )
        t_no_fix = time.time()
        wait_for(
            lambda: all(sum(f["t_recv"] > t_no_fix for f in run.fixes(i)) >= 3 for i in IDS),
            10,
            "both UUVs' fixes while on one vehicle",
        )
        t_parting = time.time()
        assert _http(base + "/api/release", {"uuv": "uuv2"})[0] == 200
        t_parted = time.time()
        wait_for(lambda: run.fixes("uuv1")[-1]["status"] == "ok", 10, "uuv1's fixes back")

        browser_checked = available() is None
        if browser_checked:
            with chromium(tmp_path, base) as browser:
                page = browser.page
                page.goto(base + "/")
                page.wait_for_selector("#conn.ok", timeout=20_000)
                wait_for(
                    lambda: page.eval_on_selector("#uuvs tbody", "b => b.rows.length") == 2,
                    10,
                    "a row per UUV",
                )
                wait_for(
                    lambda: (
                        page.eval_on_selector("#video", "c => c.dataset.uuvs")
                        == "uuv1:ok uuv2:released"
                    ),
                    10,
                    "both UUVs on the video: uuv1 ok, uuv2 released",
                )
                rows = page.inner_text("#uuvs tbody")
                assert re.search(r"uuv1\s+tracking.*\s+ok\s", rows) and re.search(
                    r"uuv2\s+released", rows
                ), rows
                tracks = dict(
                    t.split(":")
                    for t in page.eval_on_selector("#map", "m => m.dataset.tracks").split()
                )
                assert set(tracks) == set(IDS) and all(int(n) > 0 for n in tracks.values()), tracks
                health = page.inner_text("#health")
                assert (
                    "uuv1 depth" in health
                    and "uuv2 GPS_INPUT" in health
                    and health.count("UAV MAVLink") == 1
                )
                # how each UUV's [[uuv]] init_bbox was taken on the first frame: the recorded box, on its vehicle
                assert status["uuvs"]["uuv1"]["target"]["init_bbox"] == "kept", status["uuvs"][
                    "uuv1"
                ]
                assert page.inner_text("#target-state").endswith("· init_bbox kept")
                browser.screenshot("6-two-uuvs-uuv2-released")
                page.keyboard.press("2")
                assert page.eval_on_selector("#uuv-pick", "p => p.dataset.selected") == "uuv2"
                page.click("#acquire")
                wait_for(
                    lambda: page.inner_text("#cmd-result").startswith(
                        "uuv2 acquire: awaiting_target"
                    ),
                    10,
                    "the page's acquire for uuv2",
                )
                assert page.inner_text("#target-state").startswith("uuv2 target")
                assert not browser.errors, browser.errors
                assert browser.outside == []
        run.finish()
    endpoints, fixes = run.endpoints, run.fixes

    # after the release (but while uuv2 was on uuv1's vehicle): uuv2 has no fix, uuv1 keeps fixing
    def released(t: float) -> bool:
        return t > t_released + 0.5 and not t_same <= t <= t_parted + 0.5

    after = {i: [f for f in fixes(i) if released(f["t_recv"])] for i in IDS}
    assert {f["status"] for f in after["uuv2"]} <= {"released", "buffered", "awaiting_target"}, (
        after["uuv2"][:3]
    )
    ok1 = [f for f in after["uuv1"] if f["status"] == "ok"]
    assert len(after["uuv2"]) >= 30 and len(ok1) >= 0.8 * len(after["uuv1"]) >= 30, (
        len(ok1),
        len(after["uuv1"]),
    )
    gps2 = [g for t, g in endpoints["uuv2"].received if t > t_released + 0.5]
    assert gps2 and all(g["fix_type"] == 1 for g in gps2), {g["fix_type"] for g in gps2}
    gps1 = [g for t, g in endpoints["uuv1"].received if t_released + 0.5 < t < t_same]
    assert sum(g["fix_type"] == 3 for g in gps1) >= 0.8 * len(gps1) > 0
    # both on one vehicle: from the first same_vehicle on, no fix and no valid GPS_INPUT for either until parted
    same = {i: [f["status"] for f in fixes(i) if t_both <= f["t_recv"] <= t_parting] for i in IDS}
    assert all(same[i] and set(same[i]) == {"same_vehicle"} for i in IDS), same
    assert all(
        g["fix_type"] == 1 for t, g in endpoints["uuv1"].received if t_no_fix <= t <= t_parting
    )
    print(
        f"page: released uuv2; after it uuv1 {len(ok1)}/{len(after['uuv1'])} ok fixes, uuv2 "
        f"{len(after['uuv2'])} fixes, none ok; browser {'checked' if browser_checked else 'not available'}"
    )

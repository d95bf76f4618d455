"""Live scenarios shared by ``tests/test_live_links.py`` (generous bounds) and ``bench/links.py`` (the 1 s
requirement, several trials): ``skyfix run`` stopped by a signal whatever its inputs are doing, and its
links cut and coming back. Real parts only: ``skyfix replay``, a pymavlink GPS_INPUT listener, a Zenoh
router process, a depth publisher process, a TCP server that never answers RTSP.

Times are measured from outside the service: the signal to the process's exit; an input's return (the
replay's ``back`` event, the restarted router's or publisher's first moment) to the first valid GPS_INPUT
the listener receives after it.
"""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import threading
import time
import tomllib
from pathlib import Path

from groundstation.testing.live import (
    ROOT,
    GpsInputEndpoint,
    free_port,
    read_jsonl,
    replay_shift,
    skyfix,
    start,
    stop,
    wait_for,
    wait_until,
)

BUNDLED = ROOT / "sim_fixtures" / "bundled"
SHUTDOWN_STATES = ("flowing", "udp_silent", "rtsp_silent", "mavlink_silent")
LINK_INPUTS = ("mavlink", "depth", "router", "video")
# session seconds after the start: the first fixes come 2 s in, a target is valid a second later (the first valid
# GPS_INPUT 3.3 s in, on a quiet machine), and then ~4 s of valid fixes before the cut on a loaded one (0 when the
# cut came at 4 s: CI)
CUT_FROM_S = 7.0
CUT_S = {
    "mavlink": 10.0,
    "depth": 6.0,
    "router": 6.0,
    "video": 6.0,
}  # > the watchdog's 3 s + its 1 s period
# the generated session: long enough for a 10 s MAVLink cut with fixes before and after
SESSION_S = 19.0
SESSION_FPS = 15.0

# A Zenoh router (the only router on PyPI is zenoh's own, in a Python session of mode "router"), its own process;
# it opens when a line comes on its stdin.
ROUTER = r"""
import json, sys, time, zenoh
c = zenoh.Config()
c.insert_json5("mode", '"router"')
c.insert_json5("scouting/multicast/enabled", "false")
c.insert_json5("listen/endpoints", json.dumps([sys.argv[1]]))
print("loaded", flush=True)
sys.stdin.readline()  # opened when told: a restart's imports are done before the cut ends
s = zenoh.open(c)
print("ready", time.time(), flush=True)
try:
    while True:
        time.sleep(1)
finally:
    s.close()
"""

# A UUV's depth publisher, its own process: the session's depth at (now − shift), 10 Hz, from a line on its stdin
# until killed.
DEPTH_PUBLISHER = r"""
import json, sys, time
import numpy as np
from groundstation.runtime.zenoh_session import open_session
session_dir, shift, endpoint = sys.argv[1], float(sys.argv[2]), sys.argv[3]
rows = [json.loads(line) for line in open(session_dir + "/depth.jsonl") if line.strip()]
t, d = np.array([r["t"] for r in rows]), np.array([r["depth_m"] for r in rows])
print("loaded", flush=True)
sys.stdin.readline()  # started when told: a restart's imports are done before the cut ends
z = open_session([endpoint])
first = True
try:
    while True:
        now = time.time()
        z.put("uuv/depth", json.dumps({"t": now, "depth_m": float(np.interp(now - shift, t, d))}))
        if first:
            print("first", now, flush=True)
            first = False
        time.sleep(0.1)
finally:
    z.close()
"""


def loaded_router(endpoint: str) -> subprocess.Popen:
    """A router process for ``endpoint`` with its imports done, not yet open (:func:`go`; it listens a little
    before it says it is ready: a client may be connected through it before that moment)."""
    proc = subprocess.Popen(
        [sys.executable, "-c", ROUTER, endpoint],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout.readline().strip() == "loaded"
    return proc


def loaded_depth_publisher(session: Path, shift_s: float, endpoint: str) -> subprocess.Popen:
    """A :data:`DEPTH_PUBLISHER` of ``session`` with its imports done, not yet publishing (:func:`go`)."""
    proc = subprocess.Popen(
        [sys.executable, "-c", DEPTH_PUBLISHER, str(session), str(shift_s), endpoint],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        cwd=ROOT,
    )
    assert proc.stdout.readline().strip() == "loaded"
    return proc


def go(proc: subprocess.Popen) -> float:
    """Tell a loaded router or depth publisher to start; the moment it said it had (UNIX s)."""
    proc.stdin.write("go\n")
    proc.stdin.flush()
    _, t = proc.stdout.readline().split()
    return float(t)


def start_router(endpoint: str) -> tuple[subprocess.Popen, float]:
    """A router listening on ``endpoint``; the process and when it said it was ready (UNIX s)."""
    proc = loaded_router(endpoint)
    return proc, go(proc)


def kill(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.kill()
    proc.wait()


class GpsListener(GpsInputEndpoint):
    """The UUV's autopilot side of GPS_INPUT; ``got`` holds (t_recv, fix_type), t_recv the kernel's."""

    @property
    def got(self) -> list[tuple[float, int]]:
        return [(t, g["fix_type"]) for t, g in list(self.received)]

    def first_valid_after(self, t: float) -> float | None:
        return next((tr for tr, ft in self.got if tr >= t and ft == 3), None)


class SilentServer:
    """A TCP server that accepts and never says a word (an RTSP camera that hangs); ``accepted`` counts."""

    def __init__(self):
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.accepted = 0
        self._conns: list[socket.socket] = []
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self) -> None:
        while True:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            self._conns.append(conn)
            self.accepted += 1

    def close(self) -> None:
        self.sock.close()
        for c in self._conns:
            c.close()


def _run_cmd(cal: Path, mav: str, video: str, uuv: int, *extra: str) -> list[str]:
    return skyfix(
        "run",
        "--calibration",
        str(cal),
        "--mavlink",
        mav,
        "--video",
        video,
        "--video-latency-ms",
        "0",
        "--gps-input",
        f"udpout:127.0.0.1:{uuv}",
        "--fix-max-age-ms",
        "500",
        *extra,
    )


def shutdown(tmp: Path, state: str, sig: int = signal.SIGINT) -> dict:
    """``skyfix run`` in ``state`` (:data:`SHUTDOWN_STATES`), stopped by ``sig``: how long it took, its exit code,
    and the GPS_INPUT the UUV got after the signal."""
    session = BUNDLED / "nadir_hover"
    tmp.mkdir(parents=True, exist_ok=True)
    mav, video, uuv = free_port(), free_port(), free_port()
    zenoh = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    video_url = f"udp://127.0.0.1:{video}"
    server = SilentServer() if state == "rtsp_silent" else None
    if server:
        video_url = f"rtsp://127.0.0.1:{server.port}/camera?transport=tcp"
    listener = GpsListener(uuv)
    run_log = tmp / "run.log"
    procs = []
    try:
        service = start(
            _run_cmd(
                session / "session.toml",
                f"udpin:127.0.0.1:{mav}",
                video_url,
                uuv,
                "--zenoh-listen",
                zenoh,
            ),
            run_log,
        )
        procs.append(service)
        wait_for(lambda: "skyfix run: UAV" in run_log.read_text(), 30, "the service to start")
        if state in ("flowing", "mavlink_silent"):
            mav_out = f"udpout:127.0.0.1:{mav if state == 'flowing' else free_port()}"  # nobody listens there
            procs.append(
                start(
                    skyfix(
                        "replay",
                        str(session),
                        "--mavlink-out",
                        mav_out,
                        "--video-out",
                        f"udp://127.0.0.1:{video}",
                        "--zenoh-connect",
                        zenoh,
                        "--uuv-listen",
                        "",
                    ),
                    tmp / "replay.log",
                )
            )
            want = 3 if state == "flowing" else 1
            wait_for(
                lambda: any(ft == want for _, ft in listener.got), 30, f"GPS_INPUT fix_type {want}"
            )
            if state == "mavlink_silent":
                wait_for(lambda: "video: receiving" in run_log.read_text(), 30, "the video flowing")
        elif state == "rtsp_silent":
            wait_for(lambda: server.accepted > 0, 30, "the RTSP open pending")
        else:
            wait_for(
                lambda: "nothing received" in run_log.read_text(), 30, "a video open that timed out"
            )
            wait_for(lambda: len(listener.got) > 0, 30, "GPS_INPUT")
        t_signal = time.time()
        service.send_signal(sig)
        try:
            service.wait(30)
        except subprocess.TimeoutExpired:
            pass
        exit_s = time.time() - t_signal if service.returncode is not None else None
        # the last GPS_INPUT, sent just before the exit, may still be on its way through loopback: wait for a
        # no-fix after the signal (the test then asserts it is the last), for 10 s at most
        wait_until(
            lambda: any(tr >= t_signal and ft < 2 for tr, ft in listener.got), 10.0, poll_s=0.02
        )
        after = [ft for tr, ft in listener.got if tr >= t_signal]
    finally:
        for p in procs:
            kill(p)
        listener.close()
        if server:
            server.close()
    return {
        "state": state,
        "signal": signal.Signals(sig).name,
        "exit_s": exit_s,
        "rc": service.returncode,
        "gps_after_signal": after,
        "log": run_log.read_text(),
    }


def session_scenario(out: Path) -> Path:
    """The scenario of :func:`make_session` into ``out``, written next to it: nadir_hover for :data:`SESSION_S` s at
    :data:`SESSION_FPS` fps."""
    text = (
        (ROOT / "sim_fixtures" / "scenarios" / "nadir_hover.toml")
        .read_text()
        .replace("duration_s = 7.0", f"duration_s = {SESSION_S}\nfps = {SESSION_FPS}")
    )
    assert tomllib.loads(text)["fps"] == SESSION_FPS
    out.parent.mkdir(parents=True, exist_ok=True)
    scenario = out.parent / f"{out.name}.toml"
    scenario.write_text(text)
    return scenario


def make_session(out: Path) -> Path:
    """:func:`session_scenario` rendered into ``out`` (once per directory), by the simulator's own command
    (``skyfix sim``: the groundstation imports no module of the simulator)."""
    if (out / "session.toml").exists():
        return out
    cmd = skyfix("sim", str(session_scenario(out)), "--out", str(out), "--quiet")
    subprocess.run(cmd, check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
    return out


class _Statuses:
    """Every ``skyfix/status`` message (t_recv, message) seen by an own Zenoh session."""

    def __init__(self, endpoint: str):
        from groundstation.runtime.zenoh_session import open_session

        self.got: list[tuple[float, dict]] = []
        self.session = open_session([endpoint])
        self.sub = self.session.declare_subscriber(
            "skyfix/status",
            lambda s: self.got.append((time.time(), json.loads(s.payload.to_bytes()))),
        )

    def close(self) -> None:
        self.sub.undeclare()
        self.session.close()


def _said(log: Path, lines: int = 25) -> str:
    """The last ``lines`` lines of a service's log that are not JSON records."""
    said = [line for line in log.read_text().splitlines() if not line.startswith("{")]
    return "\n".join(said[-lines:])


def link_comes_back(tmp: Path, session: Path, which: str) -> dict:
    """``skyfix run`` fed by ``skyfix replay`` of ``session``; ``which`` (:data:`LINK_INPUTS`) goes away
    :data:`CUT_FROM_S` s into the session for :data:`CUT_S` s and comes back. Returned: when it went and came
    back, the first valid GPS_INPUT after (``back_s``), the GPS_INPUT and the status's ``problems`` meanwhile."""
    tmp.mkdir(parents=True, exist_ok=True)
    mav, video, uuv = free_port(), free_port(), free_port()
    endpoint = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    listener = GpsListener(uuv)
    run_log, replay_log = tmp / "run.log", tmp / "replay.log"
    procs, router, statuses = [], None, None
    zenoh_args = ("--zenoh-listen", endpoint)
    if which == "router":  # skyfix a client of a router, as on BlueOS; the replay a peer of it
        router, _ = start_router(endpoint)
        zenoh_args = (
            "--zenoh-config",
            str(ROOT / "deploy" / "zenoh" / "client.json5"),
            "--zenoh-connect",
            endpoint,
        )
    replay_extra = (
        ["--cut", f"{which}:{CUT_FROM_S}:{CUT_S[which]}"] if which in ("mavlink", "video") else []
    )
    if which == "depth":
        replay_extra = [
            "--cut",
            f"depth:0:{SESSION_S + 10}",
        ]  # the depth comes from its own publisher
    try:
        service = start(
            _run_cmd(
                session / "session.toml",
                f"udpin:127.0.0.1:{mav}",
                f"udp://127.0.0.1:{video}",
                uuv,
                *zenoh_args,
            ),
            run_log,
        )
        procs.append(service)
        wait_for(lambda: "skyfix run: UAV" in run_log.read_text(), 30, "the service to start")
        statuses = _Statuses(endpoint)
        wait_for(lambda: statuses.got, 30, "the service's status on Zenoh")
        replay = start(
            skyfix(
                "replay",
                str(session),
                "--mavlink-out",
                f"udpout:127.0.0.1:{mav}",
                "--video-out",
                f"udp://127.0.0.1:{video}",
                "--zenoh-connect",
                endpoint,
                "--uuv-listen",
                "",
                "--lead-s",
                "0.5",
                *replay_extra,
            ),
            replay_log,
        )
        procs.append(replay)
        shift = replay_shift(replay_log)
        started = json.loads(replay_log.read_text().splitlines()[0])
        t_start, t_end = started["t_start"], started["t_end"]
        publisher = None
        if which == "depth":
            publisher = loaded_depth_publisher(session, shift, endpoint)
            procs.append(publisher)
            go(publisher)
        t_cut, t_return = t_start + CUT_FROM_S, t_start + CUT_FROM_S + CUT_S[which]
        wait_for(lambda: time.time() >= t_cut, 60, "the cut")
        if which == "depth":
            kill(publisher)
            # its start-up, seconds on a loaded machine, inside the cut
            publisher = loaded_depth_publisher(session, shift, endpoint)
            procs.append(publisher)
        elif which == "router":
            kill(router)
            router = loaded_router(
                endpoint
            )  # its start-up, seconds on a loaded machine, inside the cut
        wait_for(lambda: time.time() >= t_return, 60, "the end of the cut")
        if which == "depth":
            t_back = go(publisher)
        elif which == "router":
            # the router may carry traffic before it prints "ready": the cut ends here
            t_launch = time.time()
            t_back = go(router)
        else:

            def back() -> float | None:
                return next(
                    (r["t"] for r in read_jsonl(replay_log) if r.get("event") == "back"), None
                )

            wait_for(lambda: back() is not None, 30, f"{which} back")
            t_back = back()
        wait_for(
            lambda: listener.first_valid_after(t_back) is not None,
            20,
            lambda: (
                f"a valid GPS_INPUT after the return, {t_back - t_start:.2f} s into the replay (which ends at "
                f"{t_end - t_start:.2f} s); fix types since: {[ft for tr, ft in listener.got if tr >= t_back]}; "
                f"the service said: {_said(run_log)}"
            ),
        )
        t_valid = listener.first_valid_after(t_back)
        # nothing after the first valid GPS_INPUT is measured: the replay is stopped there, not played to its end,
        # and the service stopped as at the end of any run (its exit code and log are checked by the caller)
        stop(replay)
        service.send_signal(signal.SIGINT)
        service.wait(30)
    finally:
        for p in procs:
            kill(p)
        if statuses:
            statuses.close()
        if router:
            kill(router)
        listener.close()
    named = {"mavlink": "uav", "depth": "depth", "router": "zenoh", "video": "video"}[which]
    missing = [
        (t, st["problems"]) for t, st in statuses.got if t_cut + 4.5 <= t < t_return
    ]  # none via a lost router
    t_gone_end = t_launch if which == "router" else t_back
    gone = [ft for tr, ft in listener.got if t_cut + 2.5 <= tr < t_gone_end]
    gone_at = [
        (round(tr - t_cut, 3), ft)
        for tr, ft in listener.got
        if t_cut + 2.5 <= tr < t_back and ft != 1
    ]
    return {
        "input": which,
        "back_s": t_valid - t_back,
        "t_cut": t_cut,
        "t_back": t_back,
        "rc": service.returncode,
        "named": named,
        "problems_while_missing": missing,
        "gps_while_missing": gone,
        "fixes_while_missing_at": gone_at,
        "valid_before_cut": sum(ft == 3 for tr, ft in listener.got if tr < t_cut),
        "first_valid_s": listener.first_valid_after(t_start) - t_start,
        "log": run_log.read_text(),
    }

"""Benchmark of several UUVs in one live video: CPU and latency with 1, 2 and 3 UUVs in one 1080p30 stream.

    .venv/bin/python bench/uuvs.py [--counts 1,2,3] [--rounds 1] [--baseline-frames 150] [--duration-s 20]
        [--profile-s 10] [--nice N] [--policy other,rr] [--out bench/results/uuvs.txt]

The session is the ``three_uuvs_crossing`` scenario (two BlueROV2s passing nearly head on under a camera 10 m up,
a third, ``[third_uuv]``, 0.6 m deep, passing uuv1 1 m to its side the other way, never nearer either vehicle than
1 m) rendered at 1920x1080 30 fps, generated once into ``/tmp/skyfix-bench/`` (a few minutes) and its video re-encoded
as a camera sends it (:func:`bench.live_latency.encode_as_camera`). As in ``bench/live_latency.py``,
``skyfix replay`` sends every frame as MPEG-TS over UDP :data:`CAMERA_LATENCY_MS` after its exposure, the UAV's
MAVLink and each UUV's depth on its own Zenoh key into one ``skyfix run --config`` on loopback, whose ``[[uuv]]``
tables are the UUVs of the run:

- 1 UUV: ``uuv1``;
- 2 UUVs: ``uuv1`` and ``uuv2``, the two vehicles of the scenario;
- 3 UUVs: those two and ``uuv3``, the third vehicle, its depth on its own key.

All three vehicles are in the video in every run (the ones not configured are look-alikes to the others).

Each UUV has its own GPS_INPUT link, a UDP port on 127.0.0.1 the benchmark listens on (one thread, one socket per
UUV, pymavlink's parser), stamping each GPS_INPUT with its arrival.

Measured per run: CPU seconds of the ``skyfix run`` process per second of video (from ``/proc``, over the
video's span), its peak RSS (VmHWM), how busy the whole machine was meanwhile (``/proc/stat``: on a shared
machine a saturated host caps what the service gets), the frames its decoder skipped being behind (shared by
the UUVs); per UUV: **slot → GPS_INPUT** (each new valid fix's first arrival at its endpoint minus its frame's
stream slot, the exposure + the camera's latency), p50/p99, the service's own packet arrival → GPS_INPUT sent
(``--stats``: with several UUVs, ``uuvs.{id}.latency``), the frames its pipeline dropped (its tracker behind),
the share of frames sent its tracker had the UUV in (``tracked``) and with an ok fix, the MAE of the valid GPS_INPUT against its own truth and the frame
time error (a fix's time minus the nearest true exposure: a clock map gone wrong shows there), and how many
valid GPS_INPUT lie nearer another vehicle's truth than its own (an identity swap: GPS_INPUT names no vehicle,
so the autopilot would take the other's position).

``--nice -10 --policy other,rr`` runs each count under the normal policy and again realtime, interleaved, the service
started as deploy/skyfix.service starts it (``Nice=-10``) and asking for SCHED_RR as deploy/field.toml does
(:func:`bench.live_latency.realtime_args`); each run's scheduling is read back from ``/proc`` (the service's main
thread: ``RR 1`` or ``nice N``).

With ``--profile-s`` and py-spy on PATH (installed apart from the project), each run also samples which of the
service's threads holds the interpreter's lock, and where, for that long mid-video (``py-spy record --gil``):
the threads' and the top functions' shares of the samples are printed under the table.

Baselines in each round: decode only (PyAV demux + decode + BGR conversion per frame, offline, the live decoder's
settings: :func:`bench.live_latency.decode_baseline`), the floor of every run, and one UUV's per-frame work
(:meth:`groundstation.live.pipeline.Pipeline.process` of uuv1 on decoded frames, offline:
:func:`bench.live_latency.pipeline_baseline`), the work each UUV adds per frame. ``--rounds`` repeats (baselines,
each count) to show the spread on a noisy machine. Results: ``bench/results/uuvs.txt`` and ``.json``; the runs'
logs, configs, stats and each UUV's GPS_INPUT (``gps_input_ID.jsonl``) in ``/tmp/skyfix-bench/run_uuvs_rROUND_N/``.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import select
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
import tomllib
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

from emit import emit
from live_latency import (
    BENCH_DIR,
    CAMERA_LATENCY_MS,
    POLICY_HELP,
    decode_baseline,
    encode_as_camera,
    free_port,
    kill_left,
    nearest_times,
    nice_of,
    pct,
    pipeline_baseline,
    policies,
    priority_of,
    proc_sample,
    realtime_args,
)

from groundstation.config_files import read_toml
from groundstation.mavlink.ingest import (
    mavutil,  # pymavlink, set to MAVLink 2 before its first import
)
from groundstation.session.read import load_session, uuv_files
from localizer.geodesy import horizontal_error_m

SCENARIO = ROOT / "sim_fixtures" / "scenarios" / "three_uuvs_crossing.toml"
SIZE = (1920, 1080)
VEHICLES = ("uuv1", "uuv2", "uuv3")  # all in the video, each run
RUNS = {n: VEHICLES[:n] for n in (1, 2, 3)}


#: A frame's status when the tracker had no UUV in it (``localizer.tracking.TrackResult``'s words).
NOT_TRACKED = ("lost", "awaiting_target", "released")


def ensure_session(duration_s: float, size: tuple[int, int] = SIZE) -> Path:
    """The three_uuvs_crossing session at 30 fps (``size``: width, height; 1080p by default),
    three vehicles with their records (``uuvs/uuv2/``, ``uuvs/uuv3/``), generated once, its video as a camera sends
    it."""
    path = BENCH_DIR / f"uuvs3_{size[1]}p_{duration_s:g}s"
    if not (path / "video.ts").exists():
        from sim_fixtures.generate import generate
        from sim_fixtures.scenario import scenario_from_dict

        data = read_toml(SCENARIO)
        data["camera"] |= {"width": size[0], "height": size[1]}
        sc = scenario_from_dict(data | {"duration_s": duration_s}, str(SCENARIO))
        print(f"generating {path} (once) ...", flush=True)
        generate(sc, path, progress=True)
        encode_as_camera(path)
    return path


class GpsEndpoints:
    """Each UUV autopilot's GPS_INPUT port on 127.0.0.1 (bound here, so free): one thread reads them all, every
    GPS_INPUT as ``(arrival, message dict)``."""

    def __init__(self, ids):
        self.socks, self.parsers, self.received = {}, {}, {}
        for uuv_id in ids:
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            sock.bind(("127.0.0.1", 0))
            self.socks[uuv_id] = sock
            self.parsers[uuv_id] = mavutil().mavlink.MAVLink(None)
            self.parsers[uuv_id].robust_parsing = True
            self.received[uuv_id] = []
        self.ports = {uuv_id: s.getsockname()[1] for uuv_id, s in self.socks.items()}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._listen, name="gps endpoints", daemon=True)
        self._thread.start()

    def _listen(self) -> None:
        by_sock = {s: uuv_id for uuv_id, s in self.socks.items()}
        while not self._stop.is_set():
            ready, _, _ = select.select(list(by_sock), [], [], 0.2)
            for sock in ready:
                data = sock.recv(65535)
                t = time.time()
                uuv_id = by_sock[sock]
                for msg in self.parsers[uuv_id].parse_buffer(data) or ():
                    if msg.get_type() == "GPS_INPUT":
                        self.received[uuv_id].append((t, msg.to_dict()))

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5)
        for sock in self.socks.values():
            sock.close()


def run_toml(session: Path, ids, ports: dict, gps_ports: dict, stats: Path) -> str:
    """The ``skyfix run --config`` file: one ``[[uuv]]`` table per UUV, each with its depth key, its GPS_INPUT link
    and its first box."""
    text = (
        f'calibration = "{session / "session.toml"}"\nmavlink = "udpin:127.0.0.1:{ports["mav"]}"\n'
        f'video = "udp://127.0.0.1:{ports["video"]}"\nvideo_latency_ms = {CAMERA_LATENCY_MS}\n'
        f'zenoh_listen = ["tcp/127.0.0.1:{ports["zenoh"]}"]\nno_ui = true\nstats = "{stats}"\n'
    )
    for uuv_id in ids:
        box = tomllib.loads(uuv_files(session, uuv_id).tracker_toml.read_text())["tracker"][
            "init_bbox"
        ]
        text += (
            f'\n[[uuv]]\nid = "{uuv_id}"\ndepth_key = "bench/{uuv_id}/depth"\n'
            f'gps_input = "udpout:127.0.0.1:{gps_ports[uuv_id]}"\ninit_bbox = {list(box)}\n'
        )
    return text


def host_cpu() -> tuple[float, float]:
    """(busy, total) jiffies of the whole machine so far (``/proc/stat``)."""
    values = [int(v) for v in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]]
    idle = values[3] + values[4]  # idle, iowait
    return sum(values) - idle, sum(values)


def peak_rss_mb(pid: int) -> float:
    """The process's peak resident memory so far (VmHWM), MB."""
    return (
        next(
            int(line.split()[1])
            for line in Path(f"/proc/{pid}/status").read_text().splitlines()
            if line.startswith("VmHWM:")
        )
        / 1024.0
    )


def tracked_share(pipeline: dict, frames_sent: int) -> float:
    """The share of the frames sent that the UUV's tracker had the UUV in: processed, its status none of
    :data:`NOT_TRACKED` (an ok fix, or one vetoed after tracking: ``same_vehicle``, a pose's status)."""
    missed = sum(pipeline["statuses"].get(word, 0) for word in NOT_TRACKED)
    return round((pipeline["processed"] - missed) / frames_sent, 3)


def uuv_result(
    session: Path,
    uuv_id: str,
    own: dict,
    received: list,
    shift: float,
    to_station: float,
    frames_t: np.ndarray,
) -> dict:
    """One UUV's numbers: slot → GPS_INPUT at its endpoint, the service's arrival → sent, drops, ok share, MAE, and
    how far each fix's time lands from the nearest true exposure (``frames_t``, station clock)."""
    valid = {}
    for t_recv, g in sorted(
        received, key=lambda r: r[0]
    ):  # the first arrival of each new valid fix
        if g["fix_type"] == 3:
            valid.setdefault(g["time_usec"], (t_recv, g))
    keys = sorted(valid)
    t_exp = np.array(keys) / 1e6 + to_station  # the frame's exposure, station clock
    t_arrive = np.array([valid[k][0] for k in keys])
    t = t_exp - shift
    lat, lon = (np.array([valid[k][1][f] for k in keys]) / 1e7 for f in ("lat", "lon"))

    def error_m(truth_of: str) -> np.ndarray:
        truth = np.genfromtxt(uuv_files(session, truth_of).truth, delimiter=",", names=True)
        return horizontal_error_m(
            lat, lon, np.interp(t, truth["t"], truth["lat"]), np.interp(t, truth["t"], truth["lon"])
        )

    err = error_m(uuv_id)
    other = np.min([error_m(v) for v in VEHICLES if v != uuv_id], axis=0)
    pl = own["pipeline"]
    return {
        "gps_input_messages": len(received),
        "slot_to_gps_input_ms": pct(
            (t_arrive - t_exp - CAMERA_LATENCY_MS / 1000.0) * 1000.0, 50, 99
        )
        if keys
        else {"p50": None, "p99": None, "max": None, "n": 0},
        "arrival_to_sent_ms": own["latency"],
        "pipeline": {k: pl[k] for k in ("processed", "dropped", "held_for_telemetry", "statuses")},
        "ok_share": round(pl["statuses"].get("ok", 0) / len(frames_t), 3),
        "tracked_share": tracked_share(pl, len(frames_t)),
        "frame_time_error_ms": pct(np.abs(t_exp - nearest_times(frames_t, t_exp)) * 1000.0, 50, 99)
        if keys
        else {"p50": None, "p99": None, "max": None, "n": 0},
        "mae_m": round(float(err.mean()), 4) if keys else None,
        "max_err_m": round(float(err.max()), 4) if keys else None,
        "valid_fixes": len(err),
        # valid GPS_INPUT nearer another vehicle than its own
        "nearer_other_vehicle": int((other <= err).sum()),
    }


def gil_profile(pid: int, seconds: float, out: Path) -> subprocess.Popen | None:
    """py-spy (when on PATH: installed apart from the project) sampling, for ``seconds``, which of the process's
    threads holds the interpreter's lock and where (``--gil``), into ``out``; None without py-spy."""
    spy = shutil.which("py-spy")
    if spy is None or seconds <= 0:
        return None
    cmd = [spy, "record", "--gil", "--threads", "--nonblocking", "-r", "200", "-f", "raw"]
    return subprocess.Popen(
        [*cmd, "-d", str(round(seconds)), "-o", str(out), "-p", str(pid)],  # whole seconds only
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )


#: The service's frames every sample of its loop or threads passes through: left out of the functions' shares.
FRAMEWORK = ("cli.py", "command.py", "workers.py", "service.py", "threads.py")


def own(frame: str) -> str | None:
    """A py-spy frame (``function (path:line)``) as ``module.function`` when it is skyfix's own code (``localizer``,
    ``groundstation``, less :data:`FRAMEWORK`), else None."""
    name, _, where = frame.partition(" (")
    path = where.rsplit(":", 1)[0]
    for package in ("localizer/", "groundstation/"):
        if package in path and not path.endswith(FRAMEWORK):
            module = path[path.index(package) :].removesuffix(".py").replace("/", ".")
            return f"{module.rsplit('.', 1)[-1]}.{name}"
    return None


def gil_summary(raw: Path, top: int = 15) -> dict:
    """Shares of py-spy's samples holding the lock (its raw stacks: ``thread;frame;...;frame count``): per thread
    (by name) and per function of skyfix's own (inclusive, the ``top`` most)."""
    threads: dict[str, int] = {}
    functions: dict[str, int] = {}
    total = 0
    for line in raw.read_text().splitlines() if raw.exists() else []:
        stack, _, count = line.rpartition(" ")
        frames, n = stack.split(";"), int(count)
        total += n
        name = frames[0].split("): ", 1)[-1]
        threads[name] = threads.get(name, 0) + n
        for f in {own(f) for f in frames[1:]} - {None}:
            functions[f] = functions.get(f, 0) + n
    share = {k: round(v / total, 3) for k, v in sorted(threads.items(), key=lambda kv: -kv[1])}
    best = sorted(functions.items(), key=lambda kv: -kv[1])[:top]
    return {
        "samples": total,
        "threads": share,
        "functions": {k: round(v / total, 3) for k, v in best},
    }


def live(
    session: Path, work: Path, ids, profile_s: float = 0.0, nice: int = 0, realtime: bool = False
) -> dict:
    """One ``skyfix run`` with these UUVs, started at ``nice`` (with ``realtime``: asking for SCHED_RR), fed by
    ``skyfix replay``: its CPU and memory and each UUV's numbers (and, ``profile_s`` > 0 with py-spy on PATH, what
    held the interpreter's lock for that long mid-video)."""
    endpoints = GpsEndpoints(ids)  # first: the free ports below are not theirs
    ports = {"mav": free_port(), "video": free_port(), "zenoh": free_port(socket.SOCK_STREAM)}
    stats, config = work / "stats.json", work / "run.toml"
    config.write_text(run_toml(session, ids, ports, endpoints.ports, stats))
    py = sys.executable
    run = [*(["nice", "-n", str(nice)] if nice else []), py, "-m", "groundstation.cli", "run"]
    run += ["--config", str(config), *realtime_args(realtime)]
    replay = [
        py,
        "-m",
        "groundstation.cli",
        "replay",
        str(session),
        "--mavlink-out",
        f"udpout:127.0.0.1:{ports['mav']}",
        "--video-out",
        f"udp://127.0.0.1:{ports['video']}",
        "--video-delay-ms",
        str(CAMERA_LATENCY_MS),
        "--zenoh-connect",
        f"tcp/127.0.0.1:{ports['zenoh']}",
        "--depth-key",
        f"bench/{ids[0]}/depth",
        "--uuv-listen",
        "",
        "--lead-s",
        "2",
        *[a for uuv_id in ids[1:] for a in ("--uuv-depth-key", f"{uuv_id}=bench/{uuv_id}/depth")],
    ]
    samples = []  # (time, cpu_s, rss_mb, host busy jiffies, host jiffies)
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    load = os.getloadavg()[0]
    with open(work / "run.log", "w") as run_log, open(work / "replay.log", "w") as replay_log:
        service = subprocess.Popen(run, stdout=run_log, stderr=subprocess.STDOUT, cwd=ROOT, env=env)
        rep = None
        try:
            end = time.time() + 60
            while (work / "run.log").read_text().count("skyfix run: UAV") < len(
                ids
            ):  # every UUV's chain is up
                if service.poll() is not None or time.time() > end:
                    raise RuntimeError(
                        f"skyfix run did not start: {(work / 'run.log').read_text()[-2000:]}"
                    )
                time.sleep(0.2)
            time.sleep(1.0)
            service_nice = nice_of(service.pid)
            # its main thread's scheduling as it runs (it asked for the realtime policy as it started)
            scheduling = priority_of(Path(f"/proc/{service.pid}/stat"))
            rep = subprocess.Popen(
                replay, stdout=replay_log, stderr=subprocess.STDOUT, cwd=ROOT, env=env
            )
            spy, spy_at = None, time.time() + 5.0  # the replay's lead and the first frames past
            while rep.poll() is None:
                if profile_s > 0 and spy is None and time.time() > spy_at:
                    spy = gil_profile(service.pid, profile_s, work / "py-spy.txt") or False
                samples.append((time.time(), *proc_sample(service.pid), *host_cpu()))
                time.sleep(0.25)
            if spy:  # its samples are written when it ends
                spy.wait(profile_s + 30)
            peak_mb = peak_rss_mb(service.pid)
            service.send_signal(signal.SIGINT)
            service.wait(30)
        finally:
            kill_left(service, rep, spy or None)
            endpoints.close()
    for uuv_id, received in endpoints.received.items():
        (work / f"gps_input_{uuv_id}.jsonl").write_text(
            "".join(json.dumps({"t_recv": t, **g}) + "\n" for t, g in received)
        )
    final = json.loads(stats.read_text())
    shift = json.loads((work / "replay.log").read_text().splitlines()[0])["shift_s"]
    frames_t = load_session(session).frames["t"]
    n_frames = len(frames_t)
    # CPU over the video's span at the service: from the first frame's slot to a frame interval after the last's
    t0 = frames_t[0] + shift + CAMERA_LATENCY_MS / 1000.0
    t1 = frames_t[-1] + shift + CAMERA_LATENCY_MS / 1000.0 + 1.0 / 30.0
    s = np.array(samples)
    cpu_s, _, busy, total = (
        float(np.interp(t1, s[:, 0], s[:, k]) - np.interp(t0, s[:, 0], s[:, k]))
        for k in (1, 2, 3, 4)
    )
    to_station = (final.get("uav", {}).get("clocks", {}) or {}).get("station_minus_gnss_s") or 0.0
    per_uuv = final["uuvs"] if "uuvs" in final else {ids[0]: final}
    return {
        "uuvs": list(ids),
        "frames_sent": n_frames,
        "load_average": round(load, 2),
        "service_nice": service_nice,
        "scheduling": scheduling,
        "video": {
            k: final["video"][k]
            for k in (
                "frames",
                "skipped_behind",
                "decode_errors",
                "decode_ms",
                "arrival_after_slot_ms",
                "latency_from_motion",
            )
        },
        "station_minus_gnss_s": to_station,
        "cpu_s_per_video_s": round(cpu_s / (t1 - t0), 3),
        # the whole machine, every core, over the video's span
        "host_busy_pct": round(100.0 * busy / total, 1),
        "rss_mb": {"peak": round(peak_mb, 1), "end": round(float(s[-1, 2]), 1)},
        "gil_profile": gil_summary(work / "py-spy.txt") if profile_s > 0 else None,
        "per_uuv": {
            uuv_id: uuv_result(
                session,
                uuv_id,
                per_uuv[uuv_id],
                endpoints.received[uuv_id],
                shift,
                to_station,
                frames_t + shift,
            )
            for uuv_id in ids
        },
    }


def decode_only(session: Path) -> dict:
    """The decode-only baseline: per-frame ms and the CPU seconds per second of video it takes."""
    n_frames = len(load_session(session).frames["t"])
    c0, (busy0, total0) = time.process_time(), host_cpu()
    per_frame = decode_baseline(session)
    busy1, total1 = host_cpu()
    return {
        "per_frame_ms": per_frame,
        "cpu_s_per_video_s": round((time.process_time() - c0) / (n_frames / 30.0), 3),
        "host_busy_pct": round(100.0 * (busy1 - busy0) / (total1 - total0), 1),
    }


def one_tracker(session: Path, n_frames: int) -> dict:
    """The per-UUV baseline: per-frame ms of Pipeline.process (uuv1's tracker + pose + locate) on decoded frames,
    offline, and the CPU seconds per second of video of decoding and processing them."""
    c0, (busy0, total0) = time.process_time(), host_cpu()
    per_frame = pipeline_baseline(session, n_frames)
    busy1, total1 = host_cpu()
    return {
        "per_frame_ms": per_frame,
        "cpu_s_per_video_s": round((time.process_time() - c0) / (n_frames / 30.0), 3),
        "host_busy_pct": round(100.0 * (busy1 - busy0) / (total1 - total0), 1),
    }


def table(rounds: list[dict]) -> list[str]:
    """The table: per round, the decode-only baseline, then a row per run and UUV."""
    cols = [
        ("UUVs", 5),
        ("load", 4),
        ("nice", 4),
        ("sched", 7),
        ("CPU-s/video-s", 13),
        ("peak RSS MB", 11),
        ("host busy %", 11),
        ("decoder skipped", 15),
        ("UUV", 4),
        ("slot->GPS_INPUT p50/p99 ms (n)", 30),
        ("arrival->sent p50/p99 ms", 24),
        ("dropped", 7),
        ("tracked", 7),
        ("ok share", 8),
        ("MAE m", 6),
        ("nearer other", 12),
        ("t err p50 ms", 12),
    ]
    head = " | ".join(f"{name:>{w}}" for name, w in cols)
    lines = [head, "-" * len(head)]
    for r, rnd in enumerate(rounds):
        for key, what in (
            ("decode_only", "decode only (PyAV)"),
            ("one_tracker", "decode + Pipeline.process of uuv1, per frame the latter"),
        ):
            base = rnd[key]
            lines.append(
                f"{'base':>5} | {'':>4} | {'':>4} | {'':>7} | {base['cpu_s_per_video_s']:>13} | {'':>11} | {base['host_busy_pct']:>11} | "
                f"{what}, offline, round {r + 1}: per frame p50 {base['per_frame_ms']['p50']} ms, "
                f"p99 {base['per_frame_ms']['p99']} ms"
            )
        for res in rnd["runs"].values():
            for i, (uuv_id, u) in enumerate(res["per_uuv"].items()):
                lat, a = u["slot_to_gps_input_ms"], u["arrival_to_sent_ms"]
                run = (
                    (
                        len(res["uuvs"]),
                        res["load_average"],
                        res.get("service_nice", "?"),
                        res.get("scheduling", "?"),
                        res["cpu_s_per_video_s"],
                        res["rss_mb"]["peak"],
                        res["host_busy_pct"],
                        f"{res['video']['skipped_behind']}/{res['frames_sent']}",
                    )
                    if i == 0
                    else ("",) * 8
                )
                row = (
                    *run,
                    uuv_id,
                    f"{lat['p50']} / {lat['p99']} ({lat['n']})",
                    f"{a['p50_ms']} / {a['p99_ms']}",
                    u["pipeline"]["dropped"],
                    u.get("tracked_share", tracked_share(u["pipeline"], res["frames_sent"])),
                    u["ok_share"],
                    u["mae_m"],
                    u["nearer_other_vehicle"],
                    u["frame_time_error_ms"]["p50"],
                )
                lines.append(" | ".join(f"{v!s:>{w}}" for v, (_, w) in zip(row, cols, strict=True)))
        lines.append("")
    return lines


def profiles(rounds: list[dict]) -> list[str]:
    """The lock profiles (``--profile-s``): per run, the threads' and the top functions' shares of the samples."""
    lines = []
    for r, rnd in enumerate(rounds):
        for n, res in rnd["runs"].items():
            p = res.get("gil_profile")
            if not p:
                continue
            lines.append(
                f"round {r + 1}, {n}: {p['samples']} samples of the thread holding the interpreter's lock"
            )
            lines.append("  threads: " + ", ".join(f"{k} {v:.1%}" for k, v in p["threads"].items()))
            lines.append(
                "  functions: " + ", ".join(f"{k} {v:.1%}" for k, v in p["functions"].items())
            )
    return lines


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--counts", default="1,2,3", help="comma-separated numbers of UUVs: 1, 2, 3")
    ap.add_argument(
        "--rounds",
        type=int,
        default=1,
        help="rounds of (decode only, each count), one after another: "
        "on a noisy machine, the spread between rounds",
    )
    ap.add_argument(
        "--baseline-frames", type=int, default=150, help="frames of the Pipeline.process baseline"
    )
    ap.add_argument(
        "--duration-s", type=float, default=20.0, help="session length (generated once per length)"
    )
    ap.add_argument(
        "--profile-s",
        type=int,
        default=0,
        help="with py-spy on PATH: sample what holds the interpreter's lock in skyfix run for this long "
        "mid-video, per thread and function (0: no profile)",
    )
    ap.add_argument(
        "--nice",
        type=int,
        default=0,
        help="start the service at this nice value (`nice -n`, as deploy/skyfix.service's Nice=; negative: root)",
    )
    ap.add_argument(
        "--policy", type=policies, default="other", metavar="other,rr", help=POLICY_HELP
    )
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "uuvs.txt")
    args = ap.parse_args()
    session = ensure_session(args.duration_s)
    lines = [
        (
            f"skyfix several-UUV benchmark, {time.strftime('%Y-%m-%d %H:%M:%S %Z')}, {os.cpu_count()} cores, "
            f"load average {os.getloadavg()[0]:.1f}"
        ),
        (
            f"{session.name}: three_uuvs_crossing at {SIZE[0]}x{SIZE[1]} 30 fps, MPEG-TS over UDP, camera latency "
            f"{CAMERA_LATENCY_MS} ms; runs: "
            + "; ".join(f"{n}: {', '.join(RUNS[n])}" for n in RUNS)
        ),
        (
            "three distinct vehicles in the video in every run: uuv3 is [third_uuv] "
            + ", ".join(
                f"{k} = {v}"
                for k, v in read_toml(SCENARIO)["third_uuv"].items()
                if k not in ("enabled", "role", "id")
            )
            + f"; the service at nice {args.nice} (`nice -n`, as deploy/skyfix.service's Nice=) under "
            + " and ".join(
                {"other": "the normal policy", "rr": "SCHED_RR 1"}[p] for p in args.policy
            )
            + " (sched: its main thread's, read back per run)"
        ),
        (
            "CPU-s/video-s: the skyfix run process over the video's span (decode only: this process, offline); "
            "host busy %: the whole machine, all cores, meanwhile;"
        ),
        (
            "decoder skipped: frames the service decoded but did not hand on, its decoder behind (of those sent); "
            "dropped: frames the UUV's pipeline dropped, its tracker behind;"
        ),
        (
            "tracked: frames its tracker had the UUV in / frames sent; "
            "target with 3 UUVs: >= 0.95 each, slot->GPS_INPUT p99 <= 60 ms;"
        ),
        (
            "ok share: the UUV's ok fixes / frames sent; MAE: valid GPS_INPUT at its endpoint vs its own truth; "
            "t err: |a fix's time - the nearest true exposure|;"
        ),
        (
            "nearer other: valid GPS_INPUT nearer another vehicle's truth than its own, an identity swap; "
            "load: the load average at the run's start (a shared machine)."
        ),
        "",
    ]
    rounds = []
    for r in range(args.rounds):
        rnd = {
            "decode_only": decode_only(session),
            "one_tracker": one_tracker(session, args.baseline_frames),
            "runs": {},
        }
        rounds.append(rnd)
        for n, policy in itertools.product((int(c) for c in args.counts.split(",")), args.policy):
            name = f"{n} UUV(s){' rr' if policy == 'rr' else ''}"
            work = BENCH_DIR / f"run_uuvs_r{r + 1}_{n}{'_rr' if policy == 'rr' else ''}"
            shutil.rmtree(work, ignore_errors=True)
            work.mkdir(parents=True)
            print(f"round {r + 1}, {name}: {', '.join(RUNS[n])} ...", flush=True)
            rnd["runs"][name] = live(
                session, work, RUNS[n], args.profile_s, args.nice, policy == "rr"
            )
    emit(lines + table(rounds) + profiles(rounds), args.out, rounds)
    return 0


if __name__ == "__main__":
    sys.exit(main())

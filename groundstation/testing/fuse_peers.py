"""Drones and strangers on Zenoh for ``skyfix fuse`` on loopback (tests/test_fusion.py, bench/fuse_attacks.py).

A real ``skyfix fuse`` process listens on a loopback port; this process is every peer around it in one Zenoh session:
it publishes each drone's fixes at 30 fps in real time (the UUV going north at :data:`SPEED_MPS` from
(:data:`LAT0`, :data:`LON0`); each drone with its own constant offset, white scatter and claimed sigma; a fix's time
is its publication's), one-off fixes stamped ahead, and subscribes to the fused fixes. GPS_INPUT goes to a UUV
endpoint of this process (``GpsInputEndpoint``). Positions by pyproj's geodesic, not skyfix's geodesy.
"""

from __future__ import annotations

import json
import math
import socket
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import zenoh
from pyproj import Geod

from groundstation.messages import FixMessage
from groundstation.testing.live import GpsInputEndpoint, free_port, skyfix, start, stop, wait_for
from localizer.fix import Fix
from localizer.uncertainty import H_ACC_PER_SIGMA_ISOTROPIC

LAT0, LON0 = 63.44, 10.40
SPEED_MPS = 0.3  # the UUV goes north
FPS = 30.0
UUV = "rov1"
GEOD = Geod(ellps="WGS84")


def key(drone: str) -> str:
    return f"skyfix/uuv/{UUV}/drone/{drone}/fix"


@dataclass(frozen=True)
class Drone:
    """One publisher of fixes: ``offset_ne_m`` from the UUV (m), ``white_m`` its scatter and ``sigma_m`` its claim
    (1-sigma per axis, m); ``walk_ne_mps`` (m/s) moves its offset on from ``walk_from_s`` after the stream's start;
    ``silent_s``: (from, to) seconds after the start without fixes; ``sigma_uav_m``: its GNSS sigma as its fix
    message carries it (NaN: none)."""

    name: str
    offset_ne_m: tuple[float, float] = (0.0, 0.0)
    white_m: float = 0.02
    sigma_m: float = 0.1
    walk_ne_mps: tuple[float, float] = (0.0, 0.0)
    walk_from_s: float = 0.0
    silent_s: tuple[float, float] | None = None
    sigma_uav_m: float = math.nan


def geodetic(n_m: float, e_m: float) -> tuple[float, float]:
    lon, lat, _ = GEOD.fwd(LON0, LAT0, math.degrees(math.atan2(e_m, n_m)), math.hypot(n_m, e_m))
    return lat, lon


def error_ne_m(lat: float, lon: float, t: float, t0: float) -> tuple[float, float]:
    """A position's offset (m, north and east) from the UUV's at ``t`` (it left the origin at ``t0``)."""
    az, _, dist = GEOD.inv(LON0, LAT0, lon, lat)
    return dist * math.cos(math.radians(az)) - SPEED_MPS * (t - t0), dist * math.sin(
        math.radians(az)
    )


def payload(
    drone: Drone, t: float, t0: float, rng: np.random.Generator, ahead_s: float = 0.0
) -> bytes:
    """The drone's fix message of the UUV at ``t`` (stamped ``ahead_s`` later)."""
    walked = np.array(drone.walk_ne_mps) * max(0.0, t - t0 - drone.walk_from_s)
    n, e = np.array(drone.offset_ne_m) + walked + rng.normal(0.0, drone.white_m, 2)
    lat, lon = geodetic(SPEED_MPS * (t - t0) + n, e)
    s = drone.sigma_m
    fix = Fix(
        t_unix=t + ahead_s,
        status="ok",
        lat=lat,
        lon=lon,
        alt_amsl_m=-0.9,
        v_acc_m=0.3,
        depth_m=1.3,
        t_gnss=t + ahead_s,
        h_acc_m=H_ACC_PER_SIGMA_ISOTROPIC * s,
        sigma_n_m=s,
        sigma_e_m=s,
        cov_ne_m2=0.0,
        sigma_uav_m=drone.sigma_uav_m,
        frame=0,
    )
    return json.dumps(FixMessage.of(fix).to_json()).encode()


class FuserOnLoopback:
    """``skyfix fuse --source …`` on a loopback port with GPS_INPUT to this process, and a session around it."""

    def __init__(self, work: Path, sources: list[str], *extra: str):
        self.work = work
        self.stats = work / "fuse.json"
        self.log = work / "fuse.log"
        port = free_port(socket.SOCK_STREAM)
        self.uuv = GpsInputEndpoint()
        self.proc = start(
            skyfix(
                "fuse",
                "--uuv",
                UUV,
                *[a for s in sources for a in ("--source", s)],
                "--zenoh-listen",
                f"tcp/127.0.0.1:{port}",
                "--gps-input",
                f"udpout:127.0.0.1:{self.uuv.port}",
                "--stats",
                str(self.stats),
                "--duration-s",
                "600",
                *extra,
            ),
            self.log,
        )
        conf = zenoh.Config()
        conf.insert_json5("mode", '"peer"')
        conf.insert_json5("scouting/multicast/enabled", "false")
        conf.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
        self.session = zenoh.open(conf)
        self.fused: list[dict] = []  # the fused fix messages, as received
        self.statuses: list[dict] = []
        self._subs = [
            self.session.declare_subscriber(
                f"skyfix/uuv/{UUV}/fix",
                lambda s: self.fused.append(json.loads(s.payload.to_bytes())),
            ),
            self.session.declare_subscriber(
                f"skyfix/uuv/{UUV}/fuse/status",
                lambda s: self.statuses.append(json.loads(s.payload.to_bytes())),
            ),
        ]
        self.publishers: dict[str, zenoh.Publisher] = {}
        wait_for(
            lambda: self.statuses or self.proc.poll() is not None, 60, "the fuser's first status"
        )
        assert self.proc.poll() is None, self.log.read_text()[-3000:]

    def stream(
        self,
        drones: list[Drone],
        seconds: float,
        t0: float,
        seed: int = 1,
        ahead: dict[float, tuple[str, float]] | None = None,
    ) -> None:
        """Each drone's fixes at :data:`FPS` for ``seconds`` in real time; ``ahead``: at that many seconds after
        ``t0``, one more fix of drone (name) stamped that far (s) ahead."""
        rng = np.random.default_rng(seed)
        pending = sorted((ahead or {}).items())
        start_t = time.time()
        for k in range(int(seconds * FPS)):
            tick = start_t + k / FPS
            time.sleep(max(0.0, tick - time.time()))  # the cameras' frame rate
            for d in drones:
                t = time.time()
                if d.silent_s and d.silent_s[0] <= t - t0 < d.silent_s[1]:
                    continue
                self._put(d.name, payload(d, t, t0, rng))
            while pending and time.time() - t0 >= pending[0][0]:
                _, (name, ahead_s) = pending.pop(0)
                drone = next(d for d in drones if d.name == name)
                self._put(name, payload(drone, time.time(), t0, rng, ahead_s))

    def _put(self, name: str, data: bytes) -> None:
        if name not in self.publishers:
            self.publishers[name] = self.session.declare_publisher(key(name))
        self.publishers[name].put(data)

    def close(self) -> dict:
        """Stop the fuser; its final status."""
        try:
            stop(self.proc)
        finally:
            for p in [*self.publishers.values(), *self._subs]:
                p.undeclare()
            self.session.close()
            self.uuv.close()
        assert self.proc.returncode == 0, self.log.read_text()[-3000:]
        return json.loads(self.stats.read_text())


def ok_errors(fused: list[dict], t0: float) -> np.ndarray:
    """(north, east, h_acc) of each ok fused fix against the truth at its time."""
    return np.array(
        [
            (*error_ne_m(f["lat"], f["lon"], f["t_gnss"], t0), f["h_acc_m"])
            for f in fused
            if f["status"] == "ok"
        ]
    ).reshape(-1, 3)


def gps_input_errors_m(received: list[tuple[float, dict]], t0: float) -> np.ndarray:
    """The distance (m) of each 3D GPS_INPUT from the UUV when the endpoint's kernel received it."""
    return np.array(
        [
            math.hypot(*error_ne_m(m["lat"] / 1e7, m["lon"] / 1e7, t, t0))
            for t, m in received
            if m["fix_type"] >= 3
        ]
    )


def run_fuser(
    work: Path,
    sources: list[str],
    drones: list[Drone],
    seconds: float,
    ahead: dict[float, tuple[str, float]] | None = None,
    *extra: str,
) -> tuple[dict, list[dict], list, float]:
    """The fuser taking ``sources`` while ``drones`` publish for ``seconds``: its final status, the fused fix messages,
    the GPS_INPUT received and the stream's ``t0``."""
    work.mkdir(parents=True, exist_ok=True)
    fuser = FuserOnLoopback(work, sources, *extra)
    try:
        t0 = time.time()
        fuser.stream(drones, seconds, t0, ahead=ahead)
        wait_for(
            lambda: (
                fuser.fused
                and fuser.fused[-1]["t"] >= t0 + seconds - 0.5
                or fuser.proc.poll() is not None
            ),
            30,
            "the fused fixes to catch up",
        )
    finally:
        final = fuser.close()
    return final, fuser.fused, list(fuser.uuv.received), t0

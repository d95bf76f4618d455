"""ArduPilot's ArduSub firmware (SITL) for the tests that put it in the loop: finding the binary, starting it
on free ports in a scratch directory, and a ground station on one of its serial ports (:class:`Observer`).

The binary is ``$SKYFIX_ARDUSUB``, else ``../shared/tools/ardusub/ardusub`` next to the project; without
either the tests are skipped. ArduPilot's ``sub.parm`` must lie next to the binary
(``deploy/build_ardusub.sh`` builds both). ArduCopter (:class:`ArduCopter`, the UAV with a gimbal, writing
DataFlash logs) the same way: ``$SKYFIX_ARDUCOPTER``, else ``../shared/tools/arducopter/arducopter``, with
``copter.parm`` and ``mount_brushless.parm`` beside it.
"""

from __future__ import annotations

import os
import random
import signal
import socket
import subprocess
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest
from ahead import Render, Renders
from live_helpers import ROOT, wait_for
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

DEFAULT_ARDUSUB = ROOT.parent / "shared" / "tools" / "ardusub" / "ardusub"
DEFAULT_ARDUCOPTER = ROOT.parent / "shared" / "tools" / "arducopter" / "arducopter"

# ArduSub's README (../shared/tools/ardusub/README.md): positions from GPS_INPUT, no simulated GPS,
# EKF3 horizontal position from the GPS, height from the barometer (depth), yaw from the compass.
EXTRA_PARM = """\
GPS1_TYPE 14
GPS1_DELAY_MS 65
SIM_GPS1_ENABLE 0
EK3_SRC1_POSXY 3
EK3_SRC1_VELXY 0
EK3_SRC1_POSZ 1
EK3_SRC1_VELZ 0
EK3_SRC1_YAW 1
"""


def _sitl_files(
    variable: str, default: Path, parms: tuple[str, ...]
) -> tuple[Path, tuple[Path, ...]]:
    given = os.environ.get(variable)
    if not given and not default.exists():
        pytest.skip(
            f"{default.name} SITL not found: set {variable} to its binary or provide {default}"
        )
    binary = Path(given) if given else default
    assert binary.is_file() and os.access(binary, os.X_OK), (
        f"{variable}={binary}: not an executable file"
    )
    files = tuple(binary.parent / p for p in parms)
    for f in files:
        assert f.is_file(), f"{f} missing: it must lie next to the binary"
    return binary, files


def ardusub_files() -> tuple[Path, Path]:
    """The binary and its ``sub.parm`` (ArduPilot's Tools/autotest/default_params; deploy/build_ardusub.sh copies
    it): skip when neither ``$SKYFIX_ARDUSUB`` nor the default exists."""
    binary, (parm,) = _sitl_files("SKYFIX_ARDUSUB", DEFAULT_ARDUSUB, ("sub.parm",))
    return binary, parm


def arducopter_files() -> tuple[Path, tuple[Path, ...]]:
    """ArduCopter's binary, ``copter.parm`` and ``mount_brushless.parm`` (a gimbal): skip without them."""
    return _sitl_files(
        "SKYFIX_ARDUCOPTER", DEFAULT_ARDUCOPTER, ("copter.parm", "mount_brushless.parm")
    )


def _port_free(port: int, kind: int) -> bool:
    with socket.socket(socket.AF_INET, kind) as s:
        try:
            s.bind(("0.0.0.0", port))  # ArduSub SITL binds every interface
        except OSError:
            return False
    return True


def instance_ports(n: int) -> dict:
    """ArduSub SITL's ports for ``-I n``: TCP SERIAL0/1/2, UDP RC input."""
    return {
        "serial0": 5760 + 10 * n,
        "serial1": 5762 + 10 * n,
        "serial2": 5763 + 10 * n,
        "rc_in": 5501 + 10 * n,
    }


def free_instance(exclude: set[int]) -> int:
    for n in random.sample(range(10, 100), 90):
        p = instance_ports(n)
        if (
            n not in exclude
            and all(_port_free(p[k], socket.SOCK_STREAM) for k in ("serial0", "serial1", "serial2"))
            and _port_free(p["rc_in"], socket.SOCK_DGRAM)
        ):
            return n
    raise AssertionError("no free ArduSub SITL instance (ports 5860-6753 busy)")


class Observer:
    """A GCS on one ArduSub serial port: every message it receives, stamped with its receive time (UNIX s)."""

    KEEP = (
        "HEARTBEAT",
        "STATUSTEXT",
        "COMMAND_ACK",
        "GPS_INPUT",
        "GPS_RAW_INT",
        "GLOBAL_POSITION_INT",
        "EKF_STATUS_REPORT",
    )

    def __init__(self, port: int, keep: tuple[str, ...] = KEEP):
        self.keep = keep
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=5.0)
        self.sock.settimeout(0.5)
        self.rx = mavlink2.MAVLink(None)
        self.rx.robust_parsing = True
        self.tx = mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)
        self.msgs: list[tuple[float, object]] = []
        self.closed = False
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._threads = [
            threading.Thread(target=self._read, name="observer-rx", daemon=True),
            threading.Thread(target=self._heartbeat, name="observer-hb", daemon=True),
        ]
        for th in self._threads:
            th.start()

    def _read(self) -> None:
        while not self._stop.is_set():
            try:
                data = self.sock.recv(65536)
            except TimeoutError:
                continue
            except OSError:
                break
            if not data:
                break
            t = time.time()
            for m in self.rx.parse_buffer(data) or ():
                if m.get_type() in self.keep:
                    self.msgs.append((t, m))
        self.closed = True

    def _heartbeat(
        self,
    ) -> None:  # a GCS heartbeat: ArduSub learns a route to us and forwards broadcasts
        while True:
            self.send(
                mavlink2.MAVLink_heartbeat_message(
                    mavlink2.MAV_TYPE_GCS, mavlink2.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3
                )
            )
            if self._stop.wait(1.0):
                return

    def send(self, msg) -> None:
        with self._lock:
            try:
                self.sock.sendall(msg.pack(self.tx))
            except OSError:
                pass

    def of(self, kind: str, since: float = 0.0) -> list[tuple[float, object]]:
        return [(t, m) for t, m in list(self.msgs) if t >= since and m.get_type() == kind]

    def request_interval(self, msg_id: int, hz: float, timeout_s: float = 20.0) -> None:
        """MAV_CMD_SET_MESSAGE_INTERVAL, repeated until ArduSub accepts it."""
        end = time.time() + timeout_s
        while time.time() < end:
            t_sent = time.time()
            self.send(
                mavlink2.MAVLink_command_long_message(
                    1, 1, mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL, 0, msg_id, 1e6 / hz, 0, 0, 0, 0, 0
                )
            )
            try:
                wait_for(
                    lambda t=t_sent: any(
                        m.command == mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL and m.result == 0
                        for _, m in self.of("COMMAND_ACK", t)
                    ),
                    2.0,
                    "ack",
                )
                return
            except AssertionError:
                continue
        raise AssertionError(f"ArduSub did not accept a {hz} Hz interval for message {msg_id}")

    def close(self) -> None:
        self._stop.set()
        for th in self._threads:
            th.join(2.0)
        self.sock.close()


class ArduSub:
    """ArduSub SITL in a scratch directory; :attr:`observer` is connected to SERIAL0, SERIAL1 is free.
    ``parms``: the parameter files before ``extra_parm`` (``sub.parm``)."""

    MODEL = "vectored"

    def __init__(
        self,
        binary: Path,
        parms: Path | tuple[Path, ...],
        workdir: Path,
        home: tuple[float, float, float, float],
        extra_parm: str = EXTRA_PARM,
        keep: tuple[str, ...] = Observer.KEEP,
    ):
        self.binary, self.dir, self.home, self.keep = binary, workdir, home, keep
        self.parms = (parms,) if isinstance(parms, Path) else tuple(parms)
        self.dir.mkdir(parents=True, exist_ok=True)
        (self.dir / "extra.parm").write_text(extra_parm)
        self.proc: subprocess.Popen | None = None
        self.observer: Observer | None = None
        self.ports: dict = {}
        self.log = self.dir / "ardusub.log"  # one per attempt: ardusub-I<N>.log
        self.instance: int | None = None

    def start(self, attempts: int = 3, instance: int | None = None) -> None:
        """Start on a free instance (``instance``: on that one, e.g. again after :meth:`stop`)."""
        tried: set[int] = set()
        for _ in range(attempts):
            n = free_instance(tried) if instance is None else instance
            tried.add(n)
            self.ports, self.instance = instance_ports(n), n
            self.log = self.dir / f"ardusub-I{n}-{len(list(self.dir.glob('ardusub-*.log')))}.log"
            cmd = [
                str(self.binary),
                "--model",
                self.MODEL,
                "--speedup",
                "1",
                "-w",
                f"-I{n}",
                "--home",
                ",".join(f"{v:g}" for v in self.home),
                "--defaults",
                ",".join(str(p) for p in (*self.parms, self.dir / "extra.parm")),
            ]
            with open(self.log, "w") as log:
                log.write(" ".join(cmd) + "\n")
                log.flush()
                self.proc = subprocess.Popen(
                    cmd,
                    cwd=self.dir,
                    stdout=log,
                    stderr=subprocess.STDOUT,
                    stdin=subprocess.DEVNULL,
                )
            if self._connect():
                wait_for(
                    lambda: self.observer.of("HEARTBEAT") or self.proc.poll() is not None,
                    30,
                    "ArduSub's first heartbeat",
                )
                if self.proc.poll() is None:
                    return
            self.stop()  # the port was taken meanwhile (bind failed), or it died: another instance
        raise AssertionError(f"ArduSub SITL did not start:\n{self.tail()}")

    def _connect(self, timeout_s: float = 30.0) -> bool:
        end = time.time() + timeout_s
        while time.time() < end and self.proc.poll() is None:
            if (
                "SERIAL0 on TCP port" in self.log.read_text()
            ):  # bound: it waits for this connection to boot
                try:
                    self.observer = Observer(self.ports["serial0"], self.keep)
                    return True
                except OSError:
                    pass
            time.sleep(0.1)
        return False

    def boot_s(self) -> float:
        """ArduSub's uptime (its own clock: GLOBAL_POSITION_INT.time_boot_ms)."""
        gpi = self.observer.of("GLOBAL_POSITION_INT")
        return gpi[-1][1].time_boot_ms / 1000.0 if gpi else 0.0

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def tail(self, n: int = 3000) -> str:
        return self.log.read_text()[-n:] if self.log.exists() else ""

    def stop(self) -> None:
        if self.observer is not None:
            self.observer.close()
            self.observer = None
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


class ArduCopter(ArduSub):
    """ArduCopter SITL (a quad; with ``mount_brushless.parm`` a gimbal), started as :class:`ArduSub`; its DataFlash
    logs are in ``logs/`` of its directory."""

    MODEL = "quad"


class Booting:
    """:meth:`ArduSub.start` in a thread of its own (the test goes on meanwhile), then ``then(sitl)`` if given (the
    message rates a test asks for from the boot on); :meth:`ready` waits for it and raises what it raised."""

    def __init__(self, sitl: ArduSub, then: Callable[[ArduSub], None] | None = None):
        self.sitl, self.then = sitl, then
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._start, name="sitl-boot", daemon=True)
        self.thread.start()

    def _start(self) -> None:
        try:
            self.sitl.start()
            if self.then is not None:
                self.then(self.sitl)
        except BaseException as e:  # noqa: BLE001 - handed to the test by ready()
            self.error = e

    def ready(self) -> ArduSub:
        self.thread.join()
        if self.error is not None:
            raise self.error
        return self.sitl

    def close(self) -> None:
        self.thread.join()
        self.sitl.stop()


@dataclass
class Prepared:
    """Sessions being rendered by ``skyfix sim`` (``renders``: name → the render into ``dir/name``, since
    ``t_start``) and an autopilot booting: a SITL test's slow beginnings (``tests/ahead.py``)."""

    dir: Path
    renders: Renders
    t_start: float
    boot: Booting

    def close(self) -> None:
        self.renders.close()
        self.boot.close()


def render_and_boot(
    tmp: Path, scenarios: dict[str, str], sitl: ArduSub, background: bool
) -> Prepared:
    """Start rendering each scenario (name → TOML text) into ``tmp/name`` (log ``tmp/sim_name.log``), in the
    ``background`` or not (:class:`ahead.Render`), and booting ``sitl``."""
    t_start, renders = time.time(), Renders()
    for name, text in scenarios.items():
        (tmp / f"{name}.toml").write_text(text)
        renders[name] = Render(
            tmp / f"{name}.toml", tmp / name, tmp / f"sim_{name}.log", background
        )
    return Prepared(tmp, renders, t_start, Booting(sitl))

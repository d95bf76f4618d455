"""A stand-in for systemd running ``deploy/skyfix.service`` (no systemd runs in a test's container), and the shipped
``deploy/field.toml`` with only its endpoints replaced: what tests/test_live_restart.py and bench/restart.py run.

:class:`Supervisor` reads the unit's own ``ExecStart``, ``Restart``, ``RestartSec``, ``StartLimitIntervalSec`` and
``StartLimitBurst`` and does what systemd does with them: start the command; when it ends in failure (a non-zero
exit code or a signal, ``Restart=on-failure``) start it again ``RestartSec`` later; give up after ``StartLimitBurst``
starts within ``StartLimitIntervalSec``; a clean exit (0) is not restarted.
"""

from __future__ import annotations

import configparser
import json
import re
import shlex
import socket
import subprocess
import threading
import time
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Self

from groundstation.testing.live import ROOT, free_port, start, stop

DEPLOY = ROOT / "deploy"
UNIT = DEPLOY / "skyfix.service"
_SPAN = re.compile(r"(\d+(?:\.\d+)?)\s*(ms|s|sec|min|)")
_SPAN_S = {"ms": 0.001, "s": 1.0, "sec": 1.0, "": 1.0, "min": 60.0}


def systemd_seconds(text: str) -> float:
    """A systemd time span (``1``, ``500ms``, ``2s``, ``1min 30s``) in seconds."""
    parts = _SPAN.findall(text)
    if not parts or _SPAN.sub("", text).strip():
        raise ValueError(f"not a time span systemd reads: {text!r}")
    return sum(float(n) * _SPAN_S[unit] for n, unit in parts)


def read_unit(path: Path = UNIT) -> configparser.ConfigParser:
    unit = configparser.ConfigParser(strict=False, interpolation=None)
    unit.optionxform = str  # systemd's keys are case-sensitive
    unit.read(path)
    return unit


def field_config(tmp: Path, gps_input_port: int) -> tuple[Path, dict]:
    """``deploy/field.toml`` as written, its endpoints on loopback (free ports; GPS_INPUT to ``gps_input_port``), the
    calibration beside it, the recordings in ``tmp``, its Zenoh configuration's keys made in ``tmp/team`` by
    ``deploy/make_certs.sh``: the file and its values."""
    values = tomllib.loads((DEPLOY / "field.toml").read_text())
    subprocess.run(
        [str(DEPLOY / "make_certs.sh"), str(tmp / "team"), "skyfix=127.0.0.1"],
        check=True,
        capture_output=True,
        timeout=60,
    )  # this laptop's keys, where /etc/skyfix/tls/ has them
    zenoh = tmp / "peer.json5"
    zenoh.write_text(
        (DEPLOY / values["zenoh_config"])
        .read_text()
        .replace("/etc/skyfix/tls/", f"{tmp}/team/skyfix/")
    )
    values |= {
        "calibration": str(DEPLOY / values["calibration"]),
        "zenoh_config": str(zenoh),
        "mavlink": f"udpin:127.0.0.1:{free_port()}",
        "video": f"rtp://127.0.0.1:{free_port()}?codec=h264",
        "zenoh_connect": [],
        "zenoh_listen": [f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"],
        "gps_input": f"udpout:127.0.0.1:{gps_input_port}",
        "ui": "127.0.0.1:0",
        "recordings": str(tmp / "recordings"),
    }
    path = tmp / "field.toml"
    # JSON's strings, numbers, lists
    path.write_text("".join(f"{k} = {json.dumps(v)}\n" for k, v in values.items()))
    return path, values


class Supervisor:
    """The unit's command under its restart policy (see the module doc), from ``with`` to its end. ``starts`` holds
    each start's (time, process), ``exits`` each exit code in order (a signal: minus its number)."""

    def __init__(self, argv: Callable[[list[str]], list[str]], log_dir: Path, unit: Path = UNIT):
        u = read_unit(unit)
        if u["Service"]["Restart"] != "on-failure":
            raise ValueError(
                f"{unit}: Restart={u['Service']['Restart']}: this stand-in knows on-failure only"
            )
        self.restart_s = systemd_seconds(u["Service"]["RestartSec"])
        self.limit_s = systemd_seconds(u["Unit"]["StartLimitIntervalSec"])
        self.burst = int(u["Unit"]["StartLimitBurst"])
        self.command = argv(shlex.split(u["Service"]["ExecStart"]))
        self.log_dir = log_dir
        self.starts: list[tuple[float, subprocess.Popen]] = []
        self.exits: list[int] = []
        self.gave_up = False
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="supervisor", daemon=True)

    def __enter__(self) -> Self:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        with self._lock:
            self._stop.set()
            current = self.starts[-1][1] if self.starts else None
        if current is not None:
            stop(current, timeout_s=20)
        self._thread.join(30)

    def log(self, i: int) -> Path:
        """The output of the ``i``-th start."""
        return self.log_dir / f"start{i}.log"

    def _loop(self) -> None:
        while True:
            with self._lock:
                if self._stop.is_set():
                    return
                now = time.time()
                if sum(t > now - self.limit_s for t, _ in self.starts) >= self.burst:
                    self.gave_up = True
                    return
                proc = start(self.command, self.log(len(self.starts)))
                self.starts.append((now, proc))
            code = proc.wait()
            self.exits.append(code)
            if code == 0 or self._stop.wait(self.restart_s):
                return

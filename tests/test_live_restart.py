"""Restarts that come back: every start of ``skyfix run`` records into a folder of its own (``recordings``), so the
shipped configuration never refuses to start because of an earlier recording; and ``deploy/skyfix.service``'s
restart policy, run by a stand-in supervisor (tests/supervisor.py), brings the service back after ``kill -9``: a
GPS_INPUT heard again each time. The times are bench/restart.py's."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import tomllib

from live_helpers import ROOT, GpsInputEndpoint, skyfix, wait_for

from groundstation.live.sinks.recorder import new_recording
from groundstation.testing.supervisor import Supervisor, field_config

FOLDER = re.compile(r"^\d{8}-\d{6}(-\d+)?$")


def test_starts_in_one_second_get_folders_of_their_own(tmp_path):
    t = 1_750_000_000.25  # 2025-06-15 15:06:40 UTC
    made = [new_recording(tmp_path / "rec", t) for _ in range(3)]
    assert [p.name for p in made] == ["20250615-150640", "20250615-150640-2", "20250615-150640-3"]
    assert all(p.is_dir() and not any(p.iterdir()) for p in made)
    (made[1] / "session.toml").write_text("version = 1\n")
    # nothing made earlier is reused
    assert new_recording(tmp_path / "rec", t).name == "20250615-150640-4"


def _recordings(root) -> list:
    return sorted(p for p in root.iterdir()) if root.exists() else []


def test_the_same_configuration_started_three_times_records_three_folders(tmp_path):
    endpoint = GpsInputEndpoint()
    try:
        config, _ = field_config(tmp_path, endpoint.port)
        outs = [
            subprocess.run(
                skyfix("run", "--config", str(config), "--duration-s", "1"),
                capture_output=True,
                text=True,
                cwd=ROOT,
                timeout=120,
                check=False,
            )
            for _ in range(3)
        ]
    finally:
        endpoint.close()
    for out in outs:
        assert out.returncode == 0, out.stderr[-3000:]
    folders = _recordings(tmp_path / "recordings")
    assert len(folders) == 3 and all(FOLDER.match(p.name) for p in folders), folders
    for out, folder in zip(outs, folders, strict=True):
        assert f"recording into {folder}" in out.stderr
        recorded = tomllib.loads((folder / "session.toml").read_text())
        assert recorded["version"] == 1 and recorded["mount"]["attitude_source"] == "gimbal_device"


def test_kill_9_three_times_under_the_units_restart_policy(tmp_path):
    endpoint = GpsInputEndpoint()
    config, _ = field_config(tmp_path, endpoint.port)

    def heard_since(t: float) -> bool:
        return any(t_recv > t for t_recv, _ in list(endpoint.received))

    def back(sup: Supervisor, n: int) -> None:
        """Wait for the ``n``-th start and a GPS_INPUT from it."""

        def log() -> str:
            path = sup.log(len(sup.starts) - 1)
            return path.read_text()[-2000:] if path.exists() else "nothing started"

        wait_for(
            lambda: len(sup.starts) == n and heard_since(sup.starts[-1][0]),
            60,
            lambda: f"start {n}'s GPS_INPUT ({len(sup.starts)} starts, exits {sup.exits}: {log()})",
        )

    try:
        with Supervisor(lambda argv: skyfix(*argv[1:-1], str(config)), tmp_path) as sup:
            assert sup.command[3:6] == [
                "run",
                "--config",
                str(config),
            ]  # the unit's arguments, its config replaced
            for kill in range(3):
                back(sup, kill + 1)
                proc = sup.starts[-1][1]
                os.kill(proc.pid, signal.SIGKILL)
                proc.wait(30)
            back(sup, 4)
        assert sup.exits == [-signal.SIGKILL] * 3 + [0] and not sup.gave_up, sup.exits
    finally:
        endpoint.close()
    folders = _recordings(tmp_path / "recordings")
    assert len(folders) == 4 and len({p.name for p in folders}) == 4, folders
    for folder in folders:
        assert FOLDER.match(folder.name) and (folder / "session.toml").is_file(), folder
        assert (folder / "uav.tlog").exists()

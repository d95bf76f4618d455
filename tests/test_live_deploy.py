"""The deploy/ files are valid: Zenoh JSON5 configs load in zenoh-python, the field config and
calibration are accepted by skyfix run's parsers, the systemd unit runs skyfix run, restarts under a start limit,
hardened, and systemd itself reads it without a warning."""

from __future__ import annotations

import argparse
import configparser
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import zenoh
from live_helpers import ROOT

from groundstation.config_files import load_calibration
from groundstation.live.config import run_config
from groundstation.runtime.zenoh_session import make_config
from groundstation.testing.supervisor import read_unit, systemd_seconds

DEPLOY = ROOT / "deploy"


@pytest.mark.parametrize("name", ["peer", "client", "tls"])
def test_zenoh_configs_load(name):
    conf = make_config(config_file=str(DEPLOY / "zenoh" / f"{name}.json5"))
    assert isinstance(conf, zenoh.Config)
    assert conf.get_json("scouting/multicast/enabled") == "false"


def test_field_config_and_calibration():
    cfg = run_config(argparse.Namespace(config=str(DEPLOY / "field.toml")))
    assert cfg.calibration == str(DEPLOY / "calibration.toml") and cfg.depth_source == "blueos"
    cal = load_calibration(cfg.calibration)
    # live, the target is selected or acquired
    assert cal.init_bbox is None and cal.camera.width == 1920
    assert cfg.uuv_position_key == "mavlink/1/1/GLOBAL_POSITION_INT"


def test_systemd_unit_runs_the_service():
    unit = configparser.ConfigParser(strict=False, interpolation=None)
    unit.read(DEPLOY / "skyfix.service")
    assert "skyfix run --config" in unit["Service"]["ExecStart"]
    assert unit["Service"]["KillSignal"] == "SIGINT"


def test_systemd_unit_restarts_within_its_limit_hardened_and_records_where_it_may_write():
    """Restart=on-failure with a start limit; its own user on a read-only system; the recordings (field.toml's
    ``recordings``) in its StateDirectory, the one place it may write."""
    unit = read_unit()
    service = unit["Service"]
    assert service["Restart"] == "on-failure" and systemd_seconds(service["RestartSec"]) <= 1.0
    assert (
        systemd_seconds(unit["Unit"]["StartLimitIntervalSec"]) > 0
        and int(unit["Unit"]["StartLimitBurst"]) >= 4
    )
    assert service["User"] == "skyfix" and service.get("DynamicUser", "no") == "no"
    hardening = {
        "NoNewPrivileges": "yes",
        "ProtectSystem": "strict",
        "ProtectHome": "yes",
        "PrivateTmp": "yes",
        "CapabilityBoundingSet": "",
        "RestrictSUIDSGID": "yes",
    }
    assert {k: service.get(k) for k in hardening} == hardening
    # above the desktop's programs (FIELD.md, "Priority"): the realtime policy at the lowest priority, which the
    # field config asks for and the unit allows (no higher, and not refused), the nice value for what is not realtime
    cfg = run_config(argparse.Namespace(config=str(DEPLOY / "field.toml")))
    assert cfg.realtime_priority == int(service["LimitRTPRIO"]) == 1
    assert service.get("RestrictRealtime", "no") == "no" and "CPUSchedulingPolicy" not in service
    assert -20 < int(service["Nice"]) < 0
    assert set(service["RestrictAddressFamilies"].split()) == {
        "AF_INET",
        "AF_INET6",
        "AF_UNIX",
        "AF_NETLINK",
    }
    state = Path("/var/lib") / service["StateDirectory"]
    assert (
        cfg.record is None
        and Path(cfg.recordings).is_relative_to(state)
        and service["WorkingDirectory"] == str(state)
    )


def test_systemd_analyze_verifies_the_unit_and_rates_it_ok(tmp_path):
    """systemd's own reading of the unit (its ExecStart pointed at this checkout's skyfix): no warning, and an
    exposure level of at most 3 of 10 (``systemd-analyze security``)."""
    analyze = shutil.which("systemd-analyze")
    if analyze is None:
        pytest.skip("systemd-analyze is not installed (Debian: apt install systemd)")
    unit = tmp_path / "skyfix.service"
    text = (DEPLOY / "skyfix.service").read_text()
    unit.write_text(
        text.replace("/opt/skyfix/.venv/bin/skyfix", str(Path(sys.executable).parent / "skyfix"))
    )
    verify = subprocess.run(
        [analyze, "verify", "--man=no", str(unit)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert verify.returncode == 0 and verify.stderr.strip() == "", verify.stderr
    security = subprocess.run(
        [analyze, "security", "--offline=true", str(unit)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    level = re.search(r"Overall exposure level for skyfix.service: (\d+\.\d+)", security.stdout)
    assert level is not None and float(level[1]) <= 3.0, security.stdout[-1500:]

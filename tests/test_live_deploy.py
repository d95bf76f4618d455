"""The deploy/ files are valid: Zenoh JSON5 configs load in zenoh-python, the field config and
calibration are accepted by skyfix run's parsers, the systemd unit runs skyfix run."""

from __future__ import annotations

import argparse
import configparser

import pytest
import zenoh
from live_helpers import ROOT

from groundstation.live.config import load_calibration, run_config
from groundstation.zenoh_session import make_config

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
    assert cal.init_bbox is None and cal.camera.width == 1920  # live, the target is selected or acquired
    assert cfg.uuv_position_key == "mavlink/1/1/GLOBAL_POSITION_INT"


def test_systemd_unit_runs_the_service():
    unit = configparser.ConfigParser(strict=False, interpolation=None)
    unit.read(DEPLOY / "skyfix.service")
    assert "skyfix run --config" in unit["Service"]["ExecStart"]
    assert unit["Service"]["KillSignal"] == "SIGINT"

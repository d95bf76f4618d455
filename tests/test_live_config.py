"""``skyfix run`` options: flags over a config TOML over defaults; bad values named in one line."""

from __future__ import annotations

import argparse

import pytest

from groundstation import config
from localizer.calibration import ConfigError


def _parse(argv):
    p = argparse.ArgumentParser()
    config.add_arguments(p)
    return p.parse_args(argv)


def test_flags_win_over_file_and_paths_are_relative_to_it(tmp_path):
    (tmp_path / "field.toml").write_text(
        'calibration = "cal.toml"\nmavlink = "udpin:0.0.0.0:14551"\nvideo_latency_ms = 120\n'
        'zenoh_connect = ["tcp/192.168.2.2:7447"]\ngps_input_hz = 8\n')
    cfg = config.run_config(_parse(["--config", str(tmp_path / "field.toml"), "--gps-input-hz", "20",
                                    "--zenoh-connect", "tcp/127.0.0.1:1", "--zenoh-connect", "tcp/127.0.0.1:2"]))
    assert cfg.calibration == str(tmp_path / "cal.toml")
    assert cfg.mavlink == "udpin:0.0.0.0:14551" and cfg.video_latency_ms == 120.0
    assert cfg.gps_input_hz == 20.0
    assert cfg.zenoh_connect == ("tcp/127.0.0.1:1", "tcp/127.0.0.1:2")
    assert cfg.fix_key == "skyfix/uuv/fix" and cfg.depth_key == "uuv/depth" and not cfg.zenoh_multicast


@pytest.mark.parametrize("text,key", [('mavlnk = "x"', "mavlnk"), ("gps_input_hz = \"fast\"", "gps_input_hz"),
                                      ('depth_source = "ros"', "depth_source"), ("zenoh_listen = 5", "zenoh_listen")])
def test_bad_config_keys_are_named(tmp_path, text, key):
    (tmp_path / "c.toml").write_text(text + "\n")
    with pytest.raises(ConfigError, match=key):
        config.run_config(_parse(["--config", str(tmp_path / "c.toml")]))


def test_required_and_range_checks():
    with pytest.raises(ConfigError, match="--calibration"):
        config.run_config(_parse([]))
    with pytest.raises(ConfigError, match="5 Hz"):
        config.run_config(_parse(["--calibration", "x.toml", "--gps-input-hz", "4"]))

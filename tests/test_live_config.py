"""``skyfix run`` options: flags over a config TOML over defaults; bad values named in one line."""

from __future__ import annotations

import argparse
from pathlib import Path

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


@pytest.mark.parametrize("flags,message", [
    (["--uuv-hint", "63.44"], "--uuv-hint = '63.44': expected LAT,LON in degrees"),
    (["--uuv-hint", "63.44,190"], "--uuv-hint = '63.44,190': expected LAT within ±90 and LON within ±180"),
    (["--uuv-prior-sigma-m", "0"], "--uuv-prior-sigma-m = 0.0: expected > 0 and ≤ 1000"),
    (["--select-history-s", "60"], "--select-history-s = 60.0: expected 0 … 10"),
])
def test_target_options_are_checked(flags, message):
    with pytest.raises(ConfigError) as e:
        config.run_config(_parse(["--calibration", "x.toml", *flags]))
    assert str(e.value) == f"options: {message}"


def test_target_options_from_a_config_file(tmp_path):
    (tmp_path / "c.toml").write_text('calibration = "cal.toml"\nuuv_position_key = "mavlink/1/1/GLOBAL_POSITION_INT"\n'
                                     'uuv_hint = "63.44,10.40"\nuuv_prior_sigma_m = 5\ncontrol_prefix = "boat/skyfix"\n')
    cfg = config.run_config(_parse(["--config", str(tmp_path / "c.toml")]))
    assert cfg.uuv_position_key == "mavlink/1/1/GLOBAL_POSITION_INT" and cfg.uuv_hint == "63.44,10.40"
    assert cfg.uuv_prior_sigma_m == 5.0 and cfg.control_prefix == "boat/skyfix" and cfg.select_history_s == 1.0


@pytest.mark.parametrize("option", ["--mavlink", "--gps-input"])
def test_a_link_that_cannot_open_is_one_line_and_exit_2(tmp_path, option, capsys):
    """A mistyped connection string stops the service with one line naming it, not a traceback."""
    from groundstation.cli import main

    bundled = Path(__file__).resolve().parents[1] / "sim_fixtures" / "bundled" / "nadir_hover" / "session.toml"
    argv = ["run", "--calibration", str(bundled), "--mavlink", "udpin:127.0.0.1:0", "--duration-s", "3",
            option, "udpin:127.0.0.1:notaport"]
    assert main(argv) == 2
    err_lines = [ln for ln in capsys.readouterr().err.splitlines() if "error" in ln]
    assert len(err_lines) == 1
    assert err_lines[0].startswith("skyfix run: error: MAVLink 'udpin:127.0.0.1:notaport': cannot open:")

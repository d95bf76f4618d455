"""``skyfix run`` options: flags over a config TOML over defaults; bad values named in one line."""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from groundstation.live import config
from localizer.calibration import ConfigError


def _parse(argv):
    p = argparse.ArgumentParser()
    config.add_arguments(p)
    return p.parse_args(argv)


def test_flags_win_over_file_and_paths_are_relative_to_it(tmp_path):
    (tmp_path / "field.toml").write_text(
        'calibration = "cal.toml"\nmavlink = "udpin:0.0.0.0:14551"\nvideo_latency_ms = 120\n'
        'zenoh_connect = ["tcp/192.168.2.2:7447"]\ngps_input_hz = 8\n'
    )
    cfg = config.run_config(
        _parse(
            [
                "--config",
                str(tmp_path / "field.toml"),
                "--gps-input-hz",
                "20",
                "--zenoh-connect",
                "tcp/127.0.0.1:1",
                "--zenoh-connect",
                "tcp/127.0.0.1:2",
            ]
        )
    )
    assert cfg.calibration == str(tmp_path / "cal.toml")
    assert cfg.mavlink == "udpin:0.0.0.0:14551" and cfg.video_latency_ms == 120.0
    assert cfg.gps_input_hz == 20.0
    assert cfg.zenoh_connect == ("tcp/127.0.0.1:1", "tcp/127.0.0.1:2")
    assert (
        cfg.fix_key == "skyfix/uuv/fix" and cfg.depth_key == "uuv/depth" and not cfg.zenoh_multicast
    )


@pytest.mark.parametrize(
    "text,key",
    [
        ('mavlnk = "x"', "mavlnk"),
        ('gps_input_hz = "fast"', "gps_input_hz"),
        ('depth_source = "ros"', "depth_source"),
        ("zenoh_listen = 5", "zenoh_listen"),
    ],
)
def test_bad_config_keys_are_named(tmp_path, text, key):
    (tmp_path / "c.toml").write_text(text + "\n")
    with pytest.raises(ConfigError, match=key):
        config.run_config(_parse(["--config", str(tmp_path / "c.toml")]))


def test_required_and_range_checks():
    with pytest.raises(ConfigError, match="--calibration"):
        config.run_config(_parse([]))
    with pytest.raises(ConfigError, match=r"^options: --gps-input-hz = 4.0: must be ≥ 5$"):
        config.run_config(_parse(["--calibration", "x.toml", "--gps-input-hz", "4"]))


def test_a_bad_value_names_where_it_came_from(tmp_path):
    """A key from the file is named as written there, with the file; a flag as the flag, with "options"."""
    (tmp_path / "c.toml").write_text('calibration = "cal.toml"\ntelemetry_wait_ms = 5000\n')
    with pytest.raises(ConfigError) as e:
        config.run_config(_parse(["--config", str(tmp_path / "c.toml")]))
    assert str(e.value) == f"{tmp_path / 'c.toml'}: telemetry_wait_ms = 5000: must be ≤ 2000"
    with pytest.raises(ConfigError) as e:
        config.run_config(
            _parse(["--config", str(tmp_path / "c.toml"), "--telemetry-wait-ms", "-1"])
        )
    assert str(e.value) == "options: --telemetry-wait-ms = -1.0: must be ≥ 0"
    with pytest.raises(ConfigError, match="recording needs --mavlink-backend pymavlink"):
        config.run_config(
            _parse(["--calibration", "x", "--record", "r", "--mavlink-backend", "mavsdk"])
        )


def test_help_shows_defaults_choices_and_the_required_calibration(capsys):
    from groundstation.cli import main

    with pytest.raises(SystemExit) as e:
        main(["run", "--help"])
    assert e.value.code == 0
    text = " ".join(capsys.readouterr().out.split())  # argparse wraps lines
    assert "usage: skyfix run --calibration FILE" in text
    assert "required (a flag, or a key in the --config file): --calibration FILE" in text
    assert "--tracker {default,ncc,mil,kcf,csrt}" in text
    assert "(default: udpin:0.0.0.0:14550)" in text and "(default: 10.0)" in text
    for (
        name,
        info,
    ) in config.RunConfig.__pydantic_fields__.items():  # every option has its flag and help
        if name in config.FILE_ONLY:  # tables of the config file, no flag
            assert {"uuv": "[[uuv]]", "parts": "[parts.NAME]"}[name] in text
        else:
            assert config.flag(name) in text and info.description.split()[0] in text


def test_version(capsys):
    from importlib.metadata import version

    from groundstation.cli import main

    with pytest.raises(SystemExit):
        main(["--version"])
    assert capsys.readouterr().out.strip() == f"skyfix {version('skyfix')}"


def test_unknown_calibration_keys_are_logged_by_run(tmp_path, caplog):
    """As ``process`` prints them: an unknown key in a spec table is a warning naming it; in skyfix's tables an error."""
    from groundstation.cli import main

    bundled = (
        Path(__file__).resolve().parents[1]
        / "sim_fixtures"
        / "bundled"
        / "nadir_hover"
        / "session.toml"
    )
    cal = tmp_path / "cal.toml"
    cal.write_text(
        bundled.read_text().replace("[mount]\n", "[mount]\ncamera_ofset_m = [0.0, 0.0, 0.3]\n")
    )
    argv = [
        "run",
        "--calibration",
        str(cal),
        "--mavlink",
        "udpin:127.0.0.1:0",
        "--video",
        "none",
        "--gps-input",
        "none",
        "--zenoh-listen",
        "tcp/127.0.0.1:0",
        "--duration-s",
        "0.2",
        "--no-ui",
    ]
    with caplog.at_level("WARNING"):
        assert main(argv) == 0
    assert (
        f"{cal}: mount.camera_ofset_m is not a key skyfix knows; ignored (a typo?)"
        in caplog.messages
    )
    cal.write_text(bundled.read_text() + "\n[timing]\nattitude_gap = 0.5\n")
    assert main(argv) == 2


@pytest.mark.parametrize(
    "flags,message",
    [
        (["--uuv-hint", "63.44"], "--uuv-hint = '63.44': expected LAT,LON in degrees"),
        (
            ["--uuv-hint", "63.44,190"],
            "--uuv-hint = '63.44,190': expected LAT within ±90 and LON within ±180",
        ),
        (["--uuv-prior-sigma-m", "0"], "--uuv-prior-sigma-m = 0.0: must be ≥ 0.01"),
        (["--select-history-s", "60"], "--select-history-s = 60.0: must be ≤ 10"),
    ],
)
def test_target_options_are_checked(flags, message):
    with pytest.raises(ConfigError) as e:
        config.run_config(_parse(["--calibration", "x.toml", *flags]))
    assert str(e.value) == f"options: {message}"


def test_a_tracker_that_never_reports_a_loss_is_refused_for_gps_input(tmp_path):
    with pytest.raises(ConfigError) as e:
        config.run_config(
            _parse(
                ["--calibration", "x.toml", "--tracker", "mil", "--gps-input", "udpout:127.0.0.1:1"]
            )
        )
    assert str(e.value) == (
        "options: --tracker = 'mil': this tracker never reports losing the UUV: not a source for "
        "GPS_INPUT (use default, kcf or csrt; mil is for offline comparisons)"
    )
    (tmp_path / "c.toml").write_text(
        'calibration = "cal.toml"\ntracker = "mil"\ngps_input = "zenoh:mavlink/in"\n'
    )
    with pytest.raises(
        ConfigError, match=r"c\.toml: tracker = 'mil': this tracker never reports losing the UUV"
    ):
        config.run_config(_parse(["--config", str(tmp_path / "c.toml")]))
    # no GPS_INPUT
    assert (
        config.run_config(_parse(["--calibration", "x.toml", "--tracker", "mil"])).tracker == "mil"
    )
    for name in ("default", "kcf", "csrt"):  # they report losses
        cfg = config.run_config(
            _parse(
                ["--calibration", "x.toml", "--tracker", name, "--gps-input", "udpout:127.0.0.1:1"]
            )
        )
        assert cfg.tracker == name


@pytest.mark.parametrize(
    "flags,message",
    [
        (
            ["--ui", "8080"],
            "--ui = '8080': expected HOST:PORT, e.g. 127.0.0.1:8080 or 0.0.0.0:8080",
        ),
        (["--ui", "127.0.0.1:70000"], "--ui = '127.0.0.1:70000': port 70000 is not 0..65535"),
        (
            ["--ui-token", "short"],
            (
                "--ui-token = 'short': expected 8-128 characters of A-Z a-z 0-9 . _ ~ - (it goes "
                "into a URL)"
            ),
        ),
    ],
)
def test_web_page_options_are_checked(flags, message):
    with pytest.raises(ConfigError) as e:
        config.run_config(_parse(["--calibration", "x.toml", *flags]))
    assert str(e.value) == f"options: {message}"


def test_web_page_options():
    cfg = config.run_config(_parse(["--calibration", "x.toml"]))
    # on by default, on localhost
    assert cfg.ui == "127.0.0.1:8080" and not cfg.no_ui and cfg.ui_token is None
    cfg = config.run_config(
        _parse(["--calibration", "x.toml", "--ui", "[::1]:0", "--ui-token", "abcdefgh12"])
    )
    assert cfg.ui == "[::1]:0" and cfg.ui_token == "abcdefgh12"
    assert config.run_config(_parse(["--calibration", "x.toml", "--no-ui"])).no_ui


def test_target_options_from_a_config_file(tmp_path):
    (tmp_path / "c.toml").write_text(
        'calibration = "cal.toml"\nuuv_position_key = "mavlink/1/1/GLOBAL_POSITION_INT"\n'
        'uuv_hint = "63.44,10.40"\nuuv_prior_sigma_m = 5\ncontrol_prefix = "boat/skyfix"\n'
    )
    cfg = config.run_config(_parse(["--config", str(tmp_path / "c.toml")]))
    assert (
        cfg.uuv_position_key == "mavlink/1/1/GLOBAL_POSITION_INT" and cfg.uuv_hint == "63.44,10.40"
    )
    assert (
        cfg.uuv_prior_sigma_m == 5.0
        and cfg.control_prefix == "boat/skyfix"
        and cfg.select_history_s == 1.0
    )


@pytest.mark.parametrize("option", ["--mavlink", "--gps-input"])
def test_a_link_that_cannot_open_is_one_line_and_exit_2(tmp_path, option, capsys):
    """A mistyped connection string stops the service with one line naming it, not a traceback."""
    from groundstation.cli import main

    bundled = (
        Path(__file__).resolve().parents[1]
        / "sim_fixtures"
        / "bundled"
        / "nadir_hover"
        / "session.toml"
    )
    argv = [
        "run",
        "--calibration",
        str(bundled),
        "--mavlink",
        "udpin:127.0.0.1:0",
        "--video",
        "none",
        "--gps-input",
        "none",
        "--zenoh-listen",
        "tcp/127.0.0.1:0",
        "--duration-s",
        "3",
        "--no-ui",
        option,
        "udpin:127.0.0.1:notaport",
    ]
    assert main(argv) == 2
    err_lines = [ln for ln in capsys.readouterr().err.splitlines() if "error" in ln]
    assert len(err_lines) == 1
    assert err_lines[0].startswith(
        "skyfix run: error: MAVLink 'udpin:127.0.0.1:notaport': cannot open:"
    )


def test_video_and_gps_input_are_named_or_said_to_be_none(tmp_path):
    """A run that forgets --video or --gps-input is refused; "none" says there is none (read as None); with [[uuv]]
    tables each names its own GPS_INPUT."""
    with pytest.raises(
        ConfigError, match=r"^options: --video = None: missing: name it, or say none"
    ):
        config.unnamed_inputs(
            _parse(["--calibration", "x.toml", "--gps-input", "udpout:127.0.0.1:1"])
        )
    with pytest.raises(ConfigError, match=r"^options: --gps-input = None: missing"):
        config.unnamed_inputs(_parse(["--calibration", "x.toml", "--video", "udp://0.0.0.0:5600"]))
    args = _parse(["--calibration", "x.toml", "--video", "none", "--gps-input", "none"])
    config.unnamed_inputs(args)
    cfg = config.run_config(args)
    assert cfg.video is None and cfg.gps_input is None and cfg.uuvs[0].gps_input is None
    (tmp_path / "c.toml").write_text(
        'calibration = "cal.toml"\nvideo = "none"\n[[uuv]]\nid = "a"\ngps_input = '
        '"udpout:127.0.0.1:1"\n[[uuv]]\nid = "b"\ndepth_key = "b/depth"\n'
    )
    with pytest.raises(
        ConfigError, match=rf"^{tmp_path / 'c.toml'}: uuv\[1\].gps_input = None: missing"
    ):
        config.unnamed_inputs(_parse(["--config", str(tmp_path / "c.toml")]))

"""Scenario files: every shipped one loads; bad input gets a one-line error naming key and value."""

from pathlib import Path

import pytest

from localizer.calibration import ConfigError
from sim_fixtures.scenario import load_scenario, scenario_from_dict

SCENARIOS = sorted((Path(__file__).parents[1] / "sim_fixtures" / "scenarios").glob("*.toml"))


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.stem)
def test_shipped_scenarios_load(path):
    sc = load_scenario(path)
    assert sc.name == path.stem


@pytest.mark.parametrize(
    "data, key",
    [
        ({"name": "x", "uav": {"hieght_m": 3.0}}, "uav.hieght_m"),
        ({"name": "x", "mount": {"attitude_source": "gimbal"}}, "mount.attitude_source"),
        ({"name": "x", "camera": {"width": 640.5}}, "camera.width"),
        ({"name": "x", "camera": {"distortion": [0.1, 0.2]}}, "camera.distortion"),
        ({"name": "x", "occlusions": [[3.0, 2.0]]}, "occlusions"),
        ({"name": "x", "uuv": {"depth_m": 3.9}}, "uuv.depth_m"),
        ({"name": "x", "fps": 0}, "fps"),
        ({"seed": 3}, "name"),
        ({"name": "x", "clock": {"station_ofset_s": -2.5}}, "clock.station_ofset_s"),
        ({"name": "x", "clock": {"uuv_offset_s": "291"}}, "clock.uuv_offset_s"),
        ({"name": "x", "mount": {"kind": "gimbal"}}, "mount.kind"),
        ({"name": "x", "mount": {"yaw_mode": "north"}}, "mount.yaw_mode"),
        ({"name": "x", "mount": {"kind": "servo", "attitude_source": "fixed"}}, "mount.kind"),
        ({"name": "x", "link": {"reboot_at_s": "3"}}, "link.reboot_at_s"),
        ({"name": "x", "link": {"reboot_at_s": 30.0}}, "link.reboot_at_s"),
        ({"name": "x", "link": {"reboot_down_s": 0.0}}, "link.reboot_down_s"),
        ({"name": "x", "link": {"depth_jitter_s": -0.1}}, "link.depth_jitter_s"),
        ({"name": "x", "telemetry": {"attitude_hz": 0}}, "telemetry.attitude_hz"),
        ({"name": "x", "telemetry": {"gps_raw_hz": -5.0}}, "telemetry.gps_raw_hz"),
        ({"name": "x", "telemetry": {"gps_raw_time": "gps"}}, "telemetry.gps_raw_time"),
        ({"name": "x", "uav": {"gnss_fix_type": 9}}, "uav.gnss_fix_type"),
        ({"name": "x", "uav": {"gnss_fix_type": 3.0}}, "uav.gnss_fix_type"),
        ({"name": "x", "uav": {"wobble_hz": True}}, "uav.wobble_hz"),
    ],
)
def test_bad_values_are_named(data, key):
    with pytest.raises(ConfigError) as e:
        scenario_from_dict(data, "s.toml")
    msg = str(e.value)
    assert msg.startswith(f"s.toml: {key} = ") and "\n" not in msg


def test_defaults_are_the_old_behaviour():
    sc = scenario_from_dict({"name": "x"})
    assert (sc.clock.station_offset_s, sc.clock.uuv_offset_s) == (0.0, 0.0)
    assert (sc.mount.kind, sc.mount.yaw_mode, sc.uav.wobble_deg, sc.link.reboot_at_s) == (
        "stabilised",
        "earth",
        0.0,
        None,
    )
    assert (sc.link.depth_delay_s, sc.link.depth_jitter_s, sc.site.geoid_separation_m) == (
        0.03,
        0.005,
        40.0,
    )
    assert (sc.telemetry.system_time_hz, sc.telemetry.gps_raw_hz, sc.telemetry.timesync_hz) == (
        1.0,
        5.0,
        1.0,
    )
    assert scenario_from_dict({"name": "x", "link": {"reboot_at_s": 3}}).link.reboot_at_s == 3.0


def test_unreadable_file_is_a_config_error(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "x"\n[uav\n')
    with pytest.raises(ConfigError, match="bad.toml"):
        load_scenario(bad)
    with pytest.raises(ConfigError, match="cannot read"):
        load_scenario(tmp_path / "missing.toml")

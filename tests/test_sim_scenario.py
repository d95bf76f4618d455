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
    ],
)
def test_bad_values_are_named(data, key):
    with pytest.raises(ConfigError) as e:
        scenario_from_dict(data, "s.toml")
    msg = str(e.value)
    assert msg.startswith(f"s.toml: {key} = ") and "\n" not in msg


def test_unreadable_file_is_a_config_error(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "x"\n[uav\n')
    with pytest.raises(ConfigError, match="bad.toml"):
        load_scenario(bad)
    with pytest.raises(ConfigError, match="cannot read"):
        load_scenario(tmp_path / "missing.toml")

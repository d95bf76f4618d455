"""Calibration.from_dict: good input parses; each bad value: a one-line ConfigError naming it."""

import copy
import math

import pytest

from localizer.calibration import Calibration, ConfigError, Sigmas, Timing


def test_spec_example_parses(cal_dict):
    data = cal_dict(
        mount={
            "attitude_source": "gimbal_device",
            "fixed_rpy_deg": [0.0, -90.0, 0.0],
            "camera_offset_m": [0.1, 0.0, 0.25],
        },
        water={"takeoff_height_above_surface_m": 2.10, "refractive_index": 1.34},
        tracker={"init_bbox": [912, 508, 96, 64]},
    )
    cal = Calibration.from_dict(data)
    assert cal.camera.width == 1920 and cal.camera.fx == 1664.0
    assert cal.camera.distortion == (-0.12, 0.08, 0.0004, -0.0002, -0.01)
    assert cal.mount.camera_offset_m == (0.1, 0.0, 0.25)
    assert cal.water.takeoff_height_above_surface_m == 2.10 and cal.water.surface_amsl_m is None
    assert cal.init_bbox == (912, 508, 96, 64) and cal.init_t is None
    assert cal.sigmas == Sigmas() and cal.timing == Timing()
    assert (cal.uuv.length_m, cal.uuv.width_m, cal.uuv.height_m) == (
        0.457,
        0.338,
        0.254,
    )  # a BlueROV2


def test_optional_tables(cal_dict):
    cal = Calibration.from_dict(
        cal_dict(
            water={"surface_amsl_m": 0.35},
            uncertainty={"pixel_px": 3.5},
            timing={"depth_hold_s": 2.5},
            uuv={"length_m": 0.62},
            tracker={"init_bbox": [0, 0, 10, 10], "init_t": 1763800000.5},
        )
    )
    assert cal.water.surface_amsl_m == 0.35 and cal.water.refractive_index == 1.34
    assert cal.sigmas.pixel_px == 3.5 and cal.sigmas.yaw_deg == Sigmas().yaw_deg
    assert cal.timing.depth_hold_s == 2.5
    assert cal.uuv.length_m == 0.62 and cal.uuv.width_m == 0.338
    assert cal.init_t == 1763800000.5


def _with(data, path, value):
    """Copy of ``data`` with ``path`` ("table.key") set, or deleted when value is ``...``."""
    data = copy.deepcopy(data)
    table, _, key = path.partition(".")
    if not key:
        if value is ...:
            del data[table]
        else:
            data[table] = value
        return data
    t = data.setdefault(table, {})
    if value is ...:
        del t[key]
    else:
        t[key] = value
    return data


BAD = [
    # (path to change, new value or ... to delete, text the message must name)
    ("camera", ..., "[camera]"),
    ("mount", ..., "[mount]"),
    ("camera", "1920x1080", "[camera]"),
    ("camera.fx", ..., "camera.fx"),
    ("camera.fx", math.nan, "camera.fx = nan"),
    ("camera.fy", -1664.0, "camera.fy = -1664.0"),
    ("camera.fx", "1664", "camera.fx = '1664'"),
    ("camera.width", -1920, "camera.width = -1920"),
    ("camera.height", 1080.5, "camera.height = 1080.5"),
    ("camera.width", True, "camera.width = True"),
    ("camera.cx", 5000.0, "camera.cx = 5000.0"),
    ("camera.cy", math.inf, "camera.cy = inf"),
    ("camera.distortion", [0.1, 0.2], "camera.distortion = [0.1, 0.2]"),
    ("camera.distortion", [0.0, math.nan, 0.0, 0.0, 0.0], "camera.distortion[1] = nan"),
    ("mount.attitude_source", "gimbal", "mount.attitude_source = 'gimbal'"),
    ("mount.fixed_rpy_deg", [0.0, -90.0], "mount.fixed_rpy_deg"),
    ("mount.camera_offset_m", [0.0, "x", 0.0], "mount.camera_offset_m[1] = 'x'"),
    ("water", {"takeoff_height_above_surface_m": 2.0, "surface_amsl_m": 0.3}, "surface_amsl_m"),
    ("water", {"refractive_index": 1.34}, "takeoff_height_above_surface_m"),
    ("water.refractive_index", 0.9, "water.refractive_index = 0.9"),
    (
        "water.takeoff_height_above_surface_m",
        math.nan,
        "water.takeoff_height_above_surface_m = nan",
    ),
    ("tracker", {"init_bbox": [1900, 500, 96, 64]}, "tracker.init_bbox = [1900, 500, 96, 64]"),
    ("tracker", {"init_bbox": [-5, 500, 96, 64]}, "tracker.init_bbox = [-5, 500, 96, 64]"),
    ("tracker", {"init_bbox": [5, 500, 96]}, "tracker.init_bbox"),
    ("tracker", {"init_t": "now"}, "tracker.init_t = 'now'"),
    ("uncertainty", {"pixel_sigma": 2.0}, "uncertainty.pixel_sigma = 2.0"),
    ("uncertainty", {"yaw_deg": -1.0}, "uncertainty.yaw_deg = -1.0"),
    ("timing", {"attitude_gap_s": 0}, "timing.attitude_gap_s = 0"),
    ("uuv", {"length_m": 0.0}, "uuv.length_m = 0.0: must be ≥ 0.05"),
    ("uuv", {"width_m": "0.34"}, "uuv.width_m = '0.34'"),
    (
        "uuv",
        {"height": 0.25},
        "uuv.height = 0.25: unknown key (known: height_m, length_m, width_m)",
    ),
]


@pytest.mark.parametrize("path, value, named", BAD, ids=[f"{p}={v!r}" for p, v, _ in BAD])
def test_bad_values_raise_config_error_naming_them(cal_dict, path, value, named):
    with pytest.raises(ConfigError) as exc:
        Calibration.from_dict(_with(cal_dict(), path, value), source="flight7/session.toml")
    msg = str(exc.value)
    assert "\n" not in msg
    assert msg.startswith("flight7/session.toml: ")
    assert named in msg, msg
    assert isinstance(exc.value, ValueError)


def test_unknown_key_message_lists_known_keys(cal_dict):
    with pytest.raises(ConfigError) as exc:
        Calibration.from_dict(cal_dict(uncertainty={"pixel_sigma": 2.0}))
    assert "pixel_px" in str(exc.value)
    assert exc.value.key == "uncertainty.pixel_sigma" and exc.value.value == 2.0


def test_unknown_keys_in_spec_tables_are_warnings_not_silence(cal_dict):
    """Other tools may add keys (the spec allows it), but a typo must not pass unnoticed."""
    d = copy.deepcopy(cal_dict())
    assert not Calibration.from_dict(d).warnings
    d["mount"]["camera_ofset_m"] = [9.0, 0.0, 0.2]
    cal = Calibration.from_dict(d, source="s.toml")
    assert cal.mount.camera_offset_m == Calibration.from_dict(cal_dict()).mount.camera_offset_m
    assert len(cal.warnings) == 1 and "mount.camera_ofset_m" in cal.warnings[0]

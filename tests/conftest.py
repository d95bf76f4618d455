"""Shared builders for the localizer tests: a session.toml-like calibration and filled telemetry."""

import math

import ahead
import pytest
from live_helpers import ROOT

from localizer.calibration import Calibration
from localizer.telemetry import Telemetry

T0_UNIX = 1_763_800_000.0  # UNIX time of the first telemetry sample
BOOT0_MS = 250_000  # the autopilot's time_boot_ms at T0_UNIX


def _cal_dict(**tables):
    """The session spec's example calibration; keyword tables (water={...}) replace its own."""
    data = {
        "version": 1,
        "camera": {
            "width": 1920,
            "height": 1080,
            "fx": 1664.0,
            "fy": 1664.0,
            "cx": 959.5,
            "cy": 539.5,
            "distortion": [-0.12, 0.08, 0.0004, -0.0002, -0.01],
        },
        "mount": {"attitude_source": "gimbal_device", "camera_offset_m": [0.0, 0.0, 0.0]},
        "water": {"takeoff_height_above_surface_m": 2.0, "refractive_index": 1.34},
    }
    data.update(tables)
    return data


def quat_from_ypr_deg(yaw, pitch, roll):
    """(w, x, y, z) of yaw-then-pitch-then-roll, by multiplying single-axis quaternions by hand."""

    def mul(a, b):
        w1, x1, y1, z1 = a
        w2, x2, y2, z2 = b
        return (
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        )

    hy, hp, hr = (math.radians(a) / 2 for a in (yaw, pitch, roll))
    qz = (math.cos(hy), 0.0, 0.0, math.sin(hy))
    qy = (math.cos(hp), 0.0, math.sin(hp), 0.0)
    qx = (math.cos(hr), math.sin(hr), 0.0, 0.0)
    return mul(mul(qz, qy), qx)


def _telemetry(
    *,
    height_m=30.0,
    uav_rpy_deg=(0.0, 0.0, 0.0),
    gimbal_ypr_deg=(0.0, -90.0, 0.0),
    gimbal_flags=64,
    mount_rpy_deg=None,
    depth_m=2.0,
    lat=47.5,
    lon=8.5,
    takeoff_above_surface_m=2.0,
    surface_amsl_m=None,
    alt_amsl_m=412.0,
    duration_s=3.0,
    rate_hz=20.0,
    system_time=True,
):
    """A Telemetry with constant values sampled at ``rate_hz`` from T0_UNIX for ``duration_s``.

    ``height_m`` is the UAV's reported position above the water; relative_alt and
    alt are derived from it for the water reference in use. Every sample arrives
    the instant it is taken, so the autopilot's boot clock maps exactly onto the
    station clock (BOOT0_MS at T0_UNIX).
    """
    tel = Telemetry()
    if surface_amsl_m is not None:
        alt_amsl_m = surface_amsl_m + height_m
    rel_alt = height_m - takeoff_above_surface_m
    r, p, y = (math.radians(a) for a in uav_rpy_deg)
    q = quat_from_ypr_deg(*gimbal_ypr_deg)
    n = int(duration_s * rate_hz) + 1
    for i in range(n):
        boot_ms = BOOT0_MS + round(i * 1000 / rate_hz)
        t = T0_UNIX + (boot_ms - BOOT0_MS) / 1000  # received the instant it was sampled
        if system_time:
            tel.add_system_time(boot_ms, round(t * 1e6), t)
        tel.add_attitude(boot_ms, r, p, y, (0.0, 0.0, 0.0), t)
        tel.add_position(boot_ms, lat, lon, alt_amsl_m, rel_alt, (0.0, 0.0, 0.0), t)
        tel.add_gimbal(boot_ms, q, gimbal_flags, t)
        if mount_rpy_deg is not None:
            tel.add_mount(boot_ms, *mount_rpy_deg, t)
        tel.add_depth(t, depth_m)
    return tel


@pytest.fixture
def make_cal():
    """``make_cal(**tables) -> Calibration`` from the spec's example with tables replaced."""
    return lambda **tables: Calibration.from_dict(_cal_dict(**tables))


@pytest.fixture
def cal_dict():
    """``cal_dict(**tables) -> dict``: the spec's example session.toml as parsed TOML."""
    return _cal_dict


@pytest.fixture
def make_telemetry():
    """``make_telemetry(**kw) -> Telemetry`` filled with constant samples (see ``_telemetry``)."""
    return _telemetry


@pytest.fixture
def quat_ypr():
    """``quat_ypr(yaw_deg, pitch_deg, roll_deg) -> (w, x, y, z)``, see ``quat_from_ypr_deg``."""
    return quat_from_ypr_deg


@pytest.fixture(scope="session")
def two_uuvs_crossing(tmp_path_factory):
    """``sim_fixtures/scenarios/two_uuvs_crossing.toml`` generated once for the run (video included): read by
    test_sim_two_uuvs, copied by test_live_uuvs (which re-encodes its copy's video); never changed in place."""
    from sim_fixtures.generate import generate
    from sim_fixtures.scenario import load_scenario

    scenario = ROOT / "sim_fixtures" / "scenarios" / "two_uuvs_crossing.toml"
    path = tmp_path_factory.mktemp("two_uuvs_crossing") / "s"
    generate(load_scenario(scenario), path, scenario_text=scenario.read_text())
    return path


def pytest_configure(config):
    config.addinivalue_line(
        "markers",
        f"{ahead.MARKER}(prepare, module_before=False, at_start=False): prepare(directory, background) starts the "
        "test's slow inputs while the test before it runs, the module before it, or from the run's start "
        "(tests/ahead.py)",
    )


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    ahead.prepare_ahead(item, nextitem)
    yield


@pytest.fixture
def prepared(request, tmp_path):
    """What the test's ``ahead`` marker prepared, ahead or now (tests/ahead.py); closed after the test."""
    ready = ahead.take(request.node.get_closest_marker(ahead.MARKER).args[0], tmp_path)
    yield ready
    ready.close()


def pytest_sessionfinish(session):
    ahead.close_unused()

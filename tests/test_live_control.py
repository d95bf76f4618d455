"""The operator's commands: payload checks, the UUV's own position as BlueOS sends it, and the ``skyfix status |
select | release | acquire`` console against a running ``skyfix run`` (real processes, real Zenoh on loopback)."""

from __future__ import annotations

import json
import math
import signal
import socket
import subprocess
import time

import pytest
from live_helpers import ROOT, free_port, skyfix, start, stop, wait_for

from groundstation.config_files import load_calibration
from groundstation.live.control import ControlError, jsonable, parse_select
from groundstation.live.sources.uuv_position import (
    MAX_AGE_S,
    BadPosition,
    UuvPosition,
    parse_global_position,
    parse_hint,
)
from localizer.tracking.predict import UUV_SPEED_MPS
from localizer.tracking.session import Prior


@pytest.mark.parametrize(
    ("payload", "expected"),
    [
        (
            b'{"box": [10, 20.5, 30, 40]}',
            {"frame": None, "box": (10.0, 20.5, 30.0, 40.0), "point": None},
        ),
        (
            b'{"point": [331.5, 190], "frame": 12}',
            {"frame": 12, "box": None, "point": (331.5, 190.0)},
        ),
    ],
)
def test_select_payloads(payload, expected):
    assert parse_select(payload) == expected


@pytest.mark.parametrize(
    ("payload", "why"),
    [
        (b"", "expected JSON"),
        (b"[1, 2, 3, 4]", "expected a JSON object"),
        (b'{"box": [1, 2, 3]}', "box = [1, 2, 3]: expected 4 finite numbers"),
        (b'{"box": [1, 2, "3", 4]}', "expected 4 finite numbers"),
        (b'{"box": [1, 2, 0, 4]}', "width and height must be > 0"),
        (b'{"point": [1e999, 2]}', "point = [Infinity, 2]: expected 2 finite numbers"),
        (b'{"point": [1, 2], "box": [1, 2, 3, 4]}', "either"),
        (b"{}", "either"),
        (b'{"point": [1, 2], "frame": -3}', "frame = -3: expected a frame number"),
        (b'{"point": [1, 2], "frame": true}', "frame = true"),
        (b'{"point": [1, 2], "where": 1}', "unknown key 'where'"),
        (b"[" * 100_000, "expected JSON"),
    ],
)
def test_bad_select_payloads_are_one_line_errors(payload, why):
    with pytest.raises(ControlError) as e:
        parse_select(payload)
    assert why in str(e.value) and "\n" not in str(e.value) and str(e.value).startswith("select: ")


def test_results_are_json_without_nan():
    out = jsonable({"u": float("nan"), "box": (1, 2, 3, 4), "nested": [{"x": float("inf")}]})
    assert out == {"u": None, "box": [1, 2, 3, 4], "nested": [{"x": None}]}
    json.dumps(out, allow_nan=False)


def _blueos(**message) -> bytes:
    return json.dumps(
        {
            "header": {"system_id": 1, "component_id": 1, "sequence": 7, "message_id": 33},
            "message": {
                "type": "GLOBAL_POSITION_INT",
                "time_boot_ms": 5000,
                "alt": -1000,
                "relative_alt": -1000,
                "vx": 0,
                "vy": 0,
                "vz": 0,
                "hdg": 0,
                **message,
            },
        }
    ).encode()


def test_blueos_global_position_int():
    assert parse_global_position(_blueos(lat=634400123, lon=104000456)) == pytest.approx(
        (63.4400123, 10.4000456)
    )
    # ArduPilot before it has a position
    assert parse_global_position(_blueos(lat=0, lon=0)) is None
    for payload, why in [
        (b"nope", "not JSON"),
        (b'{"message": 3}', "no 'message'"),
        (_blueos(type="VFR_HUD", lat=1, lon=1), "'VFR_HUD' is not GLOBAL_POSITION_INT"),
        (_blueos(lat=63.44, lon=10), "lat = 63.44: expected an integer"),
        (_blueos(lat=950_000_000, lon=0), "lat = 950000000: beyond ±90°"),
        (_blueos(lat=1), "lon = None"),
    ]:
        with pytest.raises(BadPosition) as e:
            parse_global_position(payload)
        assert why in str(e.value)


def test_prior_from_the_estimate_ages_and_falls_back_to_the_hint():
    pos = UuvPosition(session=None, key=None, sigma_m=2.0, hint=parse_hint("63.5, 10.5"))
    assert pos.prior(100.0) == Prior(63.5, 10.5, 2.0)  # nothing received yet: the hint
    pos._on_payload("k", _blueos(lat=634400000, lon=104000000), t_recv=100.0)
    p = pos.prior(102.0)
    assert (p.lat, p.lon) == pytest.approx((63.44, 10.40)) and p.sigma_m == pytest.approx(
        2.0 + 2.0 * UUV_SPEED_MPS
    )
    assert pos.prior(100.0 + MAX_AGE_S + 1).lat == 63.5  # too old: the hint again
    pos._on_payload("k", b"garbage", t_recv=101.0)
    pos._on_payload("k", _blueos(lat=0, lon=0), t_recv=101.0)
    assert (pos.bad, pos.unknown, pos.received) == (1, 1, 3) and pos.prior(
        101.0
    ).lat == pytest.approx(63.44)
    assert UuvPosition(session=None, key=None, sigma_m=2.0).prior(1.0) is None
    with pytest.raises(ValueError, match="expected LAT,LON"):
        parse_hint("63.5")
    with pytest.raises(ValueError, match="within ±90"):
        parse_hint("95, 10")


CAL = """
[camera]
width = 640
height = 360
fx = 500.0
fy = 500.0
cx = 319.5
cy = 179.5
[mount]
attitude_source = "fixed"
[water]
takeoff_height_above_surface_m = 1.5
"""


def _console(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        skyfix(*args), capture_output=True, text=True, cwd=ROOT, timeout=60, check=False
    )


def test_console_commands_against_a_running_service(tmp_path):
    (tmp_path / "cal.toml").write_text(CAL)
    assert load_calibration(str(tmp_path / "cal.toml")).init_bbox is None
    ep = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    nobody = _console("status", "--zenoh-connect", ep, "--timeout-s", "0.5")
    assert nobody.returncode == 2
    assert (
        nobody.stderr.strip()
        == "skyfix status: error: no skyfix service answered on skyfix/cmd/status within 0.5 s"
    )
    service = start(
        skyfix(
            "run",
            "--calibration",
            str(tmp_path / "cal.toml"),
            "--mavlink",
            f"udpin:127.0.0.1:{free_port()}",
            "--zenoh-listen",
            ep,
            "--video",
            "none",
            "--gps-input",
            "none",
            "--duration-s",
            "60",
        ),
        tmp_path / "run.log",
    )
    watch = None
    try:
        common = ("--zenoh-connect", ep, "--timeout-s", "10")
        wait_for(
            lambda: _console("status", *common, "--json").returncode == 0,
            30,
            "the service's status",
        )
        status = json.loads(_console("status", *common, "--json").stdout)
        assert status["target"]["state"] == "awaiting_target" and status["fix"] is None
        assert math.isclose(status["t"], time.time(), abs_tol=10.0)

        refused = _console("select", *common, "--box", "10,10,40,40")
        assert (
            refused.returncode == 2
            and refused.stderr.strip() == "skyfix select: error: select: no frame received yet"
        )
        bad = _console("select", *common, "--box", "10,10")
        assert bad.returncode == 2 and "'10,10': expected X,Y,W,H" in bad.stderr

        released = _console("release", *common)
        assert (
            released.returncode == 0
            and json.loads(released.stdout)["target"]["state"] == "released"
        )
        summary = _console("status", *common)
        assert summary.returncode == 0 and "target released" in summary.stdout
        acquired = _console("acquire", *common)
        assert (
            acquired.returncode == 0
            and json.loads(acquired.stdout)["target"]["state"] == "awaiting_target"
        )

        watch = start(
            skyfix("status", *common, "--watch", "--interval-s", "0.3"), tmp_path / "watch.log"
        )
        wait_for(
            lambda: (tmp_path / "watch.log").read_text().count("target awaiting_target") >= 3,
            30,
            "three status summaries",
        )
        watch.send_signal(signal.SIGINT)
        assert watch.wait(10) == 0
    finally:
        if watch is not None and watch.poll() is None:
            watch.kill()
        stop(service)
    assert service.returncode == 0, (tmp_path / "run.log").read_text()[-2000:]

"""The height live, on loopback: ``skyfix replay`` of a generated session (a barometer 0.5 m high, a downward
lidar that sees the water, a GNSS receiver that gives only HDOP/VDOP) → ``skyfix run`` → an independent Zenoh
subscriber. The status says what measured the height and how well, as its schema says; the height is the
simulator's truth, not the barometer's."""

from __future__ import annotations

import json
import socket
import sys

import numpy as np
from jsonschema import Draft202012Validator
from live_helpers import (
    SUBSCRIBER,
    free_port,
    read_jsonl,
    replay_shift,
    skyfix,
    start,
    stop,
    wait_for,
)
from test_sim_knobs import SCENARIOS

from groundstation.contracts import GROUNDSTATION
from sim_fixtures.generate import generate
from sim_fixtures.motion import Motion
from sim_fixtures.scenario import load_scenario, with_overrides

SCENARIO = with_overrides(
    load_scenario(SCENARIOS / "height_rangefinder.toml"),
    duration_s=15.0,
    uav={"baro_drift_m": 0.04},
    rangefinder={"dropouts": ()},
)


def _statuses(path):
    return [json.loads(s["payload"]) for s in read_jsonl(path) if s["key"] == "skyfix/status"]


def _rangefinder_used(path) -> bool:
    last = _statuses(path)[-1:]
    return bool(
        last
        and last[0].get("height")
        and last[0]["height"]["sources"].get("rangefinder", {}).get("used", 0) >= 30
    )


def test_live_status_says_what_measured_the_height(tmp_path):
    session = generate(SCENARIO, tmp_path / "session", video=False).session
    mav = free_port()
    ep = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    sub_out = tmp_path / "zenoh.jsonl"
    procs = [
        start(
            skyfix(
                "run",
                "--calibration",
                str(session / "session.toml"),
                "--mavlink",
                f"udpin:127.0.0.1:{mav}",
                "--zenoh-listen",
                ep,
                "--video",
                "none",
                "--gps-input",
                "none",
                "--duration-s",
                "40",
            ),
            tmp_path / "run.log",
        ),
        start(
            [sys.executable, "-c", SUBSCRIBER, ep, "skyfix/status", str(sub_out)],
            tmp_path / "sub.log",
        ),
    ]
    try:
        wait_for(lambda: bool(_statuses(sub_out)), 20, "skyfix status on Zenoh")
        procs.append(
            start(
                skyfix(
                    "replay",
                    str(session),
                    "--no-video",
                    "--mavlink-out",
                    f"udpout:127.0.0.1:{mav}",
                    "--zenoh-connect",
                    ep,
                ),
                tmp_path / "replay.log",
            )
        )
        shift = replay_shift(tmp_path / "replay.log")
        wait_for(lambda: _rangefinder_used(sub_out), 30, "the rangefinder in the height's status")
    finally:
        for p in procs:
            stop(p)
    status = _statuses(sub_out)
    schema = Draft202012Validator(json.loads(GROUNDSTATION.path_of("status").read_text()))
    bad = [e.message for s in status for e in schema.iter_errors(s)]
    assert not bad, bad[0]
    s = status[-1]
    h = s["height"]
    # about when it was taken: the height swings 0.3 m in 20 s
    tau = s["t"] - shift - SCENARIO.start_unix
    truth = float(-Motion(SCENARIO).uav_ned(np.array([tau]))[0, 2])
    assert (
        h["source"] == "rangefinder+baro+gnss"
        and h["reference"] == "takeoff"
        and h["reference_set_at"] == "boot"
    )
    assert abs(h["height_m"] - truth) < 0.1 and h["sigma_m"] < 0.1
    # 0.5 m high
    assert abs(h["ekf_height_m"] - h["height_m"] - h["bias_m"]) < 2e-3 and 0.4 < h["bias_m"] < 0.6
    assert (
        h["sources"]["rangefinder"]["refused"] == 0
        and h["sources"]["rangefinder"]["disagrees_m"] is None
    )
    assert h["armed"] is True and h["rangefinder_out_of_range"] == 0
    g = s["uav"]["gnss"]
    assert (g["fix_type"], g["h_acc_m"], g["v_acc_m"], g["hdop"], g["vdop"]) == (
        3,
        None,
        None,
        0.9,
        1.4,
    )
    assert g["sigma_horizontal_m"] == round(0.9 * 1.8, 3) and g["sigma_vertical_m"] == round(
        1.4 * 1.8, 3
    )
    assert s["uav"]["rates_hz"]["DISTANCE_SENSOR"] > 5

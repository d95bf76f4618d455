"""`skyfix evaluate --use-track` on short generated sessions whose barometer drifts: what each height source buys,
against the simulator's truth (the UUV's position, and the camera's true height from the scenario's motion)."""

import csv

import numpy as np
import pytest
from test_sim_knobs import SCENARIOS

from groundstation.cli import main
from groundstation.session.positions import read_positions_csv
from sim_fixtures.generate import generate
from sim_fixtures.motion import Motion
from sim_fixtures.scenario import load_scenario, with_overrides

# shortened, the barometer drifting at the scenarios' rates (baro_drift_m is over the whole session)
RTK = with_overrides(
    load_scenario(SCENARIOS / "height_rtk_drift.toml"),
    duration_s=120.0,
    uav={"baro_drift_m": 1.2 * 120 / 600},
)
RTK_NOISE = with_overrides(load_scenario(SCENARIOS / "height_rtk_noise.toml"), duration_s=60.0)
RANGEFINDER = with_overrides(
    load_scenario(SCENARIOS / "height_rangefinder.toml"),
    duration_s=90.0,
    uav={"baro_drift_m": 0.8 * 90 / 300},
    rangefinder={"dropouts": ((20.0, 60.0),)},
)


def evaluate(capsys, sc, tmp_path, name):
    session = generate(sc, tmp_path / name, video=False).session
    assert (
        main(
            [
                "evaluate",
                str(session),
                "--use-track",
                "--out",
                str(tmp_path / f"{name}_out"),
                "--quiet",
            ]
        )
        == 0
    )
    with open(tmp_path / f"{name}_out" / "evaluation.csv", newline="") as f:
        row = next(r for r in csv.DictReader(f) if r["method"] == "refraction")
    pos = read_positions_csv(tmp_path / f"{name}_out" / name / "refraction" / "positions.csv")
    true_h = -Motion(sc).camera_ned(np.arange(len(pos.t_unix)) / sc.fps)[:, 2]  # frame i at i / fps
    return (
        {k: float(row[k]) for k in ("mae_m", "within_2sigma", "coverage")},
        pos,
        pos.height_m - true_h,
        capsys.readouterr().err,
    )


def test_rtk_gnss_beside_a_drifting_barometer(capsys, tmp_path):
    """The water's altitude known: RTK altitudes make the height centimetre-true; the same flight without
    GNSS altitudes (fix type 0) is the barometer's 0.4-0.64 m error, and its sigma says so."""
    rtk, pos, dh, _ = evaluate(capsys, RTK, tmp_path, "rtk")
    assert rtk["coverage"] == 1.0 and rtk["mae_m"] <= 0.02 and rtk["within_2sigma"] >= 0.95
    assert np.abs(dh).max() < 0.05 and np.mean(np.abs(dh) <= 2 * pos.sigma_height_m) >= 0.95
    assert set(pos.height_source) == {"gnss_rtk"}
    baro, pos, dh, _ = evaluate(
        capsys, with_overrides(RTK, uav={"gnss_fix_type": 0}), tmp_path, "baro"
    )
    assert baro["mae_m"] > 0.2 and np.abs(dh).min() > 0.35 and set(pos.height_source) == {"amsl"}
    # not measured, but not claimed either
    assert np.mean(np.abs(dh) <= 2 * pos.sigma_height_m) >= 0.95


def test_white_rtk_noise_does_not_move_the_height(capsys, tmp_path):
    """RTK altitudes with 2 cm of white noise each (take-off reference): the height moves less than a centimetre from
    frame to frame, and a flight whose barometer is exact is located as well as without GPS_RAW_INT; with a drifting
    barometer, the drift is followed."""
    exact = with_overrides(RTK_NOISE, uav={"baro_drift_m": 0.0, "gnss_alt_error_m": 0.0})
    rtk, pos, dh, _ = evaluate(capsys, exact, tmp_path, "rtk")
    assert set(pos.height_source) == {"baro+gnss_rtk"}
    # was 1.8 cm, 5.4 cm
    assert np.sqrt(np.mean(np.diff(dh) ** 2)) < 0.01 and np.abs(dh).max() < 0.02
    alone, pos, _, _ = evaluate(
        capsys, with_overrides(exact, telemetry={"gps_raw_hz": 0.0}), tmp_path, "alone"
    )
    assert set(pos.height_source) == {"takeoff"}
    assert rtk["mae_m"] <= 1.25 * alone["mae_m"]  # was 2.6 times
    drifting = with_overrides(RTK_NOISE, uav={"baro_drift_m": 0.5})  # 0.5 m in a minute
    _, pos, dh, _ = evaluate(capsys, drifting, tmp_path, "drifting")
    assert np.abs(dh[len(dh) // 2 :]).max() < 0.03 and np.sqrt(np.mean(np.diff(dh) ** 2)) < 0.01
    assert np.mean(np.abs(dh) <= 2 * pos.sigma_height_m) >= 0.95


def test_rangefinder_that_sees_the_water_or_the_seafloor(capsys, tmp_path):
    water, pos, dh, err = evaluate(capsys, RANGEFINDER, tmp_path, "water")
    assert water["mae_m"] <= 0.02 and water["within_2sigma"] >= 0.95 and "warning" not in err
    assert np.mean(np.abs(dh) <= 2 * pos.sigma_height_m) >= 0.95
    t = pos.t_unix - pos.t_unix[0]
    assert np.all(pos.height_source[(t < 49.5) | (t > 60.5)] == "rangefinder+baro+gnss")
    # 30 s into the dropout
    assert np.all(pos.height_source[(t > 50.5) & (t < 59.5)] == "baro+gnss")
    floor, pos, dh, err = evaluate(
        capsys, with_overrides(RANGEFINDER, rangefinder={"sees": "floor"}), tmp_path, "floor"
    )
    assert err.count("height: rangefinder gives") == 1 and "sigma apart" in err  # one line
    assert "rangefinder" not in "".join(pos.height_source)  # never used
    assert floor["mae_m"] > 0.2 and np.mean(np.abs(dh) <= 2 * pos.sigma_height_m) >= 0.95
    # the disagreement is in the sigma
    assert np.median(pos.sigma_height_m) > np.median(np.abs(dh)) + 1.0


@pytest.mark.parametrize("reference", ["takeoff", "amsl"])
def test_the_uuv_at_the_surface(capsys, tmp_path, reference):
    sc = with_overrides(
        load_scenario(SCENARIOS / "surface_uuv.toml"),
        site={"water_reference": reference},
        uav={"baro_bias_m": 0.0, "baro_drift_m": 0.0, "gnss_fix_type": 0},
        duration_s=4.0,
    )
    scores, pos, _, _ = evaluate(capsys, sc, tmp_path, reference)
    assert scores["coverage"] == 1.0 and scores["mae_m"] < 0.01 and np.all(pos.depth_m == 0.0)

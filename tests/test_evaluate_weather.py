"""skyfix evaluate's columns for generated weather: coverage of the visible frames, the waves' own error, and what the
session's telemetry allows (the true pixel's solution), against independent computations from the session's files."""

import csv
import math

import numpy as np
import pytest

from groundstation.cli import main
from groundstation.session.positions import read_positions_csv
from sim_fixtures.bundle import BUNDLED_DIR
from sim_fixtures.generate import generate
from sim_fixtures.scenario import load_scenario, with_overrides

SCENARIOS = BUNDLED_DIR.parent / "scenarios"


def rows_of(path):
    with open(path, newline="") as f:
        return {r["method"]: r for r in csv.DictReader(f)}


def seen_and_fixed(session, positions):
    """Frames where track.csv has the UUV's pixel, and those of them with an ok fix (positions.csv, same frames)."""
    with open(session / "track.csv", newline="") as f:
        seen = np.array([r["u"] != "" for r in csv.DictReader(f)])
    pos = read_positions_csv(positions)
    assert len(pos) == len(seen)
    return seen, seen & (pos.status == "ok")


@pytest.fixture(scope="module")
def weather(tmp_path_factory):
    """weather_5mps_rtk for 3 s, without video (pixels from track.csv)."""
    out = tmp_path_factory.mktemp("weather") / "weather_5mps_rtk"
    generate(
        with_overrides(load_scenario(SCENARIOS / "weather_5mps_rtk.toml"), duration_s=3.0),
        out,
        video=False,
    )
    return out


def test_waves_columns_against_the_sessions_files(weather, tmp_path):
    assert main(["evaluate", str(weather), "--out", str(tmp_path), "--quiet"]) == 0
    rows = rows_of(tmp_path / "evaluation.csv")
    with open(weather / "truth_waves.csv", newline="") as f:
        waves = [
            math.hypot(float(r["wave_dn_m"]), float(r["wave_de_m"]))
            for r in csv.DictReader(f)
            if r["wave_dn_m"]
        ]
    assert len(waves) > 80
    for method, row in rows.items():
        assert float(row["wave_mae_m"]) == pytest.approx(np.mean(waves), abs=1e-9)
        seen, fixed = seen_and_fixed(weather, tmp_path / weather.name / method / "positions.csv")
        assert float(row["visible_coverage"]) == pytest.approx(fixed.sum() / seen.sum())
        # no video: the run is the true pixel's, so it is what the telemetry allows, scored afresh
        assert float(row["allowed_mae_m"]) == pytest.approx(float(row["mae_m"]), rel=1e-9)
        assert float(row["allowed_shape_m"]) == pytest.approx(float(row["shape_m"]), rel=1e-9)
        assert float(row["mae_ratio"]) == pytest.approx(1.0) and float(
            row["shape_ratio"]
        ) == pytest.approx(1.0)
    # the drone's own errors (a 2 deg compass, a 0.3 deg tilt at 25 m) are most of it, the waves centimetres
    assert (
        0.01 < float(rows["refraction"]["wave_mae_m"]) < 0.15 < float(rows["refraction"]["mae_m"])
    )


def test_without_waves_the_waves_columns_are_empty_and_coverage_counts_visible_frames(
    tmp_path, capsys
):
    session = BUNDLED_DIR / "occlusion"
    assert main(["evaluate", str(session), "--use-track", "--out", str(tmp_path), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "visible" in printed and "×shape" in printed
    for method, row in rows_of(tmp_path / "evaluation.csv").items():
        for key in ("wave_mae_m", "allowed_mae_m", "allowed_shape_m", "mae_ratio", "shape_ratio"):
            assert math.isnan(float(row[key]))
        seen, fixed = seen_and_fixed(session, tmp_path / "occlusion" / method / "positions.csv")
        assert seen.sum() < len(seen)  # occluded frames: not counted
        assert float(row["visible_coverage"]) == pytest.approx(fixed.sum() / seen.sum())
        assert float(row["visible_coverage"]) > float(row["coverage"])

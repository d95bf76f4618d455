"""skyfix evaluate: the table's numbers against independent computations."""

import argparse
import csv
import math

import numpy as np
import pytest
from pyproj import Geod

from groundstation.offline import evaluate
from groundstation.offline.evaluate import errors_m, score
from groundstation.session.positions import read_positions_csv
from groundstation.session.read import read_table
from localizer.fix import Fixes
from sim_fixtures.bundle import BUNDLED_DIR

GEOD = Geod(ellps="WGS84")


def test_score_by_hand():
    err = np.array([0.1, np.nan, 0.2, 0.3, 0.4])
    h_acc = np.array([0.1, 0.5, 0.05, 0.2, 0.1])
    s = score(err, h_acc, frames=5)
    assert (s.frames, s.fixes) == (5, 4)
    assert s.coverage == pytest.approx(0.8)
    assert s.mae_m == pytest.approx(0.25)
    assert s.rmse_m == pytest.approx(math.sqrt((0.01 + 0.04 + 0.09 + 0.16) / 4))
    assert s.p95_m == pytest.approx(0.385)  # linear between the 3rd and 4th of 4 sorted values
    assert s.max_m == pytest.approx(0.4)
    assert s.within_2sigma == pytest.approx(0.5)  # 0.1 ≤ 0.2 and 0.3 ≤ 0.4; 0.2 > 0.1, 0.4 > 0.2


def test_no_fix_at_all():
    s = score(np.full(3, np.nan), np.full(3, np.nan), frames=3)
    assert s.fixes == 0 and s.coverage == 0 and math.isnan(s.mae_m)


def fixes_at(t, lat, lon, status):
    return Fixes.of(t, status, lat=lat, lon=lon)


def test_errors_against_geodesic_offsets():
    lon0, lat0 = 10.4, 63.44
    lon1, lat1, _ = GEOD.fwd(lon0, lat0, 75.0, 2.0)  # truth moves 2 m in 2 s
    truth = {
        "t": np.array([100.0, 102.0]),
        "lat": np.array([lat0, lat1]),
        "lon": np.array([lon0, lon1]),
    }
    mid_lon, mid_lat, _ = GEOD.fwd(lon0, lat0, 75.0, 1.0)  # truth at t = 101
    dists = [0.25, 0.05, 1.3]
    lons, lats = [], []
    for d, az in zip(dists, (30.0, 200.0, 310.0)):
        lo, la, _ = GEOD.fwd(mid_lon, mid_lat, az, d)
        lons.append(lo)
        lats.append(la)
    fx = fixes_at(
        [101.0, 101.0, 101.0, 101.0, 103.0],
        [*lats, lats[0], lats[0]],
        [*lons, lons[0], lons[0]],
        ["ok", "ok", "ok", "lost", "ok"],
    )
    err = errors_m(fx, truth)
    assert np.allclose(err[:3], dists, atol=2e-4)
    assert np.isnan(err[3]) and np.isnan(err[4])  # no fix; outside the truth's span


def run_evaluate(*argv):
    p = argparse.ArgumentParser()
    evaluate.register(p.add_subparsers(), "evaluate")
    args = p.parse_args(["evaluate", *argv])
    return args.func(args)


def test_cli_table_matches_independent_computation(tmp_path, capsys):
    session = BUNDLED_DIR / "occlusion"
    assert run_evaluate(str(session), "--use-track", "--out", str(tmp_path), "--quiet") == 0
    printed = capsys.readouterr().out
    assert "occlusion" in printed and "refraction" in printed and "straight" in printed
    truth = read_table(session / "truth.csv", ("t", "lat", "lon", "depth_m"))
    n_frames = len(read_table(session / "video_frames.csv", ("frame", "t"))["t"])
    with open(tmp_path / "evaluation.csv") as f:
        rows = {r["method"]: r for r in csv.DictReader(f)}
    assert set(rows) == {"refraction", "straight"}
    for method, row in rows.items():
        pos = read_positions_csv(tmp_path / "occlusion" / method / "positions.csv")
        ok = pos.status == "ok"
        lat_t = np.interp(pos.t_unix[ok], truth["t"], truth["lat"])
        lon_t = np.interp(pos.t_unix[ok], truth["t"], truth["lon"])
        # positions.csv: 1e-9 deg ~ 0.1 mm
        _, _, d = GEOD.inv(pos.lon[ok], pos.lat[ok], lon_t, lat_t)
        # occluded frames have no fix
        assert int(row["fixes"]) == ok.sum() < n_frames == int(row["frames"])
        assert float(row["coverage"]) == pytest.approx(ok.sum() / n_frames)
        assert float(row["mae_m"]) == pytest.approx(np.mean(d), abs=1e-4)
        assert float(row["rmse_m"]) == pytest.approx(np.sqrt(np.mean(d**2)), abs=1e-4)
        assert float(row["max_m"]) == pytest.approx(np.max(d), abs=1e-4)
        assert float(row["p95_m"]) == pytest.approx(
            np.sort(d)[int(np.ceil(0.95 * len(d))) - 1], abs=2e-3
        )
        within = np.mean(d <= 2 * pos.h_acc_m[ok])
        assert float(row["within_2sigma"]) == pytest.approx(within, abs=1.5 / len(d))
    for png in ("top_view.png", "timeline.png", "status.png"):
        assert (tmp_path / "occlusion" / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_default_tracks_the_video(tmp_path):
    session = BUNDLED_DIR / "nadir_hover"
    assert run_evaluate(str(session), "--out", str(tmp_path), "--quiet") == 0
    pos = read_positions_csv(tmp_path / "nadir_hover" / "refraction" / "positions.csv")
    track = read_table(session / "track.csv", ("t", "u", "v"), allow_empty=("u", "v"))
    ok = pos.status == "ok"
    assert ok.mean() > 0.9
    assert not np.allclose(pos.u[ok], track["u"][ok], atol=1e-3)  # pixels came from the tracker
    assert np.nanmax(np.abs(pos.u[ok] - track["u"][ok])) < 5.0


def test_a_bad_session_is_reported_and_the_others_evaluated(tmp_path, capsys):
    no_truth = tmp_path / "no_truth"
    no_truth.mkdir()
    for f in (BUNDLED_DIR / "fixed_camera").iterdir():
        if f.name != "truth.csv":
            (no_truth / f.name).write_bytes(f.read_bytes())
    code = run_evaluate(
        str(no_truth),
        str(BUNDLED_DIR / "fixed_camera"),
        "--use-track",
        "--out",
        str(tmp_path / "out"),
        "--quiet",
    )
    captured = capsys.readouterr()
    assert code == 2
    err_lines = captured.err.strip().splitlines()
    assert len(err_lines) == 1 and "no_truth" in err_lines[0] and "truth.csv" in err_lines[0]
    assert "fixed_camera" in captured.out
    with open(tmp_path / "out" / "evaluation.csv") as f:
        assert [r["session"] for r in csv.DictReader(f)] == ["fixed_camera", "fixed_camera"]

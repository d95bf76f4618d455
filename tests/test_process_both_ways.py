"""``skyfix process`` tracks the video forward and backward: positions.csv stays causal, the smoothed track takes
the frames traced back from a re-acquisition (``traced_back``).

``oblique_occl`` cut to 4 s (640x360) with the UUV hidden from 1.5 to 2.5 s, as tests/test_tracking_both_ways.py:
the causal pass misses a few frames after the UUV shows again; traced back, they are located too.
positions.csv must be what the causal pass alone gives (byte for byte), and the frames traced back must have a fix
of their own in positions_smoothed.csv, where the UUV is seen (track.csv), near the truth (truth.csv).
"""

from __future__ import annotations

import csv
import shutil
from pathlib import Path

import numpy as np
import pytest

from groundstation.cli import main
from groundstation.offline.process import process_session
from groundstation.offline.smoothed import NAME as SMOOTHED_NAME
from groundstation.offline.smoothed import offline_track
from groundstation.session.positions import read_positions_csv, write_positions_csv
from groundstation.session.read import load_session
from localizer.fix_gate import MAX_ACCEL_MPS2, MAX_SPEED_MPS
from localizer.geodesy import horizontal_error_m
from sim_fixtures.generate import generate
from sim_fixtures.scenario import load_scenario, with_overrides

pytestmark = pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="needs the ffmpeg CLI")

SCENARIO = Path(__file__).resolve().parents[1] / "sim_fixtures" / "scenarios" / "oblique_occl.toml"


@pytest.fixture(scope="module")
def processed(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("occl_process")
    sc = with_overrides(load_scenario(SCENARIO), duration_s=4.0, occlusions=[[1.5, 2.5]])
    path = generate(sc, tmp / "s").session
    assert main(["process", str(path), "--out", str(tmp / "out"), "--quiet"]) == 0
    return load_session(path), tmp / "out", tmp


def _truth_error_m(session, lat, lon) -> np.ndarray:
    truth = session.truth
    lat_t = np.interp(session.frames["t"], truth["t"], truth["lat"])
    lon_t = np.interp(session.frames["t"], truth["t"], truth["lon"])
    return horizontal_error_m(lat, lon, lat_t, lon_t)


def test_positions_stay_causal_and_the_smoothed_track_takes_the_frames_traced_back(processed):
    session, out, tmp = processed
    causal = process_session(load_session(session.path), use_track=False)  # the causal pass alone
    write_positions_csv(tmp / "causal.csv", causal)
    assert (out / "positions.csv").read_bytes() == (tmp / "causal.csv").read_bytes()

    with open(out / SMOOTHED_NAME, newline="") as f:
        rows = list(csv.DictReader(f))
    smoothed = read_positions_csv(out / SMOOTHED_NAME)
    traced = np.array([r["traced_back"] == "1" for r in rows])
    own = np.array([r["status"] == "ok" and float(r["gap_s"]) == 0.0 for r in rows])
    visible = np.isfinite(session.track["u"])
    ok = causal.status == "ok"
    assert len(rows) == len(causal) == len(visible)
    assert traced.any() and not ok[traced].any()  # frames positions.csv has no fix for ...
    assert visible[traced].all()  # ... where the UUV is seen ...
    assert np.array_equal(own, ok | traced)  # ... now with a fix of their own in the smoothed track
    assert own[visible].sum() > ok[visible].sum()

    err = _truth_error_m(session, smoothed.lat, smoothed.lon)
    assert np.all(err[traced] < 2 * smoothed.h_acc_m[traced])  # none wrong
    # not worse than where the causal pass had the UUV, nor than the same frames bridged without their fixes
    assert np.max(err[traced]) <= 1.5 * np.percentile(err[ok], 95)
    before, _ = offline_track(causal, MAX_SPEED_MPS["bluerov2"], MAX_ACCEL_MPS2["bluerov2"])
    assert before.ok[traced].all() and np.all(before.gap_s[traced] > 0)
    err_before = _truth_error_m(session, before.lat, before.lon)
    print(
        f"traced back {int(traced.sum())}: error {np.mean(err[traced]):.3f} m "
        f"(bridged without them {np.mean(err_before[traced]):.3f} m); ok frames p95 "
        f"{np.percentile(err[ok], 95):.3f} m"
    )

"""A reference of known position fixes the drone's absolute offset (localizer/reference.py): the window's offset
and its sigma from white sightings, and a plain-GNSS drone's fixes against the simulator's truth (the marker's pixel
the simulator's own projection, bench/reference.py's)."""

import sys
from pathlib import Path

import numpy as np

from groundstation.offline import process
from groundstation.offline.evaluate import error_ne_m
from groundstation.offline.reference import apply as apply_reference
from groundstation.offline.reference import read_reference
from groundstation.offline.reference import sightings as marker_sightings
from groundstation.session.read import load_session, read_table
from localizer.pose import camera_pose
from localizer.reference import BLOCK_S, WINDOW_S, applied, correct, offsets, sightings
from sim_fixtures.generate import generate
from sim_fixtures.scenario import load_scenario, with_overrides

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
import reference as bench


def test_offset_is_the_windows_mean_with_its_standard_error():
    """Sightings at 10 Hz of a constant offset (0.7, -0.4) m plus 20 cm white noise per axis: the offset found within
    3 sigma of the truth, the sigma within 40 % of the white noise's standard error over the window; a time with no
    sightings near it has none."""
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 30.0, 0.1)
    true = np.array([0.7, -0.4])
    obs = true + rng.normal(0.0, 0.2, (len(t), 2))
    found = offsets(t, obs, np.zeros((len(t), 2, 4)), np.array([15.0, 100.0]))
    expected_sigma = 0.2 / np.sqrt(WINDOW_S / 0.1)  # white: the block means' scatter / sqrt(blocks)
    assert np.all(np.abs(found.offset_ne_m[0] - true) < 3 * found.sigma_ne_m[0])
    assert np.all(np.abs(found.sigma_ne_m[0] / expected_sigma - 1.0) < 0.4)
    assert found.sightings[0] == round(WINDOW_S / 0.1) + 1
    assert np.all(np.isnan(found.offset_ne_m[1])) and found.sightings[1] == 0
    assert BLOCK_S < WINDOW_S


def _marker_corrected(tmp_path, scenario: str):
    """``scenario`` for 40 s at 5 fps with the marker, geometry only (its pixel the simulator's + 0.5 px): the session,
    its fixes, which marker frames were seen, and the fixes corrected by the marker's offset."""
    sc = load_scenario(ROOT / "sim_fixtures" / "scenarios" / f"{scenario}.toml")
    sc = with_overrides(sc, duration_s=40.0, fps=5.0, marker={"enabled": True})
    generate(sc, tmp_path, video=False)
    s = load_session(tmp_path)
    fixes = process.process_session(s, use_track=True)
    cal, tel = s.calibration, s.telemetry
    t_m, u_m, v_m = bench.marker_track(tmp_path, np.random.default_rng(1), 0.5)
    ref, _ = read_reference(s)
    off, seen, jac = sightings(cal, camera_pose(cal, tel, t_m), u_m, v_m, ref)
    found = offsets(t_m[seen], off[seen], jac[seen], fixes.t_unix)
    return s, fixes, seen, correct(cal, camera_pose(cal, tel, fixes.t_unix), fixes, found)


def test_plain_gnss_drone_with_a_marker_in_view(tmp_path):
    """sensors_plain_nadir for 40 s at 5 fps (plain GNSS walk, AHRS and compass biases), a surveyed marker on the
    floor ([marker], its pixel the simulator's + 0.5 px): the absolute MAE at most a fifth of the uncorrected one, and the claim still covers: at least 90 % within
    2 h_acc, each h_acc smaller than before."""
    s, fixes, seen, better = _marker_corrected(tmp_path, "sensors_plain_nadir")
    ok = fixes.status == "ok"
    assert seen.mean() > 0.9
    before = np.hypot(*error_ne_m(fixes.t_unix, fixes.lat, fixes.lon, ok, s.truth)[ok].T)
    after = np.hypot(*error_ne_m(better.t_unix, better.lat, better.lon, ok, s.truth)[ok].T)
    assert np.mean(after) < 0.2 * np.mean(before), (np.mean(after), np.mean(before))
    assert np.mean(after <= 2 * better.h_acc_m[ok]) >= 0.9
    assert np.all(better.h_acc_m[ok] < fixes.h_acc_m[ok])


def test_an_rtk_drone_keeps_its_own_fixes_where_they_claim_less(tmp_path):
    """sensors_rtk_nadir (RTK, the same biases) with the marker as in the plain drone's test: the reference's offset is
    taken only by fixes whose own claim is larger than the corrected one; the others are left exactly as they were,
    so the RTK drone's absolute MAE is not made worse by a reference less sure than its own position."""
    s, fixes, _, better = _marker_corrected(tmp_path, "sensors_rtk_nadir")
    ok = fixes.status == "ok"
    moved = applied(fixes, better)
    assert moved.mean() < 0.5, moved.mean()
    kept = ~moved
    assert np.array_equal(better.lat[kept], fixes.lat[kept], equal_nan=True)
    assert np.array_equal(better.h_acc_m[kept], fixes.h_acc_m[kept], equal_nan=True)
    assert np.all(better.h_acc_m[moved] < fixes.h_acc_m[moved])
    before = np.hypot(*error_ne_m(fixes.t_unix, fixes.lat, fixes.lon, ok, s.truth)[ok].T)
    after = np.hypot(*error_ne_m(better.t_unix, better.lat, better.lon, ok, s.truth)[ok].T)
    assert np.mean(after) <= 1.1 * np.mean(before), (np.mean(after), np.mean(before))


def test_a_rendered_marker_is_found_and_corrects_a_plain_gnss_drone(tmp_path):
    """sensors_plain_nadir's drone for 3 s at 640x360 with a [marker] on the floor, rendered: skyfix process's
    --reference auto finds the bullseye in at least 90 % of the frames it searches, within 1 px of the simulator's
    reference_track.csv, and the fixes' absolute MAE falls below a quarter of the uncorrected one with at least 90 %
    within 2 h_acc."""
    sc = load_scenario(ROOT / "sim_fixtures" / "scenarios" / "sensors_plain_nadir.toml")
    sc = with_overrides(sc, duration_s=3.0, fps=30.0, marker={"enabled": True})
    generate(sc, tmp_path)
    s = load_session(tmp_path)
    truth = read_table(tmp_path / "reference_track.csv", ("t", "u", "v"), allow_empty=("u", "v"))
    found = read_reference(s)
    assert found is not None
    t, u, v = marker_sightings(s, *found)
    seen = np.isfinite(u)
    assert seen.mean() >= 0.9
    i = np.searchsorted(truth["t"], t[seen])
    assert np.max(np.hypot(u[seen] - truth["u"][i], v[seen] - truth["v"][i])) < 1.0
    fixes = process.process_session(s, use_track=True)
    better, cells = apply_reference(s, fixes, "auto")
    assert cells is not None and cells["ref_offset_n_m"][0] != ""
    ok = fixes.status == "ok"
    before = np.hypot(*error_ne_m(fixes.t_unix, fixes.lat, fixes.lon, ok, s.truth)[ok].T)
    after = np.hypot(*error_ne_m(better.t_unix, better.lat, better.lon, ok, s.truth)[ok].T)
    assert np.mean(after) < 0.25 * np.mean(before), (np.mean(after), np.mean(before))
    assert np.mean(after <= 2 * better.h_acc_m[ok]) >= 0.9
    assert apply_reference(s, fixes, "off") == (fixes, None)

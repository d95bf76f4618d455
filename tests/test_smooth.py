"""The smoothed offline track (localizer/smooth.py) and the gates over a whole recording (fix_gate.gate_offline).

The smoother is checked against an independent batch least-squares solution of the same
linear-Gaussian model (the initial state and every step's white acceleration as the unknowns),
on fixes whose truth is known: a constant-velocity UUV with white noise, a bias every fix
shares, gaps short and long. The offline gates on a bundled occlusion session, tracked by the
real pipeline: what the live gates hold back for a second after the re-acquisition is taken.
"""

from __future__ import annotations

import csv
import math
from dataclasses import replace

import numpy as np
import pytest

from groundstation.cli import main
from groundstation.offline.evaluate import shape_m
from groundstation.offline.process import process_session
from groundstation.offline.smoothed import COLUMNS, offline_track
from groundstation.runtime.gps_input import LOSS_STATUSES
from groundstation.session.positions import read_positions_csv
from groundstation.session.read import load_session, read_table
from localizer.fix import Fixes
from localizer.fix_gate import CONFIRM_S, FixGate, gate_offline
from localizer.geodesy import geodetic_to_ned, ned_to_geodetic
from localizer.smooth import BRIDGE_SIGMA_M, recording_fits, smooth_fixes, through_smoother
from localizer.uncertainty import H_ACC_PER_SIGMA_ISOTROPIC
from localizer.uuv_track import PROCESS_ACCEL_SHARE, WHITE_FLOOR_M
from sim_fixtures.bundle import BUNDLED_DIR

V, A = 1.5, 3.0  # a BlueROV2's bounds
FPS = 30.0
LAT0, LON0 = 63.44, 10.40


def fixes_of(t, n_m, e_m, sigma_m, status=None) -> Fixes:
    """Fixes at local north/east (m) with a claimed isotropic 1-sigma per axis."""
    status = np.full(len(t), "ok", dtype=object) if status is None else status
    lat, lon, _ = ned_to_geodetic(n_m, e_m, 0.0, LAT0, LON0, 0.0)
    lat, lon = np.where(status == "ok", lat, np.nan), np.where(status == "ok", lon, np.nan)
    s = np.full(len(t), float(sigma_m))
    return Fixes.of(
        t,
        status,
        lat=lat,
        lon=lon,
        sigma_n_m=s,
        sigma_e_m=s,
        cov_ne_m2=np.zeros(len(t)),
        h_acc_m=s * H_ACC_PER_SIGMA_ISOTROPIC,
        depth_m=np.full(len(t), 1.5),
    )


def local(lat, lon):
    n, e, _ = geodetic_to_ned(lat, lon, 0.0, LAT0, LON0, 0.0)
    return np.stack([n, e], axis=1)


def line(seconds: float, seed: int, sigma_m: float, v_ne=(0.2, -0.1)):
    """A UUV at constant velocity, its fixes with white noise of ``sigma_m`` per axis."""
    rng = np.random.default_rng(seed)
    t = 1.7e9 + np.arange(int(seconds * FPS)) / FPS
    truth = np.outer(t - t[0], v_ne)
    return t, truth, truth + rng.normal(0.0, sigma_m, truth.shape)


def batch(t, z, taken, R_m2: float, P0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Posterior means (N×2) and covariances (N×2×2) of the positions, by least squares over the initial state
    and each step's white acceleration (1-sigma PROCESS_ACCEL_SHARE·A), written out from the model, not the
    filter: x_k = F x_{k-1} + Γ w_k, Γ = σ_a (Δ²/2, Δ); the first fix is the prior's position. Third: the
    covariance (N×2×2) of the estimate's error per unit variance of white noise on the fixes, when the truth has
    no acceleration (the estimate is linear in the fixes: Σ_j L_kj L_kjᵀ)."""
    n = len(t)
    sa = PROCESS_ACCEL_SHARE * A
    dim = 4 + 2 * (n - 1)
    M = np.zeros((n, 4, dim))
    M[0, :, :4] = np.eye(4)
    for k in range(1, n):
        d = t[k] - t[k - 1]
        F = np.eye(4)
        F[0, 2] = F[1, 3] = d
        M[k] = F @ M[k - 1]
        M[k, :, 4 + 2 * (k - 1) : 4 + 2 * k] = sa * np.vstack(
            [np.eye(2) * d * d / 2, np.eye(2) * d]
        )
    pos = M[:, :2]
    used = pos[np.flatnonzero(taken)].reshape(-1, dim)
    data = used.T @ used / R_m2  # Σ Hᵀ R⁻¹ H over the fixes (the first: the prior's)
    prior_info = np.zeros((dim, dim))
    prior_info[:4, :4] = np.linalg.inv(P0)
    prior_info[:2, :2] = 0.0  # the prior's position is the first fix, counted in data
    prior_info[4:, 4:] = np.eye(dim - 4)
    cov = np.linalg.inv(prior_info + data)
    mean = cov @ (used.T @ z[np.flatnonzero(taken)].ravel()) / R_m2
    gain = (pos.reshape(-1, dim) @ cov).reshape(n, 2, dim)
    spread = (gain.reshape(-1, dim) @ (data / R_m2)).reshape(n, 2, dim)
    return pos @ mean, np.einsum("kij,kmj->kim", gain, pos), np.einsum("kij,kmj->kim", spread, gain)


def test_the_smoother_is_the_batch_least_squares_of_its_model():
    t, _, z = line(4.0, 1, 0.02)
    status = np.full(len(t), "ok", dtype=object)
    status[(t - t[0] > 1.5) & (t - t[0] < 2.2)] = "lost"  # a gap in the middle
    sm = smooth_fixes(
        fixes_of(t, z[:, 0], z[:, 1], 0.02, status), status == "ok", V, A, bridge_sigma_m=1.0
    )
    R = sm.white_share * 0.02**2 + WHITE_FLOOR_M**2
    P0 = np.diag([R, R, V * V, V * V])
    mean, cov, _ = batch(t, z - z[0], status == "ok", R, P0)
    assert sm.ok.all()
    assert np.abs(local(sm.lat, sm.lon) - (mean + z[0])).max() < 1e-6
    assert np.allclose(sm.cov_own_m2, cov, rtol=1e-6, atol=1e-12)


def test_white_noise_is_averaged_by_the_expected_factor_and_covered():
    sigma = 0.02
    t, truth, z = line(20.0, 2, sigma)
    sm = smooth_fixes(fixes_of(t, z[:, 0], z[:, 1], sigma), np.ones(len(t), bool), V, A)
    err = local(sm.lat, sm.lon) - truth
    R = sm.white_share * sigma**2 + WHITE_FLOOR_M**2
    _, _, noise = batch(t, z, np.ones(len(t), bool), R, np.diag([R, R, V * V, V * V]))
    rms_raw = math.sqrt(np.mean(np.sum((z - truth) ** 2, axis=1)))
    rms = math.sqrt(np.mean(np.sum(err**2, axis=1)))
    expected = sigma * math.sqrt(np.mean(noise[:, 0, 0] + noise[:, 1, 1]))
    assert rms < 0.5 * rms_raw  # 0.0068 m against 0.028 m
    assert 0.85 < rms / expected < 1.15
    # white noise as large as claimed: most of the claim changes frame to frame
    assert sm.white_share > 0.5
    # the claim allows accelerations
    assert rms < math.sqrt(np.mean(sm.cov_own_m2[:, 0, 0] + sm.cov_own_m2[:, 1, 1]))
    assert np.mean(np.hypot(*err.T) <= 2.0 * sm.h_acc_m) > 0.9


def test_a_shared_error_stays_in_the_smoothed_track_and_its_sigma():
    """A bias every fix shares (0.3 m north, 0.2 m west) under a claim of 0.25 m per axis, with 1 cm of white noise:
    smoothing takes out the noise, not the bias, and the smoothed claim keeps covering it."""
    t, truth, z = line(10.0, 3, 0.01)
    offset = np.array([0.3, -0.2])
    fx = fixes_of(t, z[:, 0] + offset[0], z[:, 1] + offset[1], 0.25)
    sm = smooth_fixes(fx, np.ones(len(t), bool), V, A)
    err = local(sm.lat, sm.lon) - truth
    assert np.abs(err.mean(axis=0) - offset).max() < 0.005
    assert sm.white_share < 0.01  # the claim's frame-to-frame share: 1 cm of 25 cm
    assert np.all(np.hypot(*err.T) <= 2.0 * sm.h_acc_m)
    assert np.all(sm.h_acc_m > 0.99 * fx.h_acc_m * math.sqrt(1.0 - sm.white_share))
    # the track's form is sharpened, its place is not
    assert shape_m(err) < 0.004 < shape_m(z - truth)


def test_gaps_are_bridged_within_the_bound_and_beyond_it_have_no_position():
    t, truth, z = line(10.0, 4, 0.02)
    rel = t - t[0]
    status = np.full(len(t), "ok", dtype=object)
    short, long_ = (rel > 2.0) & (rel < 2.4), (rel > 5.0) & (rel < 8.0)
    status[short | long_] = "lost"
    status[rel < 0.5] = "awaiting_target"
    fx = fixes_of(t, z[:, 0], z[:, 1], 0.02, status)
    sm, words = offline_track(fx, V, A)
    err = np.hypot(*(local(sm.lat, sm.lon) - truth).T)
    assert sm.ok[short].all() and np.all(err[short] <= 2.0 * sm.h_acc_m[short])
    assert np.all(sm.gap_s[short] == pytest.approx(rel[short][-1] - rel[short][0] + 2 / FPS))
    middle = long_ & (np.abs(rel - 6.5) < 0.5)
    assert (
        not sm.ok[middle].any()
        and np.isnan(sm.lat[middle]).all()
        and set(words[middle]) == {"lost"}
    )
    ends = long_ & sm.ok  # the gap's first and last frames are bridged, within the bound
    assert ends.sum() > 10 and np.all(
        np.linalg.eigvalsh(sm.cov_own_m2[ends])[:, -1] <= BRIDGE_SIGMA_M**2
    )
    assert np.all(err[ends] <= 2.0 * sm.h_acc_m[ends])
    assert not sm.ok[rel < 0.5].any() and set(words[rel < 0.5]) == {"awaiting_target"}


def test_fixes_off_the_track_are_refused_offline_and_bridged_over():
    """Ten frames on a look-alike 2 m away: the offline gates refuse them, the smoothed track stays on the UUV."""
    t, truth, z = line(6.0, 5, 0.01)
    away = (t - t[0] > 3.0) & (t - t[0] < 3.0 + 10 / FPS)
    z[away] += [2.0, 0.0]
    sm, _ = offline_track(fixes_of(t, z[:, 0], z[:, 1], 0.02), V, A)
    err = np.hypot(*(local(sm.lat, sm.lon) - truth).T)
    assert sm.ok[away].all() and np.all(sm.gap_s[away] > 0)  # bridged, not measured
    assert err[away].max() < 0.03
    # the first second confirmed by those after it
    assert sm.ok[~away].all() and np.all(sm.gap_s[~away] == 0)


def jitter(
    t, seed: int, amp_m: float = 0.015, white_m: float = 0.005, hz: float = 1.0
) -> np.ndarray:
    """A wave's jitter: a 1 Hz oscillation of ``amp_m`` on each axis (random phases) plus white noise."""
    rng = np.random.default_rng(seed)
    phase = rng.uniform(0.0, 2.0 * math.pi, 2)
    wave = amp_m * np.sin(2.0 * math.pi * hz * (t - t[0])[:, None] + phase)
    return wave + rng.normal(0.0, white_m, wave.shape)


def test_a_swell_after_a_calm_stretch_is_taken_offline_and_a_look_alike_still_refused():
    """2.5 s of calm (4 mm), then a 1 Hz swell of 10 cm with 2 cm of white noise, under an RTK drone's claim (0.33 m
    per axis), ten frames on a look-alike 2 m away in the swell: the live gate, its share measured on the calm, refuses
    the swell's true fixes as ``innovation``; offline its share is at least the recording's over a wave's period, so
    every true fix is taken and the look-alike's are still refused (bridged over)."""
    t, truth, _ = line(12.0, 11, 0.0)
    s = t - t[0]
    calm = (s < 2.5)[:, None]
    z = truth + np.where(calm, jitter(t, 11, 0.004, 0.001), jitter(t, 11, 0.1, 0.02))
    away = (s > 7.0) & (s < 7.0 + 10 / FPS)
    z[away] += [2.0, 0.0]
    fixes = fixes_of(t, z[:, 0], z[:, 1], 0.33)
    live = gate_offline(
        fixes, np.zeros(len(t), bool), FixGate(V, A, max_h_acc_m=math.inf, max_age_s=math.inf)
    )
    assert np.sum((live == "innovation") & ~away) > 30  # 86 of 350
    sm, status = offline_track(fixes, V, A)
    assert np.all(sm.gap_s[~away] == 0) and np.all(status == "ok")
    assert np.all(sm.gap_s[away] > 0)
    assert np.hypot(*(local(sm.lat, sm.lon) - truth)[away].T).max() < 0.05


def test_another_series_goes_through_the_same_smoother():
    """The fixes' own positions through :func:`through_smoother` are the smoothed track; a constant comes out as
    itself and a sum as the sum of its parts (the smoother is linear: an error budget adds up)."""
    t, truth, _ = line(8.0, 12, 0.0)
    z = truth + jitter(t, 12)
    fixes = fixes_of(t, z[:, 0], z[:, 1], 0.012)
    taken = np.ones(len(t), bool)
    sm = smooth_fixes(fixes, taken, V, A)
    own = through_smoother(fixes, taken, sm, V, local(fixes.lat, fixes.lon))
    assert np.abs(own - local(sm.lat, sm.lon)).max() < 1e-6
    const = through_smoother(fixes, taken, sm, V, np.tile([0.3, -0.2], (len(t), 1)))
    assert np.abs(const - [0.3, -0.2]).max() < 1e-9
    a, b = truth, z - truth
    parts = through_smoother(fixes, taken, sm, V, a) + through_smoother(fixes, taken, sm, V, b)
    assert np.abs(parts - through_smoother(fixes, taken, sm, V, z)).max() < 1e-9
    # another acceleration bound put in its place is the smoother at that bound (bench/smoothed_budget.py's window):
    # white noise keeps the vehicle's bound, so smoothing with a smaller vehicle's is the same filter
    t, _, z = line(8.0, 13, 0.02)
    fixes = fixes_of(t, z[:, 0], z[:, 1], 0.02)
    taken = np.ones(len(t), bool)
    at_vehicle, at_half = smooth_fixes(fixes, taken, V, A), smooth_fixes(fixes, taken, V, 0.5)
    assert np.all(at_half.accel_mps2 == 0.5)
    replaced = replace(at_vehicle, accel_mps2=np.full(len(t), 0.5))
    own = through_smoother(fixes, taken, replaced, V, local(fixes.lat, fixes.lon))
    assert np.abs(own - local(at_half.lat, at_half.lon)).max() < 1e-6
    # and not the vehicle's own track: the bound is what changed
    assert np.abs(own - local(at_vehicle.lat, at_vehicle.lon)).max() > 1e-3


def test_the_recordings_fits_serve_the_smoother_only_for_the_same_fixes():
    """:func:`recording_fits` of the ok fixes (computed once for the gates' floor) handed to the smoother: the same
    track, array for array, as the smoother's own where it smooths those very fixes; where the gates refused some
    (the first among them, so the positions' origin moves too), the smoother makes its own and gives what it gives
    without them."""
    t, truth, _ = line(10.0, 6, 0.0)
    z = truth + jitter(t, 6)
    fixes = fixes_of(t, z[:, 0], z[:, 1], 0.012)
    recorded = recording_fits(fixes, fixes.status == "ok")
    every = np.ones(len(t), bool)
    some = every.copy()
    some[[0, 40, 41, 200]] = False
    for taken in (every, some):
        mine = smooth_fixes(fixes, taken, V, A)
        given = smooth_fixes(fixes, taken, V, A, recorded=recorded)
        for name in vars(mine):
            assert np.array_equal(getattr(mine, name), getattr(given, name), equal_nan=True), name
    assert not np.array_equal(
        smooth_fixes(fixes, some, V, A).north_m, smooth_fixes(fixes, every, V, A).north_m
    )


@pytest.mark.parametrize("seed", [6, 7])
def test_a_waves_jitter_is_averaged_over_its_period_and_covered(seed):
    """A 1 Hz oscillation of 1.5 cm and 0.5 cm of white noise under a claim of 1.2 cm per axis: the frame-to-frame
    share misses it, the share over a wave's period finds it, and the data's acceleration (far below the vehicle's
    bound) lets the smoother average it; the smoothed claim still covers the error."""
    t, truth, _ = line(20.0, seed, 0.0)
    z = truth + jitter(t, seed)
    sm = smooth_fixes(fixes_of(t, z[:, 0], z[:, 1], 0.012), np.ones(len(t), bool), V, A)
    err = local(sm.lat, sm.lon) - truth
    rms_raw = math.sqrt(np.mean(np.sum((z - truth) ** 2, axis=1)))
    rms = math.sqrt(np.mean(np.sum(err**2, axis=1)))
    # 0.0015-0.0021 m against 0.0166 m (the vehicle's bound as the process noise: 0.006)
    assert rms < 0.25 * rms_raw
    # (1.17 / 1.2)^2 = 0.95
    assert 0.7 < sm.wave_share < 1.2 and sm.white_share == min(1.0, sm.wave_share)
    assert np.median(sm.accel_mps2) < 0.1 * A
    assert np.mean(np.hypot(*err.T) <= 2.0 * sm.h_acc_m) > 0.95


def test_white_noise_keeps_the_vehicles_bound():
    t, _, z = line(10.0, 8, 0.02)
    sm = smooth_fixes(fixes_of(t, z[:, 0], z[:, 1], 0.02), np.ones(len(t), bool), V, A)
    assert sm.wave_share < 2.0 * sm.white_share and np.all(sm.accel_mps2 == A)


def u_turn(v_mps: float, a_mps2: float, seconds: float = 12.0, straight_s: float = 4.0):
    """Straight at ``v_mps``, a U-turn at the acceleration ``a_mps2`` (radius v²/a), straight back: times, truth
    (N×2) and the turn's frames."""
    t = 1.7e9 + np.arange(int(seconds * FPS)) / FPS
    s = t - t[0]
    r = v_mps**2 / a_mps2
    turn_s = math.pi * r / v_mps
    angle = np.clip((s - straight_s) / turn_s, 0.0, 1.0) * math.pi
    n = np.where(s < straight_s, v_mps * s, v_mps * straight_s + r * np.sin(angle))
    n = np.where(s > straight_s + turn_s, v_mps * straight_s - v_mps * (s - straight_s - turn_s), n)
    e = r - r * np.cos(angle)
    return t, np.column_stack([n, e]), (s >= straight_s) & (s <= straight_s + turn_s)


@pytest.mark.parametrize(("v_mps", "seed"), [(1.0, 9), (1.5, 10)])
def test_a_turn_at_the_vehicles_acceleration_is_followed_through_the_jitter(v_mps, seed):
    """A U-turn at the BlueROV2's 3 m/s² (0.33-0.75 m radius) under the same jitter: the data's acceleration rises to
    it around the turn, the smoothed track follows (its mean error there millimetres, its largest the jitter's)."""
    t, truth, turn = u_turn(v_mps, A)
    z = truth + jitter(t, seed)
    sm = smooth_fixes(fixes_of(t, z[:, 0], z[:, 1], 0.012), np.ones(len(t), bool), V, A)
    err = local(sm.lat, sm.lon) - truth
    near = np.convolve(turn, np.ones(31), mode="same") > 0  # the turn and half a second either side
    assert np.median(sm.accel_mps2[turn]) > 0.4 * A > np.median(sm.accel_mps2[~near])
    assert np.hypot(*err[near].mean(axis=0)) < 0.01
    assert np.hypot(*err[near].T).max() < 0.04
    assert math.sqrt(np.mean(np.sum(err**2, axis=1))) < 0.6 * math.sqrt(
        np.mean(np.sum((z - truth) ** 2, axis=1))
    )
    assert np.mean(np.hypot(*err[near].T) <= 2.0 * sm.h_acc_m[near]) > 0.95


@pytest.fixture(scope="module")
def occlusion():
    session = load_session(BUNDLED_DIR / "occlusion")
    fixes = process_session(session, use_track=False)  # tracked by the real pipeline
    track = read_table(
        BUNDLED_DIR / "occlusion" / "track.csv", ("t", "u", "v"), allow_empty=("u", "v")
    )
    visible = np.isfinite(track["u"])
    assert len(track["t"]) == len(fixes) and np.allclose(track["t"], fixes.t_unix, atol=1e-3)
    return fixes, visible


def test_a_reacquired_target_is_confirmed_by_the_frames_after_it_offline(occlusion):
    fixes, visible = occlusion
    lost = np.isin(fixes.status, LOSS_STATUSES)
    live, live_gate = [], FixGate()
    for i in range(len(fixes)):  # as the live GPS_INPUT sink offers them
        if lost[i]:
            live_gate.target_lost()
        live.append(live_gate.check(fixes[i], fixes.t_unix[i]) if fixes.status[i] == "ok" else "")
    live = np.array(live, dtype=object)
    offline = gate_offline(fixes, lost, FixGate(max_h_acc_m=math.inf, max_age_s=math.inf))
    # the first fix after the loss
    back = np.flatnonzero((fixes.status == "ok") & np.r_[False, lost[:-1]])
    assert len(back) == 1
    first_second = (fixes.t_unix >= fixes.t_unix[back[0]]) & (
        fixes.t_unix < fixes.t_unix[back[0]] + 0.9 * CONFIRM_S
    )
    first_second &= fixes.status == "ok"
    assert first_second.sum() >= 20
    assert set(live[first_second]) == {"unconfirmed"}
    assert all(w is None for w in offline[first_second])
    live_cover = np.mean([w is None for w in live[visible]])
    offline_cover = np.mean([w is None for w in offline[visible]])
    sm, words = offline_track(fixes, V, A)
    # the first acquisition's second, and the re-acquisition's
    assert offline_cover > live_cover + 0.3
    # their own fixes, and the rest bridged
    assert sm.ok[visible].all() and np.all(sm.gap_s[first_second] == 0)
    assert "refused" not in set(words)


def test_process_writes_the_smoothed_track_beside_positions(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["process", str(BUNDLED_DIR / "occlusion"), "--use-track", "--out", str(out)]) == 0
    assert "smoothed:" in capsys.readouterr().out
    with open(out / "positions_smoothed.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert tuple(rows[0]) == COLUMNS
    pos = read_positions_csv(out / "positions.csv")
    # the same six first columns: report, export
    again = read_positions_csv(out / "positions_smoothed.csv")
    assert np.array_equal(again.t_unix, pos.t_unix)
    assert np.all(again.h_acc_m[again.status == "ok"] > 0)
    bridged = np.array([float(r["gap_s"]) > 0 for r in rows])
    assert np.all(pos.status[bridged] != "ok")

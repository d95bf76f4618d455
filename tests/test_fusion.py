"""Several drones' fixes of one UUV fused (localizer/fusion.py, groundstation/fuse/fuser.py), on hand-worked cases.

The end-to-end case (two live services, the fuser, ArduSub's SITL) is tests/test_sitl_fuse.py.
"""

from __future__ import annotations

import math
import subprocess

import numpy as np
import pytest
from live_helpers import skyfix, truth_errors_m
from pyproj import Geod
from scipy.optimize import brentq

from groundstation.fuse.fuser import Fuser
from groundstation.fuse.service import FixSources
from groundstation.messages import FixMessage
from groundstation.session.positions import read_positions_csv
from groundstation.testing.fuse_peers import Drone, gps_input_errors_m, ok_errors, run_fuser
from groundstation.testing.fuse_peers import key as peer_key
from localizer.fix import Fix
from localizer.fix_gate import FixGate
from localizer.fusion import (
    MAX_STEP_S,
    SHARED_TERMS,
    Estimate,
    Sample,
    SharedSigmas,
    SourceTrack,
    choose,
    fit_shared,
    fuse,
    shared_effects,
)
from localizer.uncertainty import H_ACC_PER_SIGMA_ISOTROPIC

LAT0, LON0 = 63.44, 10.40
GEOD = Geod(ellps="WGS84")


def est(n, e, sn, se, alt=-1.0, v_acc=0.3) -> Estimate:
    return Estimate(np.array([n, e], float), np.diag([sn**2, se**2]), alt, v_acc)


def test_fuse_weighs_by_the_covariances_worked_by_hand():
    # north: 0 ± 1 and 2 ± 1 → 1, variance 1/2; east: 0 ± 2 and 2 ± 1 → (0/4 + 2/1) / (1/4 + 1) = 1.6, variance 0.8
    f = fuse([est(0, 0, 1, 2, alt=-1.0, v_acc=0.2), est(2, 2, 1, 1, alt=-1.2, v_acc=0.4)])
    assert f.z == pytest.approx([1.0, 1.6])
    assert f.C == pytest.approx(np.diag([0.5, 0.8]))
    # altitude by 1/v_acc²: (−1/0.04 − 1.2/0.16) / (1/0.04 + 1/0.16) = −1.04; its accuracy the best source's
    assert f.alt_m == pytest.approx(-1.04)
    assert f.v_acc_m == pytest.approx(0.2)


def test_fuse_of_correlated_covariances_matches_the_information_form():
    C1 = np.array([[0.04, 0.03], [0.03, 0.09]])
    C2 = np.array([[0.09, -0.02], [-0.02, 0.04]])
    z1, z2 = np.array([0.1, -0.2]), np.array([-0.05, 0.1])
    f = fuse([Estimate(z1, C1, 0.0, 0.1), Estimate(z2, C2, 0.0, 0.1)])
    # the same combination as a Kalman update of z1 by z2: K = C1 (C1 + C2)⁻¹
    K = C1 @ np.linalg.inv(C1 + C2)
    assert f.z == pytest.approx(z1 + K @ (z2 - z1))
    assert f.C == pytest.approx((np.eye(2) - K) @ C1)


def test_choose_leaves_out_the_drone_that_disagrees():
    good = {
        "a": est(0.00, 0.00, 0.1, 0.1),
        "b": est(0.05, -0.03, 0.2, 0.2),
        "c": est(-0.04, 0.02, 0.15, 0.15),
    }
    assert choose(good, None) == ("a", "b", "c")
    off = dict(good, c=est(2.0, 0.0, 0.15, 0.15))  # 2 m off: 8 sigma from a
    assert choose(off, None) == ("a", "b")


def test_two_disagreeing_drones_need_the_prior_to_decide_or_there_is_no_fix():
    two = {"a": est(0.0, 0.0, 0.1, 0.1), "b": est(1.5, 0.0, 0.1, 0.1)}
    assert choose(two, None) == ()
    assert choose(two, est(1.45, 0.02, 0.1, 0.1)) == ("b",)
    # a prior halfway agrees with neither (5.3 sigma)
    assert choose(two, est(0.75, 0.0, 0.1, 0.1)) == ()
    # a vague prior agrees with both: still undecided
    assert choose(two, est(0.75, 0.0, 1.0, 1.0)) == ()


def test_source_track_moves_a_fix_on_by_its_velocity_and_grows_its_covariance():
    tr = SourceTrack(max_accel_mps2=3.0)
    v = np.array([1.0, -0.5])
    C = np.diag([0.01, 0.01])
    for k in range(16):
        t = 100.0 + k / 30.0
        tr.add(Sample(t, np.array([2.0, 3.0]) + v * (t - 100.0), C, -1.0, 0.2))
    t_last = 100.0 + 15 / 30.0
    e = tr.at(t_last + 0.1)
    assert e.z == pytest.approx(np.array([2.0, 3.0]) + v * (t_last + 0.1 - 100.0), abs=1e-9)
    grow = (0.5 * 3.0 * 0.1**2) ** 2
    assert np.diag(e.C) == pytest.approx(np.diag(C) + grow, rel=1e-6)
    assert tr.at(t_last).z == pytest.approx(tr.samples[-1].z)
    assert tr.at(t_last + MAX_STEP_S + 0.01) is None
    tr.clear()
    assert tr.at(t_last) is None


def geodetic(n_m: float, e_m: float) -> tuple[float, float]:
    """lat, lon of a point n_m north and e_m east of (LAT0, LON0), by pyproj (not the fuser's geodesy)."""
    lon, lat, _ = GEOD.fwd(LON0, LAT0, math.degrees(math.atan2(e_m, n_m)), math.hypot(n_m, e_m))
    return lat, lon


def fix(t: float, n_m: float, e_m: float, sigma_m: float) -> Fix:
    lat, lon = geodetic(n_m, e_m)
    return Fix(
        t_unix=t,
        status="ok",
        lat=lat,
        lon=lon,
        alt_amsl_m=-0.9,
        v_acc_m=0.3,
        depth_m=1.3,
        t_gnss=t,
        h_acc_m=H_ACC_PER_SIGMA_ISOTROPIC * sigma_m,
        sigma_n_m=sigma_m,
        sigma_e_m=sigma_m,
        cov_ne_m2=0.0,
        frame=0,
    )


def drive(
    fuser: Fuser,
    offsets: dict[str, tuple[float, float, float]],
    seconds: float,
    t0: float = 1000.0,
    lost: dict[str, tuple[float, float]] | None = None,
    from_s: float = 0.0,
) -> list[Fix]:
    """Each source at 30 fps (staggered by a few ms) seeing the UUV going north at 0.3 m/s, with a constant
    offset (n, e) and its sigma; ``lost``: source → (from, to) seconds without fixes; ``from_s``: the first frame's
    seconds after ``t0``. The fused fixes."""
    out = []
    for k in range(round(from_s * 30), round((from_s + seconds) * 30)):
        for i, (name, (dn, de, sigma)) in enumerate(sorted(offsets.items())):
            t = t0 + k / 30.0 + 0.004 * i
            if lost and name in lost and lost[name][0] <= t - t0 < lost[name][1]:
                continue
            fused = fuser.on_fix(name, fix(t, 0.3 * (t - t0) + dn, de, sigma), t + 0.08)
            if fused is not None:
                out.append(fused)
    return out


def new_fuser() -> Fuser:
    return Fuser(lambda: FixGate(max_age_s=0.5), 3.0, sources=("a", "b", "c"))


def north_east(f: Fix, t0: float = 1000.0) -> tuple[float, float]:
    """The fix's offset from the UUV's true place (m), by pyproj."""
    az, _, dist = GEOD.inv(LON0, LAT0, f.lon, f.lat)
    n, e = dist * math.cos(math.radians(az)), dist * math.sin(math.radians(az))
    return n - 0.3 * (f.t_gnss - t0), e


def test_fuser_weighs_the_better_drone_more_and_rejects_the_one_off_its_sigma():
    fuser = new_fuser()
    fused = drive(fuser, {"a": (0.10, 0.0, 0.1), "b": (-0.10, 0.0, 0.2), "c": (3.0, 0.0, 0.2)}, 4.0)
    ok = [f for f in fused if f.ok]
    assert len(ok) > 60 and all(f.status in ("ok", "disagree") for f in fused)
    # a and b: north offsets 0.1 (σ 0.1) and −0.1 (σ 0.2) → (0.1/0.01 − 0.1/0.04) / (1/0.01 + 1/0.04) = 0.06
    n, e = north_east(ok[-1])
    assert n == pytest.approx(0.06, abs=0.005) and e == pytest.approx(0.0, abs=0.005)
    assert ok[-1].sigma_n_m == pytest.approx(1 / math.sqrt(1 / 0.01 + 1 / 0.04), rel=0.02)
    st = fuser.status(2000.0)["sources"]
    assert st["c"]["rejected"] > 60 and st["c"]["used"] == 0
    assert fuser.status(2000.0)["last_sources"] == ["a", "b"]


def test_a_drone_dropping_out_leaves_no_gap_and_it_rejoins_after_its_gate_confirms_it():
    fuser = new_fuser()
    fused = drive(
        fuser, {"a": (0.05, 0.0, 0.1), "b": (-0.05, 0.0, 0.1)}, 6.0, lost={"b": (2.0, 4.0)}
    )
    ok = [f for f in fused if f.ok]
    gaps = np.diff([f.t_unix for f in ok])
    assert gaps.max() < 0.1, gaps.max()  # a alone carries on through b's absence
    during = [north_east(f)[0] for f in ok if 2.3 < f.t_gnss - 1000.0 < 3.9]
    assert np.allclose(during, 0.05, atol=0.005)  # a's own
    after = [north_east(f)[0] for f in ok if f.t_gnss - 1000.0 > 5.2]
    # b back (confirmed by its gate within a second) and averaged in
    assert np.allclose(after, 0.0, atol=0.005)


def test_disagreeing_pair_with_nothing_to_decide_is_no_fix():
    fuser = new_fuser()
    fused = drive(fuser, {"a": (0.0, 0.0, 0.1), "b": (2.0, 0.0, 0.1)}, 2.0)
    after_confirm = [f for f in fused if f.t_gnss - 1000.0 > 1.2]
    assert after_confirm and all(
        f.status == "disagree" and math.isnan(f.lat) for f in after_confirm
    )


def test_garbage_and_foreign_payloads_are_counted_and_change_nothing():
    fuser = new_fuser()
    sources = FixSources(None, "skyfix/uuv/x/drone/*/fix", fuser, [])
    good = FixMessage.of(fix(1000.0, 0.0, 0.0, 0.1)).to_json()
    for payload in (
        b"\xff\xfe",
        b"{}",
        b'{"schema": "skyfix.fix/1"}',
        b"[" * 100000,
        str(good).encode(),
        (str(good).replace("'", '"')[:-1] + ', "extra": 1}').encode(),
    ):
        sources.on_payload("skyfix/uuv/x/drone/a/fix", payload, 1000.1)
    assert sources.bad == 6 and fuser.sources == {}


#: name: (UAV height m, UAV yaw deg, gimbal pitch deg, gimbal yaw deg): a looks 80° down from 9 m, b 60° down from
#: 13 m and another side
DRONES = {"a": (9.0, 190.0, -80.0, 200.0), "b": (13.0, 100.0, -60.0, 110.0)}
DRONE_SCENARIO = """
name = "fuse_{name}"
description = "drone {name} of two over one UUV (tests/test_fusion.py)"
seed = 16
duration_s = 20.0

[mount]
attitude_source = "gimbal_device"
gimbal_frame = "earth"
pitch_deg = {pitch}
yaw_deg = {gimbal_yaw}

[uav]
height_m = {height}
yaw_deg = {yaw}

[uuv]
depth_m = 1.3

[telemetry]
attitude_noise_deg = 0.2
"""


def test_two_generated_drones_over_one_dive_fuse_below_the_better_one(tmp_path):
    """The simulator's one dive seen by two drones (a at 9 m looking 80° down, b at 13 m looking 60° down from
    another side; each with its own attitude noise, pixels from track.csv), each processed by ``skyfix process``,
    their fixes fed to the fuser in the order they would arrive (b's 50 ms later): the fused error against the
    truth is below the better drone's."""
    fixes = {}
    for name, (height, yaw, pitch, gimbal_yaw) in DRONES.items():
        (tmp_path / f"{name}.toml").write_text(
            DRONE_SCENARIO.format(
                name=name, height=height, yaw=yaw, pitch=pitch, gimbal_yaw=gimbal_yaw
            )
        )
        session = tmp_path / f"session_{name}"
        for cmd in (
            ("sim", str(tmp_path / f"{name}.toml"), "--out", str(session), "--no-video", "--quiet"),
            ("process", str(session), "--use-track", "--out", str(tmp_path / name), "--quiet"),
        ):
            done = subprocess.run(
                skyfix(*cmd), check=False, capture_output=True, text=True, timeout=300
            )
            assert done.returncode == 0, done.stderr[-2000:]
        fixes[name] = read_positions_csv(tmp_path / name / "positions.csv")
    truth = (tmp_path / "session_a" / "truth.csv").read_text()
    assert truth == (tmp_path / "session_b" / "truth.csv").read_text(), (
        "the two drones must see the same dive"
    )
    arrivals = sorted(
        (fixes[name].t_unix[i] + delay, name, i)
        for name, delay in (("a", 0.10), ("b", 0.15))
        for i in range(len(fixes[name]))
    )
    fuser = Fuser(lambda: FixGate(max_age_s=0.5), 3.0, sources=tuple(fixes))
    fused = [
        f for now, name, i in arrivals if (f := fuser.on_fix(name, fixes[name][i], now)) is not None
    ]
    ok = [f for f in fused if f.ok]
    assert len(ok) > 0.9 * len(fixes["a"]) and fuser.disagreements == 0

    def mae(fs) -> float:
        return float(
            np.mean(
                truth_errors_m(
                    tmp_path / "session_a",
                    [f.t_unix for f in fs],
                    [f.lat for f in fs],
                    [f.lon for f in fs],
                )
            )
        )

    t_fused = ok[0].t_unix  # from when both drones were confirmed by their gates
    own = {
        name: mae(
            [
                f
                for f in (fixes[name][i] for i in range(len(fixes[name])))
                if f.ok and f.t_unix >= t_fused
            ]
        )
        for name in fixes
    }
    print(
        f"\nfused MAE {mae(ok):.4f} m, drone a {own['a']:.4f} m, drone b {own['b']:.4f} m; fused h_acc "
        f"{np.mean([f.h_acc_m for f in ok]):.3f} m"
    )
    assert mae(ok) < min(own.values()), (mae(ok), own)


# -- trust: shared errors, configured sources, the future, floors, the fused track (issue 29) -------------------------


def shared_gnss(sigma_m: float) -> np.ndarray:
    G = np.zeros((2, len(SHARED_TERMS)))
    G[0, SHARED_TERMS.index("gnss_n")] = G[1, SHARED_TERMS.index("gnss_e")] = sigma_m
    return G


def test_drones_sharing_an_error_do_not_average_it_away_worked_by_hand():
    # four drones, each 0.2 m (per axis) of its own and 0.1 m of GNSS error they all share:
    # P = W/N + S = 0.04/4 + 0.01 = 0.02 (taken as independent: 0.05/4 = 0.0125)
    G = fit_shared(np.eye(2) * 0.05, shared_gnss(0.1))
    one = Estimate(np.zeros(2), np.eye(2) * 0.05, -1.0, 0.3, G)
    assert one.C == pytest.approx(np.eye(2) * 0.05) and one.W == pytest.approx(np.eye(2) * 0.04)
    assert fuse([one] * 4).C == pytest.approx(np.eye(2) * 0.02)
    many = fuse([one] * 400).C  # 0.04/400 + 0.01: never below the shared 0.01
    assert many == pytest.approx(np.eye(2) * 0.0101) and np.all(np.diag(many) >= 0.01)
    # a shared error moving two drones oppositely (the depth, seen from opposite sides) cancels: z_a = x + g s + w_a,
    # z_b = x − g s + w_b → x = (z_a + z_b)/2, north variance 0.04/2 = 0.02 (taken as independent: 1/(2/0.05) = 0.025)
    Ga, Gb = np.zeros((2, len(SHARED_TERMS))), np.zeros((2, len(SHARED_TERMS)))
    Ga[0, 0], Gb[0, 0] = 0.1, -0.1
    C = np.diag([0.05, 0.04])
    f = fuse(
        [
            Estimate(np.array([0.3, 0.0]), C, -1.0, 0.3, Ga),
            Estimate(np.array([-0.1, 0.0]), C, -1.0, 0.3, Gb),
        ]
    )
    assert f.z == pytest.approx([0.1, 0.0]) and f.C == pytest.approx(np.diag([0.02, 0.02]))


def test_shared_errors_are_held_within_the_claim():
    # claims 2 cm north, 5 cm east; the drones are said to share 10 cm
    C = np.diag([0.02**2, 0.05**2])
    G = fit_shared(C, shared_gnss(0.1))
    # 3/4 of the claim where it is smallest
    assert G @ G.T == pytest.approx(np.eye(2) * 0.75 * 0.02**2)
    assert np.all(np.linalg.eigvalsh(C - G @ G.T) >= 0.25 * 0.02**2 - 1e-12)
    # within it: as it is
    assert fit_shared(C, shared_gnss(0.01)) == pytest.approx(shared_gnss(0.01))


def test_shared_effects_follow_each_drones_geometry():
    # the UUV 3 m north and 4 m east of the UAV 9 m above the water, 1.3 m deep; the ray's slopes in air and water by
    # Snell, solved here independently: rho = h tan(a) + d tan(w), sin(a) = 1.34 sin(w)
    f = Fix(
        t_unix=0.0,
        status="ok",
        north_m=3.0,
        east_m=4.0,
        height_m=9.0,
        depth_m=1.3,
        sigma_depth_m=0.05,
        sigma_height_m=0.4,
        height_source="baro+gnss",
    )
    a = brentq(
        lambda a: 9.0 * math.tan(a) + 1.3 * math.tan(math.asin(math.sin(a) / 1.34)) - 5.0, 0.0, 1.5
    )
    w = math.asin(math.sin(a) / 1.34)
    along = np.array([0.6, 0.8])
    G = shared_effects(
        f, SharedSigmas(gnss_m=0.1, height_m=0.3, clock_s=0.01), np.array([0.3, -0.2])
    )
    assert G[:, 0] == pytest.approx(along * math.tan(w) * 0.05, rel=1e-6)
    # the shared 0.3, below the fix's 0.4
    assert G[:, 1] == pytest.approx(along * math.tan(a) * 0.3, rel=1e-6)
    assert G[:, 2:4] == pytest.approx(np.eye(2) * 0.1) and G[:, 4] == pytest.approx([0.003, -0.002])
    # its own height measurement: the weather's trend does not enter
    f.height_source = "rangefinder"
    assert shared_effects(f, SharedSigmas(height_m=0.3))[:, 1] == pytest.approx([0.0, 0.0])


def test_fixes_from_unconfigured_drones_are_counted_and_never_fused():
    fuser = Fuser(lambda: FixGate(max_age_s=0.5), 3.0, sources=("a",))
    fused = drive(
        fuser, {"a": (0.0, 0.0, 0.1), "x": (20.0, 0.0, 0.05), "y": (20.0, 0.1, 0.05)}, 3.0
    )
    ok = [f for f in fused if f.ok]
    assert len(ok) > 40 and max(abs(north_east(f)[0]) for f in ok) < 0.01
    st = fuser.status(2000.0)
    assert st["unconfigured"] == {"x": 90, "y": 90} and set(st["sources"]) == {"a"}
    assert st["last_sources"] == ["a"] and st["configured"] == ["a"]


def test_a_fix_from_the_future_is_refused_and_the_fusion_goes_on():
    fuser = new_fuser()
    two = {"a": (0.0, 0.0, 0.1), "b": (0.02, 0.0, 0.1)}
    before = drive(fuser, two, 2.0)
    t = 1002.0
    # GNSS time a day ahead (station time right), then both a day ahead
    for t_gnss, t_unix in ((t + 86400.0, t), (t + 86400.0, t + 86400.0)):
        day_ahead = fix(t, 0.3 * 2.0, 0.0, 0.1)
        day_ahead.t_gnss, day_ahead.t_unix = t_gnss, t_unix
        assert fuser.on_fix("a", day_ahead, t + 0.08) is None
    after = drive(fuser, two, 2.0, from_s=2.01)
    assert sum(f.ok for f in before) > 20
    ok_after = [f for f in after if f.ok]
    assert len(ok_after) > 50 and ok_after[-1].t_unix > 1003.9  # a's fixes still taken
    refused = fuser.status(2000.0)["sources"]["a"]["refused"]
    assert refused["future"] == 2 and set(refused) == {"future", "unconfirmed"}, (
        refused
    )  # nothing held back
    assert fuser.status(2000.0)["last_sources"] == ["a", "b"]


def test_a_source_claiming_far_less_than_it_sits_off_the_others_is_floored():
    # beside one real drone (0.25 m per axis, on the UUV), a fake 0.8 m north claiming 0.014 m (h_acc 0.02): they
    # agree by their claims (3.2 sigma); unfloored the fuser would follow the fake (0.797 m off, claiming 0.014 m)
    fuser = new_fuser()
    ok = [f for f in drive(fuser, {"a": (0.0, 0.0, 0.25), "c": (0.8, 0.0, 0.014)}, 4.0) if f.ok]
    both = [f for f in ok if fuser.sources["c"].used and f.t_gnss > 1001.5]
    assert both and fuser.status(2000.0)["last_sources"] == ["a", "c"]
    for f in (
        both
    ):  # the disagreement floors both (nothing tells which is right): the claim covers the error
        n, _ = north_east(f)
        assert abs(n) <= 2.0 * f.sigma_n_m, (n, f.sigma_n_m)
    assert fuser.sources["c"].floor_m > 0.7
    # with two real drones beside it, the fake alone is floored and barely moves the fusion
    fuser = new_fuser()
    ok = [
        f
        for f in drive(
            fuser, {"a": (0.05, 0.0, 0.25), "b": (-0.05, 0.0, 0.25), "c": (0.8, 0.0, 0.014)}, 4.0
        )
        if f.ok and f.t_gnss > 1001.5
    ]
    assert ok and fuser.status(2000.0)["last_sources"] == ["a", "b", "c"]
    assert max(abs(north_east(f)[0]) for f in ok) < 0.1  # (0.8 x 2.0) / (16 + 16 + 2.0) = 0.047
    st = fuser.status(2000.0)["sources"]
    assert st["c"]["floor_m"] > 0.7 and st["a"]["floor_m"] < 0.05 and st["b"]["floor_m"] < 0.05


def test_a_source_scattering_beyond_its_claim_is_floored_by_its_own_scatter():
    fuser = Fuser(lambda: FixGate(max_age_s=0.5), 3.0, sources=("a",))
    rng = np.random.default_rng(5)
    ok = []
    for k in range(150):  # claims 0.05 m per axis, scatters 0.1 m from frame to frame
        t = 1000.0 + k / 30.0
        n, e = rng.normal(0.0, 0.1, 2)
        fused = fuser.on_fix("a", fix(t, 0.3 * (t - 1000.0) + n, e, 0.05), t + 0.08)
        ok += [fused] if fused is not None and fused.ok else []
    late = [f for f in ok if f.t_gnss > 1003.0]
    assert late and min(f.sigma_n_m for f in late) > 0.08, [round(f.sigma_n_m, 3) for f in late]


def test_a_fused_position_beyond_where_the_uuv_can_be_is_not_sent_as_valid():
    # a alone fused for 2 s; then b and c, agreeing with each other, appear 20 m east: once their own gates confirm
    # them they outnumber a, and the fusion jumps 20 m in a frame
    fuser = new_fuser()
    fused = drive(fuser, {"a": (0.0, 0.0, 0.1)}, 2.0)
    fused += drive(
        fuser,
        {"a": (0.0, 0.0, 0.1), "b": (0.0, 20.0, 0.1), "c": (0.0, 20.05, 0.1)},
        3.0,
        from_s=2.0,
    )
    assert fuser.status(2000.0)["last_sources"] == ["b", "c"]
    ok = [f for f in fused if f.ok]
    assert len(ok) > 60 and max(abs(north_east(f)[1]) for f in ok) < 0.01
    assert fused[-1].status == "off_track" and fuser.output.refused > 30


def test_fuse_refuses_to_start_without_its_sources():
    for extra, named in (
        ((), "--source = None"),
        (("--source", "a*"), "--source = 'a*'"),
        (("--source", "a", "--sources", "skyfix/uuv/rov1/drone/b/fix"), "--source = 'a'"),
    ):
        done = subprocess.run(
            skyfix("fuse", "--uuv", "rov1", *extra, "--duration-s", "1"),
            check=False,
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert done.returncode == 2 and done.stderr.count("\n") == 1 and named in done.stderr, (
            done.stderr
        )


def test_fuse_on_zenoh_takes_its_sources_only_and_goes_on_past_a_fix_from_the_future(tmp_path):
    """A real ``skyfix fuse --source a --source b`` on loopback: two strangers publishing 20 m away on drone keys of
    the UUV reach neither the fused fixes nor GPS_INPUT; a's fix stamped a day ahead is refused and the fusion goes
    on."""
    drones = [
        Drone("a", (0.02, 0.0)),
        Drone("b", (-0.02, 0.0)),
        Drone("x", (0.0, 20.0), 0.01, 0.05),
        Drone("y", (0.0, 20.1), 0.01, 0.05),
    ]
    final, fused, gps_input, t0 = run_fuser(
        tmp_path, ["a", "b"], drones, 5.0, ahead={2.5: ("a", 86400.0)}
    )
    errors = ok_errors(fused, t0)
    fusion = final["fusion"]
    print(
        f"\n{len(errors)} ok fused fixes, largest error {np.abs(errors[:, :2]).max():.3f} m; unconfigured "
        f"{fusion['unconfigured']}; a refused {fusion['sources'][peer_key('a')]['refused']}"
    )
    assert len(errors) > 30 and np.abs(errors[:, :2]).max() < 0.5
    assert set(fusion["unconfigured"]) == {peer_key("x"), peer_key("y")}
    assert min(fusion["unconfigured"].values()) > 30 and set(fusion["sources"]) == {
        peer_key("a"),
        peer_key("b"),
    }
    assert fusion["sources"][peer_key("a")]["refused"]["future"] == 1
    late = [f for f in fused if f["status"] == "ok" and f["t"] > t0 + 3.5]
    assert len(late) > 10 and fusion["last_sources"] == [peer_key("a"), peer_key("b")]
    valid = gps_input_errors_m(gps_input, t0)
    assert len(valid) > 10 and valid.max() < 1.0, valid.max()

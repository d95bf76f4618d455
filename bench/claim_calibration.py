"""Is the claim calibrated across a platform's population of sensor biases? The share of fixes within 2·h_acc.

    .venv/bin/python bench/claim_calibration.py [--seeds 30] [--duration 20] [--fps 2] [--work /tmp/skyfix-claim]
                                                [--out bench/results/claim_calibration.txt] [--only WORD ...]
                                                [--as-written]

A drone's biases do not average out over a flight: one session is all in or all out of its claim. "Calibrated"
is a statement about the platform: over the drones (and flights) its configuration describes, 90-98 % of fixes
within 2·h_acc. So for each condition (RTK / plain GNSS x nadir / oblique x two heights, and wind waves of
2/5/8 m/s where the simulator has ``[waves]``), ``--seeds`` short geometry-only sessions (``--no-video``, the true
pixel from track.csv) are flown by drones whose biases are drawn from the platform's distributions
(:data:`PLATFORM`: per axis, N(0, sigma)): the stabilised gimbal's levelling error, the AHRS's tilt, the compass;
the GNSS walk, the AHRS's wander and the barometer's wander are the simulator's own processes of each seed. The
biases are drawn stratified (:func:`population`): each tilt's size (a 2-D normal's radius) and the compass bias at
their ``--seeds`` quantiles, paired at random, the tilts' directions uniform. One drone is all in or all out of its claim, so ``--seeds`` random draws would measure their own luck
(100 of them: the share within 2·h_acc anywhere within about ±1.5 % of what the claim holds, and the same luck on
every condition, which all fly the same drones). Each
session's ``[uncertainty]`` is what the simulator writes for its sensors, with ``tilt_deg`` and ``yaw_deg`` set
to the platform's (the population's) sigmas, as a field team's configuration would state them: it knows its
platform, not this drone's draw; and ``pixel_px`` 0 (``--pixel-px``): the true pixel has no error of its own.
``--as-written`` keeps the session's own table (the draws' magnitudes, or skyfix's defaults with an older
simulator).

Printed per condition: fixes (sessions), the pooled share within 2·h_acc, the share a calibrated claim gives
("calib.": a normal error of each fix's own claimed covariance, so 95.4 % for an error along one axis to 98.2 % for
a circular one), the share within h_acc, the share of
sessions that are entirely within 2·h_acc, RMS error and RMS h_acc and their ratio (1: the claim is the error's DRMS; well below 1:
loose), MAE and median h_acc; with waves the RMS of the waves' own error (truth_waves.csv), the RMS of the
claim's wave term alone (every other sigma 0) and the share of the waves' error within twice that.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from scipy.stats import norm

ROOT = Path(__file__).resolve().parents[1]

from groundstation.offline import process
from groundstation.offline.evaluate import error_ne_m
from groundstation.session.read import load_session, read_table
from sim_fixtures.generate import generate
from sim_fixtures.scenario import Scenario, load_scenario, with_overrides

SCENARIOS = ROOT / "sim_fixtures" / "scenarios"
#: The platform's population (1-sigma per axis, degrees): a stabilised gimbal's levelling error, the AHRS's tilt
#: (in the camera only through a servo mount or a fixed camera; here the lever arm) and the compass's bias.
PLATFORM = {"gimbal_level_deg": 0.2, "ahrs_tilt_deg": 0.2, "compass_deg": 1.5}
WANDER = {"wander_deg": 0.05, "wander_s": 60.0, "baro_wander_m": 0.15, "baro_noise_m": 0.03}
VIEWS = {"nadir": "sensors_{}_nadir", "oblique": "sensors_{}_oblique"}
HEIGHTS_M = {"nadir": (10.0, 25.0), "oblique": (8.0, 20.0)}
WINDS_MPS = (2.0, 5.0, 8.0)


@dataclass(frozen=True)
class Condition:
    name: str
    gnss: str  # rtk | plain
    view: str  # nadir | oblique
    height_m: float
    wind_mps: float = 0.0


def has_waves() -> bool:
    return "waves" in Scenario.__dataclass_fields__


def conditions() -> list[Condition]:
    out = [
        Condition(f"{g}_{v}_{h:g}m", g, v, h)
        for g in ("rtk", "plain")
        for v in VIEWS
        for h in HEIGHTS_M[v]
    ]
    if has_waves():
        out += [
            Condition(f"rtk_{v}_{HEIGHTS_M[v][1]:g}m_wind{w:g}", "rtk", v, HEIGHTS_M[v][1], w)
            for v in VIEWS
            for w in WINDS_MPS
        ]
    return out


def population(seeds: int) -> np.ndarray:
    """The biases of ``seeds`` drones of the platform (seeds, 5), in their sigmas (gimbal level x2, AHRS tilt x2,
    compass), stratified: at the quantiles (i + 0.5) / seeds, paired at random (the same for every condition), each
    tilt's size (its two axes a circular normal: a Rayleigh radius) in a uniformly drawn direction, and the compass
    bias (a normal): the population's spread and tails, not a sample's luck."""
    rng = np.random.default_rng(2028)
    q = (np.arange(seeds) + 0.5) / seeds
    tilts = []
    for _ in range(2):
        radius = rng.permutation(np.sqrt(-2.0 * np.log1p(-q)))
        angle = rng.uniform(0.0, 2.0 * np.pi, seeds)
        tilts += [radius * np.cos(angle), radius * np.sin(angle)]
    return np.column_stack([*tilts, rng.permutation(norm.ppf(q))])


def draw_sensors(seed: int, seeds: int) -> dict:
    """Drone ``seed``'s biases (``[sensors]``) of :func:`population` ``seeds``, in :data:`PLATFORM`'s sigmas."""
    g, a, c = (PLATFORM[k] for k in ("gimbal_level_deg", "ahrs_tilt_deg", "compass_deg"))
    level_n, level_e, roll, pitch, yaw = population(seeds)[seed] * (g, g, a, a, c)
    return {
        "gimbal_level_deg": (float(level_n), float(level_e)),
        "roll_bias_deg": float(roll),
        "pitch_bias_deg": float(pitch),
        "yaw_bias_deg": float(yaw),
        **WANDER,
    }


def scenario(c: Condition, seed: int, seeds: int, duration_s: float, fps: float) -> Scenario:
    sc = load_scenario(SCENARIOS / f"{VIEWS[c.view].format(c.gnss)}.toml")
    tables = {
        "name": f"{c.name}_s{seed}",
        "seed": 1000 + seed,
        "duration_s": duration_s,
        "fps": fps,
        "uav": {"height_m": c.height_m},
        "sensors": {**draw_sensors(seed, seeds), "gnss_mode": c.gnss},
    }
    if c.wind_mps:
        tables["waves"] = {"wind_mps": c.wind_mps}
    return with_overrides(sc, **tables)


def platform_claim(cal, pixel_px: float):
    """The calibration with the platform's tilt and compass sigmas in ``[uncertainty]`` (see the module doc; a
    stabilised gimbal's tilt carries its own levelling error, not the AHRS's) and ``pixel_px``."""
    yaw = float(np.hypot(PLATFORM["compass_deg"], WANDER["wander_deg"]))
    return replace(
        cal,
        sigmas=replace(
            cal.sigmas, tilt_deg=PLATFORM["gimbal_level_deg"], yaw_deg=yaw, pixel_px=pixel_px
        ),
    )


def waves_only(cal):
    """The calibration with every sigma 0 but the wind's: the claim's wave term alone."""
    quiet = {
        f: 0.0
        for f in (
            "pixel_px",
            "tilt_deg",
            "yaw_deg",
            "height_m",
            "baro_drift_10min_m",
            "depth_m",
            "uav_horizontal_m",
            "time_s",
            "surface_amsl_m",
        )
    }
    return replace(cal, sigmas=replace(cal.sigmas, **quiet))


#: directions (radians) over which :func:`calibrated_share` integrates
_ANGLES = np.linspace(0.0, np.pi, 720, endpoint=False)


def calibrated_share(fixes, ok) -> np.ndarray:
    """Per fix, the share within 2·h_acc of a normal error of the fix's own claimed covariance (sigma_n, sigma_e,
    cov_ne): what a calibrated claim of that shape holds (95.4 % along one axis, 98.2 % circular). Exact: with
    variances a, b along its axes, a standard normal (ρ cos θ, ρ sin θ) is within when
    ρ² (a cos² θ + b sin² θ) <= 4 (a + b), which for ρ² (exponential, mean 2) has probability
    1 − exp(−2 (a + b) / (a cos² θ + b sin² θ)), averaged over θ."""
    cov = np.zeros((int(ok.sum()), 2, 2))
    cov[:, 0, 0], cov[:, 1, 1] = fixes.sigma_n_m[ok] ** 2, fixes.sigma_e_m[ok] ** 2
    cov[:, 0, 1] = cov[:, 1, 0] = fixes.cov_ne_m2[ok]
    axes = np.clip(np.linalg.eigvalsh(cov), 0.0, None)  # (n, 2) the variances along its axes
    along = axes @ np.stack([np.cos(_ANGLES) ** 2, np.sin(_ANGLES) ** 2])  # (n, angles)
    with np.errstate(divide="ignore"):
        return np.mean(1.0 - np.exp(-2.0 * axes.sum(axis=1, keepdims=True) / along), axis=1)


def session_errors(path: Path, pixel_px: float | None) -> tuple[np.ndarray, ...]:
    """(horizontal error, h_acc, :func:`calibrated_share`, the waves' own error, the claim's wave term) per fixed
    frame (m) of the true pixel's refraction fixes; ``pixel_px`` None: the session's own ``[uncertainty]``, else the
    platform's (:func:`platform_claim`)."""
    s = load_session(path)
    if pixel_px is not None:
        s.calibration = platform_claim(s.calibration, pixel_px)
    fixes = process.process_session(s, use_track=True)
    ok = fixes.status == "ok"
    err = np.hypot(*error_ne_m(fixes.t_unix, fixes.lat, fixes.lon, ok, s.truth).T)[ok]
    waves = wave_acc = np.full(err.shape, np.nan)
    if (path / "truth_waves.csv").is_file():
        w = read_table(
            path / "truth_waves.csv",
            ("t", "wave_dn_m", "wave_de_m"),
            allow_empty=("wave_dn_m", "wave_de_m"),
        )
        waves = np.hypot(w["wave_dn_m"], w["wave_de_m"])[ok]
        s.calibration = waves_only(s.calibration)
        wave_acc = process.process_session(s, use_track=True).h_acc_m[ok]
    return err, fixes.h_acc_m[ok], calibrated_share(fixes, ok), waves, wave_acc


def fly(
    c: Condition, seeds: int, duration_s: float, fps: float, work: Path, pixel_px: float | None
) -> list:
    """:func:`session_errors` of ``seeds`` drones of the platform in condition ``c`` (sessions under ``work``)."""
    per_seed = []
    for seed in range(seeds):
        out = work / c.name / f"s{seed}"
        generate(scenario(c, seed, seeds, duration_s, fps), out, video=False)
        per_seed.append(session_errors(out, pixel_px))
    return per_seed


def rms(x) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


@dataclass(frozen=True)
class Pooled:
    fixes: int
    sessions: int
    within_2sigma: float  # share of the fixes within 2·h_acc
    calibrated: float  # ... that a calibrated claim would hold (:func:`calibrated_share`)
    # ... within h_acc (a 2-D normal error: 63-68 % when the claim is its DRMS)
    within_1sigma: float
    whole: float  # share of the sessions with every fix within 2·h_acc
    rms_err_m: float
    rms_acc_m: float
    mae_m: float
    median_acc_m: float

    @property
    def ratio(self) -> float:
        """RMS error / RMS h_acc: 1 when h_acc is the errors' DRMS, well below 1 when the claim is loose."""
        return self.rms_err_m / self.rms_acc_m


def pooled(per_seed: list) -> Pooled:
    err, acc, calibrated = (np.concatenate(column) for column in list(zip(*per_seed))[:3])
    return Pooled(
        len(err),
        len(per_seed),
        float(np.mean(err <= 2 * acc)),
        float(np.mean(calibrated)),
        float(np.mean(err <= acc)),
        float(np.mean([np.all(e <= 2 * a) for e, a, *_ in per_seed])),
        rms(err),
        rms(acc),
        float(np.mean(err)),
        float(np.median(acc)),
    )


def summary(c: Condition, per_seed: list) -> str:
    p = pooled(per_seed)
    line = (
        f"{c.name:<26} {p.fixes:5d} ({p.sessions:3d})  {p.within_2sigma:6.1%}  {p.calibrated:6.1%}"
        f"  {p.within_1sigma:6.1%}"
        f"  {p.whole:6.1%}  {p.rms_err_m:7.3f}  {p.rms_acc_m:7.3f}  {p.ratio:5.2f}  {p.mae_m:7.3f}"
        f"  {p.median_acc_m:7.3f}"
    )
    waves, wave_acc = (np.concatenate(column) for column in list(zip(*per_seed))[3:])
    if np.isfinite(waves).all() and len(waves):
        line += f"  {rms(waves):7.3f}  {rms(wave_acc):7.3f}  {np.mean(waves <= 2 * wave_acc):6.1%}"
    return line


HEADER = (
    f"{'condition':<26} {'fixes (sessions)':>17}  {'in 2σ':>6}  {'calib.':>6}  {'in 1σ':>6}  {'whole':>6}  {'RMS err':>7}"
    f"  {'RMS acc':>7}  {'ratio':>5}  {'MAE':>7}  {'med acc':>7}  {'waves':>7}  {'w. acc':>7}  {'w. 2σ':>6}"
)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=30)
    ap.add_argument("--duration", type=float, default=20.0, help="seconds per session")
    ap.add_argument("--fps", type=float, default=2.0)
    ap.add_argument("--work", type=Path, default=Path("/tmp/skyfix-claim"))
    ap.add_argument(
        "--out", type=Path, default=ROOT / "bench" / "results" / "claim_calibration.txt"
    )
    ap.add_argument(
        "--only", nargs="*", default=(), help="conditions whose name contains one of these words"
    )
    ap.add_argument(
        "--as-written",
        action="store_true",
        help="the sessions' own [uncertainty] (no platform sigmas)",
    )
    ap.add_argument(
        "--pixel-px",
        type=float,
        default=0.0,
        help="[uncertainty] pixel_px with the platform's sigmas (default 0: track.csv's pixel is exact)",
    )
    args = ap.parse_args()
    picked = [c for c in conditions() if not args.only or any(w in c.name for w in args.only)]
    claim = (
        "as written" if args.as_written else f"platform tilt/yaw sigmas, pixel_px {args.pixel_px:g}"
    )
    lines = [
        (
            f"claim calibration: {args.seeds} seeds x {args.duration:g} s at {args.fps:g} fps, true pixel, "
            f"[uncertainty]: {claim}; platform {PLATFORM}, {WANDER}"
        ),
        HEADER,
    ]
    print("\n".join(lines), flush=True)
    t0 = time.perf_counter()
    for c in picked:
        per_seed = fly(
            c,
            args.seeds,
            args.duration,
            args.fps,
            args.work,
            None if args.as_written else args.pixel_px,
        )
        lines.append(summary(c, per_seed))
        print(lines[-1], flush=True)
    lines.append(f"({time.perf_counter() - t0:.0f} s)")
    print(lines[-1])
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines) + "\n")
    print(f"-> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

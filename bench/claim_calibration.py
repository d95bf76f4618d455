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

Printed per condition: fixes (sessions), the pooled share within 2·h_acc (h_acc: half the radius of the claimed
covariance's 95 % circle, localizer/uncertainty.py), the share a calibrated claim gives ("calib.": a normal error of
each fix's own claimed covariance within 2·h_acc, 95 % of any shape: checks h_acc against its covariance), the share
within h_acc (53 % of a circular error to 67 % of one along one axis), the share of sessions that are entirely
within 2·h_acc, RMS error and RMS h_acc, the ratio of the RMS error to the RMS of the claimed covariance's DRMS
sqrt(σ_N² + σ_E²) (1: calibrated; well below 1: loose), MAE and median h_acc, the share of the errors' components
along the claimed covariance's axes within 2 sigma of theirs ("axes 2σ": 95.4 % for a calibrated claim of any
shape) and the share of fixes within twice the larger axis's sigma ("2σ maj": 86.5 % of a circular error, 95.4 % of
one along one axis); with waves the RMS of the waves' own error (truth_waves.csv), the RMS of the claim's wave term
alone as an h_acc (every other sigma 0) and the share of the waves' error within twice that.
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


#: ``--terms``: one error source at a time, by name: the ``[sensors]`` keys of the drone's draw that make it (every
#: other source off: :data:`SENSORS_OFF`) and the ``[uncertainty]`` sigmas of the claim's term for it (every other
#: sigma 0, :func:`only_sigmas`); "rest" is none of the drone's errors against the claim's remaining terms.
TERMS = {
    "gimbal_level": (("gimbal_level_deg",), ("tilt_deg",)),
    "ahrs_tilt": (("roll_bias_deg", "pitch_bias_deg"), ()),
    "compass": (("yaw_bias_deg",), ("yaw_deg",)),
    "wander": (("wander_deg", "wander_s"), ()),
    "gnss": (("gnss_mode",), ("uav_horizontal_m",)),
    "barometer": (("baro_wander_m", "baro_noise_m"), ("height_m", "baro_drift_10min_m")),
    "rest": ((), ("depth_m", "time_s", "pixel_px")),
}
SENSORS_OFF = {
    "roll_bias_deg": 0.0,
    "pitch_bias_deg": 0.0,
    "yaw_bias_deg": 0.0,
    "wander_deg": 0.0,
    "gimbal_level_deg": (0.0, 0.0),
    "gnss_mode": "exact",
    "baro_wander_m": 0.0,
    "baro_noise_m": 0.0,
}


def scenario(
    c: Condition, seed: int, seeds: int, duration_s: float, fps: float, term: str | None = None
) -> Scenario:
    """Condition ``c`` flown by drone ``seed`` of :func:`population` ``seeds``; ``term``: that one error source
    of the drone's (:data:`TERMS`), the rest off."""
    sc = load_scenario(SCENARIOS / f"{VIEWS[c.view].format(c.gnss)}.toml")
    sensors = {**draw_sensors(seed, seeds), "gnss_mode": c.gnss}
    if term is not None:
        sensors = {**SENSORS_OFF, **{k: v for k, v in sensors.items() if k in TERMS[term][0]}}
    tables = {
        "name": f"{c.name}_s{seed}",
        "seed": 1000 + seed,
        "duration_s": duration_s,
        "fps": fps,
        "uav": {"height_m": c.height_m},
        "sensors": sensors,
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


#: the [uncertainty] sigmas that make a fix's horizontal claim (wind_mps aside)
_CLAIM_SIGMAS = (
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


def only_sigmas(cal, keep=()):
    """The calibration with every sigma 0 but ``keep``'s and the wind's."""
    quiet = {f: 0.0 for f in _CLAIM_SIGMAS if f not in keep}
    return replace(cal, sigmas=replace(cal.sigmas, **quiet))


def waves_only(cal):
    """The calibration with every sigma 0 but the wind's: the claim's wave term alone."""
    return only_sigmas(cal)


#: directions (radians) over which :func:`calibrated_share` integrates
_ANGLES = np.linspace(0.0, np.pi, 720, endpoint=False)


def calibrated_share(fixes, ok) -> np.ndarray:
    """Per fix, the share within 2·h_acc of a normal error of the fix's own claimed covariance (sigma_n, sigma_e,
    cov_ne): what a calibrated claim of that shape holds (95 % of any shape when h_acc is its covariance's). Exact:
    with variances a, b along its axes, a standard normal (ρ cos θ, ρ sin θ) is within when
    ρ² (a cos² θ + b sin² θ) <= 4 h_acc², which for ρ² (exponential, mean 2) has probability
    1 − exp(−2 h_acc² / (a cos² θ + b sin² θ)), averaged over θ."""
    cov = np.zeros((int(ok.sum()), 2, 2))
    cov[:, 0, 0], cov[:, 1, 1] = fixes.sigma_n_m[ok] ** 2, fixes.sigma_e_m[ok] ** 2
    cov[:, 0, 1] = cov[:, 1, 0] = fixes.cov_ne_m2[ok]
    axes = np.clip(np.linalg.eigvalsh(cov), 0.0, None)  # (n, 2) the variances along its axes
    along = axes @ np.stack([np.cos(_ANGLES) ** 2, np.sin(_ANGLES) ** 2])  # (n, angles)
    with np.errstate(
        divide="ignore", invalid="ignore"
    ):  # a claim of 0 (--terms' unclaimed sources): NaN
        return np.mean(1.0 - np.exp(-2.0 * fixes.h_acc_m[ok, None] ** 2 / along), axis=1)


def along_axes(err_ne_m, fixes, ok) -> tuple[np.ndarray, np.ndarray]:
    """Per fix, the share of its error's two components along its claimed covariance's axes within 2 sigma of that
    axis (0, 0.5 or 1: 95.4 % on average for a calibrated claim of any shape), and its larger axis's sigma (m): what
    ArduPilot's EKF3 takes a GPS_INPUT's horiz_accuracy as (each axis's 1-sigma)."""
    cov = np.zeros((int(ok.sum()), 2, 2))
    cov[:, 0, 0], cov[:, 1, 1] = fixes.sigma_n_m[ok] ** 2, fixes.sigma_e_m[ok] ** 2
    cov[:, 0, 1] = cov[:, 1, 0] = fixes.cov_ne_m2[ok]
    var, vec = np.linalg.eigh(cov)
    along = np.einsum("ni,nij->nj", err_ne_m, vec)
    with np.errstate(divide="ignore", invalid="ignore"):
        within = np.abs(along) <= 2 * np.sqrt(np.clip(var, 0.0, None))
    return within.mean(axis=1), np.sqrt(np.clip(var[:, 1], 0.0, None))


def session_errors(
    path: Path, pixel_px: float | None, term: str | None = None
) -> tuple[np.ndarray, ...]:
    """(horizontal error, h_acc, the claimed covariance's DRMS, :func:`calibrated_share`, :func:`along_axes`' two,
    the waves' own error, the claim's wave term) per fixed frame (m) of the true pixel's refraction fixes; ``pixel_px`` None: the session's own ``[uncertainty]``, else the
    platform's (:func:`platform_claim`); ``term``: only that term's sigmas of it (:data:`TERMS`)."""
    s = load_session(path)
    if pixel_px is not None:
        s.calibration = platform_claim(s.calibration, pixel_px)
    if term is not None:
        s.calibration = only_sigmas(s.calibration, TERMS[term][1])
    fixes = process.process_session(s, use_track=True)
    ok = fixes.status == "ok"
    err_ne = error_ne_m(fixes.t_unix, fixes.lat, fixes.lon, ok, s.truth)[ok]
    err = np.hypot(*err_ne.T)
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
    axes, major = along_axes(err_ne, fixes, ok)
    drms = np.hypot(fixes.sigma_n_m[ok], fixes.sigma_e_m[ok])
    return err, fixes.h_acc_m[ok], drms, calibrated_share(fixes, ok), axes, major, waves, wave_acc


def fly(
    c: Condition,
    seeds: int,
    duration_s: float,
    fps: float,
    work: Path,
    pixel_px: float | None,
    term: str | None = None,
) -> list:
    """:func:`session_errors` of ``seeds`` drones of the platform in condition ``c`` (sessions under ``work``);
    ``term``: that error source alone against that term of the claim (:data:`TERMS`)."""
    per_seed = []
    for seed in range(seeds):
        out = work / (c.name if term is None else f"{c.name}_{term}") / f"s{seed}"
        generate(scenario(c, seed, seeds, duration_s, fps, term), out, video=False)
        per_seed.append(session_errors(out, pixel_px, term))
    return per_seed


def rms(x) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


@dataclass(frozen=True)
class Pooled:
    fixes: int
    sessions: int
    within_2sigma: float  # share of the fixes within 2·h_acc
    calibrated: float  # ... that a calibrated claim would hold (:func:`calibrated_share`)
    # ... within h_acc (a calibrated claim: 53 % of a circular error to 67 % of one along one axis)
    within_1sigma: float
    whole: float  # share of the sessions with every fix within 2·h_acc
    rms_err_m: float
    rms_acc_m: float
    rms_drms_m: float  # RMS of the claimed covariances' DRMS
    mae_m: float
    median_acc_m: float
    axes_2sigma: (
        float  # share of the errors' components along the claim's axes within 2 sigma of theirs
    )
    major_2sigma: (
        float  # share of the fixes within 2 x the claim's larger axis's sigma (EKF3's reading)
    )

    @property
    def ratio(self) -> float:
        """RMS error / RMS of the claimed covariances' DRMS: 1 when calibrated, well below 1 when loose."""
        return self.rms_err_m / self.rms_drms_m


def pooled(per_seed: list) -> Pooled:
    err, acc, drms, calibrated, axes, major = (
        np.concatenate(column) for column in list(zip(*per_seed))[:6]
    )
    return Pooled(
        len(err),
        len(per_seed),
        float(np.mean(err <= 2 * acc)),
        float(np.mean(calibrated)),
        float(np.mean(err <= acc)),
        float(np.mean([np.all(e <= 2 * a) for e, a, *_ in per_seed])),
        rms(err),
        rms(acc),
        rms(drms),
        float(np.mean(err)),
        float(np.median(acc)),
        float(np.mean(axes)),
        float(np.mean(err <= 2 * major)),
    )


def summary(c: Condition, per_seed: list) -> str:
    p = pooled(per_seed)
    line = (
        f"{c.name:<26} {p.fixes:5d} ({p.sessions:3d})  {p.within_2sigma:6.1%}  {p.calibrated:6.1%}"
        f"  {p.within_1sigma:6.1%}"
        f"  {p.whole:6.1%}  {p.rms_err_m:7.3f}  {p.rms_acc_m:7.3f}  {p.ratio:5.2f}  {p.mae_m:7.3f}"
        f"  {p.median_acc_m:7.3f}  {p.axes_2sigma:6.1%}  {p.major_2sigma:6.1%}"
    )
    waves, wave_acc = (np.concatenate(column) for column in list(zip(*per_seed))[6:])
    if np.isfinite(waves).all() and len(waves):
        line += f"  {rms(waves):7.3f}  {rms(wave_acc):7.3f}  {np.mean(waves <= 2 * wave_acc):6.1%}"
    return line


def term_summary(c: Condition, term: str, per_seed: list) -> str:
    """One line of ``--terms``: the error source's RMS error against its term's RMS claim."""
    p = pooled(per_seed)
    line = f"{c.name:<18} {term:<13} {p.fixes:5d}  {p.rms_err_m:7.4f}  {p.rms_acc_m:7.4f}"
    if p.rms_acc_m == 0:  # a source the claim has no term for
        return line + f"  {'-':>5}  {'-':>6}  {'-':>6}"
    return line + f"  {p.ratio:5.2f}  {p.within_2sigma:6.1%}  {p.calibrated:6.1%}"


TERM_HEADER = (
    f"{'condition':<18} {'term':<13} {'fixes':>5}  {'RMS err':>7}  {'RMS acc':>7}  {'ratio':>5}"
    f"  {'in 2σ':>6}  {'calib.':>6}"
)

HEADER = (
    f"{'condition':<26} {'fixes (sessions)':>17}  {'in 2σ':>6}  {'calib.':>6}  {'in 1σ':>6}  {'whole':>6}  {'RMS err':>7}"
    f"  {'RMS acc':>7}  {'ratio':>5}  {'MAE':>7}  {'med acc':>7}  {'axes 2σ':>6}  {'2σ maj':>6}  {'waves':>7}"
    f"  {'w. acc':>7}  {'w. 2σ':>6}"
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
    ap.add_argument(
        "--terms",
        action="store_true",
        help="one error source at a time against its term of the claim (conditions without wind)",
    )
    args = ap.parse_args()
    picked = [c for c in conditions() if not args.only or any(w in c.name for w in args.only)]
    if args.terms:
        picked = [c for c in picked if not c.wind_mps]
    claim = (
        "as written" if args.as_written else f"platform tilt/yaw sigmas, pixel_px {args.pixel_px:g}"
    )
    lines = [
        (
            f"claim calibration: {args.seeds} seeds x {args.duration:g} s at {args.fps:g} fps, true pixel, "
            f"[uncertainty]: {claim}; platform {PLATFORM}, {WANDER}"
        ),
        TERM_HEADER if args.terms else HEADER,
    ]
    print("\n".join(lines), flush=True)
    t0 = time.perf_counter()
    for c in picked if args.terms else ():
        for term in TERMS:
            per_seed = fly(c, args.seeds, args.duration, args.fps, args.work, args.pixel_px, term)
            lines.append(term_summary(c, term, per_seed))
            print(lines[-1], flush=True)
    for c in () if args.terms else picked:
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

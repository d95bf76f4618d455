"""``skyfix evaluate SESSION... [--out DIR]``: accuracy against ground truth, in the spirit of the paper's Table I.

Each session (it needs ``truth.csv``) is processed twice, with Snell refraction
and with the paper's straight ray, and each method's fixes are scored against
the truth interpolated at the fix times. Horizontal error is the distance in the
local tangent plane (:func:`localizer.geodesy.horizontal_error_m`). Per method:
MAE, RMSE, p95 and max of the horizontal error (metres) over frames with a fix;
the shape's MAE (``shape``: the MAE once the best constant offset is taken out, the
geometric median of the error vectors: what a track's form is worth when its place is
off by a bias); coverage = frames with a fix / frames; ``in 2σ`` = share of fixes whose
error is within twice their reported ``h_acc_m``; and the same (``smoothed_*``) for the
smoothed offline track (:mod:`groundstation.offline.smoothed`). Then ``visible_coverage``:
the share of the frames where the UUV can be seen (track.csv has its pixel) that have a fix;
and, for a generated session with wind waves (``truth_waves.csv``), ``wave_mae_m``: the
scene's waves' own error (the mean length of ``(wave_dn_m, wave_de_m)``: the true pixel's ray
through a flat surface against the truth, the telemetry exact), and what the session's
telemetry allows: ``allowed_mae_m``, ``allowed_shape_m``, the flat-surface solution of the
true pixel (track.csv) with the telemetry as the session reports it (what ``--use-track``
scores), and this row's MAE and shape over them (``mae_ratio``, ``shape_ratio``: 1 with
``--use-track``; the tracker's pixels against the true ones otherwise). Writes, per session,
``DIR/<session>/<method>/positions.csv`` and ``positions_smoothed.csv``, the plots of :mod:`groundstation.offline.plots`
(``top_view.png``, ``timeline.png``, ``status.png``: both methods against the truth),
and ``DIR/evaluation.csv``. A session of several UUVs is scored once per UUV against that UUV's own truth
(``uuvs/<id>/truth.csv``), in ``DIR/<session>/<id>/``.
"""

from __future__ import annotations

import csv
import sys
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path

import numpy as np

from groundstation.offline.plots import write_plots
from groundstation.offline.process import (
    add_motion_offset_flag,
    add_size_argument,
    add_uuv_argument,
    add_uuv_bounds,
    frame_pixels,
    locate_frames,
    located,
    print_warnings,
    size_of,
)
from groundstation.offline.smoothed import NAME as SMOOTHED_NAME
from groundstation.offline.smoothed import offline_track, traced_back, write_smoothed_csv
from groundstation.outputs import output_dir
from groundstation.session.positions import write_positions_csv
from groundstation.session.read import (
    PRIMARY_UUV,
    SessionError,
    load_session,
    read_table,
    uuv_files,
    uuv_ids,
)
from localizer.calibration import ConfigError
from localizer.fix import Fixes
from localizer.fix_gate import MAX_ACCEL_MPS2, MAX_SPEED_MPS
from localizer.geodesy import geodetic_to_ned
from localizer.tracking import TRACKERS

METHODS = (("refraction", True), ("straight", False))


@dataclass(frozen=True)
class Scores:
    """One method on one session. Errors in metres; NaN when there is no fix at all (or, ``smoothed_*``, when the
    smoothed track was not scored)."""

    frames: int
    fixes: int
    coverage: float
    mae_m: float
    rmse_m: float
    p95_m: float
    max_m: float
    within_2sigma: float
    shape_m: float = float("nan")
    smoothed_fixes: int = 0
    smoothed_coverage: float = float("nan")
    smoothed_mae_m: float = float("nan")
    smoothed_shape_m: float = float("nan")
    smoothed_within_2sigma: float = float("nan")
    visible_coverage: float = float("nan")
    wave_mae_m: float = float("nan")
    allowed_mae_m: float = float("nan")
    allowed_shape_m: float = float("nan")
    mae_ratio: float = float("nan")
    shape_ratio: float = float("nan")

    def with_smoothed(self, sm: Scores) -> Scores:
        """These scores with ``sm``'s (the smoothed track's) as ``smoothed_*``."""
        return replace(
            self,
            smoothed_fixes=sm.fixes,
            smoothed_coverage=sm.coverage,
            smoothed_mae_m=sm.mae_m,
            smoothed_shape_m=sm.shape_m,
            smoothed_within_2sigma=sm.within_2sigma,
        )

    def with_allowed(self, allowed: Scores) -> Scores:
        """These scores with what the telemetry allows (``allowed``: the true pixel's scores) and the ratios."""
        return replace(
            self,
            allowed_mae_m=allowed.mae_m,
            allowed_shape_m=allowed.shape_m,
            mae_ratio=self.mae_m / allowed.mae_m,
            shape_ratio=self.shape_m / allowed.shape_m,
        )


def truth_at(truth: dict, t_unix) -> tuple[np.ndarray, np.ndarray]:
    """Truth latitude and longitude (degrees) linearly interpolated at ``t_unix``; NaN outside its span."""
    t = np.asarray(t_unix, dtype=float)
    inside = (t >= truth["t"][0]) & (t <= truth["t"][-1])
    lat = np.where(inside, np.interp(t, truth["t"], truth["lat"]), np.nan)
    lon = np.where(inside, np.interp(t, truth["t"], truth["lon"]), np.nan)
    return lat, lon


def errors_m(fixes: Fixes, truth: dict) -> np.ndarray:
    """Horizontal error (m) of each fix against the truth; NaN where there is no fix or no truth."""
    return np.hypot(*error_ne_m(fixes.t_unix, fixes.lat, fixes.lon, fixes.status == "ok", truth).T)


def error_ne_m(t_unix, lat, lon, ok, truth: dict) -> np.ndarray:
    """N×2 north and east error (m) of positions against the truth (the local tangent plane at the truth); NaN
    rows where not ``ok`` or no truth."""
    lat_t, lon_t = truth_at(truth, t_unix)
    ok = np.asarray(ok, bool) & np.isfinite(lat_t)
    err = np.full((len(ok), 2), np.nan)
    n, e, _ = geodetic_to_ned(lat[ok], lon[ok], 0.0, lat_t[ok], lon_t[ok], 0.0)
    err[ok, 0], err[ok, 1] = n, e
    return err


def shape_m(err_ne_m: np.ndarray) -> float:
    """MAE (m) of N×2 error vectors (NaN rows left out) once the constant offset that minimises it is taken out:
    their geometric median (Weiszfeld's iteration from the mean). NaN without any."""
    e = err_ne_m[np.all(np.isfinite(err_ne_m), axis=1)]
    if not len(e):
        return float("nan")
    c = e.mean(axis=0)
    for _ in range(200):
        w = 1.0 / np.maximum(np.hypot(*(e - c).T), 1e-12)
        c, before = (e * w[:, None]).sum(axis=0) / w.sum(), c
        if np.hypot(*(c - before)) < 1e-9:
            break
    return float(np.mean(np.hypot(*(e - c).T)))


def score(
    err_m: np.ndarray, h_acc_m: np.ndarray, frames: int, err_ne_m: np.ndarray | None = None
) -> Scores:
    """Table numbers from per-fix errors (NaN = no fix) and the fixes' reported 1-sigma accuracy; the shape's MAE
    from the error vectors ``err_ne_m`` (N×2), when given."""
    ok = np.isfinite(err_m)
    e = err_m[ok]
    if len(e) == 0:
        nan = float("nan")
        return Scores(frames, 0, 0.0, nan, nan, nan, nan, nan)
    return Scores(
        frames=frames,
        fixes=len(e),
        coverage=len(e) / frames,
        mae_m=float(np.mean(e)),
        rmse_m=float(np.sqrt(np.mean(e * e))),
        p95_m=float(np.percentile(e, 95)),
        max_m=float(np.max(e)),
        within_2sigma=float(np.mean(e <= 2.0 * h_acc_m[ok])),
        shape_m=shape_m(err_ne_m) if err_ne_m is not None else float("nan"),
    )


HEADER = (
    "session",
    "method",
    "fixes",
    "coverage",
    "MAE m",
    "shape m",
    "RMSE m",
    "p95 m",
    "max m",
    "in 2σ",
    "smoothed",
    "MAE m",
    "shape m",
    "in 2σ",
    "visible",
    "waves m",
    "allowed",
    "shape m",
    "×MAE",
    "×shape",
)


def table_rows(results: list[tuple[str, str, Scores]]) -> list[tuple[str, ...]]:
    """Formatted cells of the table, one row per (session, method); the smoothed track's last."""
    return [
        (
            name,
            method,
            f"{s.fixes}/{s.frames}",
            f"{s.coverage:.1%}",
            f"{s.mae_m:.4f}",
            f"{s.shape_m:.4f}",
            f"{s.rmse_m:.4f}",
            f"{s.p95_m:.4f}",
            f"{s.max_m:.4f}",
            f"{s.within_2sigma:.1%}",
            f"{s.smoothed_fixes}/{s.frames}",
            f"{s.smoothed_mae_m:.4f}",
            f"{s.smoothed_shape_m:.4f}",
            f"{s.smoothed_within_2sigma:.1%}",
            _cell(s.visible_coverage, "{:.1%}"),
            _cell(s.wave_mae_m, "{:.4f}"),
            _cell(s.allowed_mae_m, "{:.4f}"),
            _cell(s.allowed_shape_m, "{:.4f}"),
            _cell(s.mae_ratio, "{:.2f}"),
            _cell(s.shape_ratio, "{:.2f}"),
        )
        for name, method, s in results
    ]


def _cell(value: float, form: str) -> str:
    return form.format(value) if np.isfinite(value) else "-"


def format_table(results: list[tuple[str, str, Scores]]) -> str:
    """The table as aligned text."""
    rows = [HEADER, *table_rows(results)]
    widths = [max(len(r[i]) for r in rows) for i in range(len(HEADER))]
    lines = [
        "  ".join(c.ljust(w) if i < 2 else c.rjust(w) for i, (c, w) in enumerate(zip(r, widths)))
        for r in rows
    ]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def evaluate_session(
    path,
    out_dir: Path,
    use_track: bool = False,
    tracker: str = "default",
    progress: bool = False,
    motion: bool = True,
    height_from_size: str = "check",
    uuv: str | None = None,
    bounds: tuple[float, float] = (MAX_SPEED_MPS["bluerov2"], MAX_ACCEL_MPS2["bluerov2"]),
):
    """Score both methods on one session, on each of its UUVs (or on ``uuv`` alone); returns
    ``[(name, method, Scores), ...]`` and writes outputs (the height from the UUV's size: its summary line on
    stderr). A session of one UUV is named by its folder, each UUV of a session of several ``<folder>/<id>``.
    ``bounds``: the UUV's top speed (m/s) and acceleration (m/s²), for the smoothed track."""
    ids = uuv_ids(path) if uuv is None else (uuv,)
    folder = Path(path).resolve().name
    results = []
    for uuv_id in ids:
        name = folder if len(ids) == 1 and uuv_id == PRIMARY_UUV else f"{folder}/{uuv_id}"
        results.extend(
            _evaluate_uuv(
                load_session(path, uuv_id),
                name,
                out_dir,
                use_track,
                tracker,
                progress,
                motion,
                height_from_size,
                bounds,
            )
        )
    return results


def _evaluate_uuv(
    session,
    name: str,
    out_dir: Path,
    use_track: bool,
    tracker: str,
    progress: bool,
    motion: bool,
    height_from_size: str,
    bounds: tuple[float, float],
):
    if session.truth is None or len(session.truth["t"]) == 0:
        raise SessionError(
            f"{uuv_files(session.path, session.uuv_id).truth}: missing (evaluate needs ground truth)"
        )
    from_track = use_track or session.video_path is None
    if not use_track and from_track:
        print(f"{name}: no video: pixels from track.csv", file=sys.stderr)
    size = size_of(session, height_from_size, from_track)
    try:
        pixels = frame_pixels(session, from_track, tracker, progress, motion, size, both_ways=True)
    finally:
        print_warnings(session)
    if size is not None:
        print(f"{name}: {size.summary()}", file=sys.stderr)
    frames = len(session.frames["t"]) if session.frames is not None else None
    sess_dir = out_dir / name
    waves_path = uuv_files(session.path, session.uuv_id).truth_waves
    waves = wave_mae_m(waves_path)
    allowed = (
        None
        if use_track or not waves_path.is_file()
        else load_session(session.path, session.uuv_id)
    )
    runs, results = {}, []
    for method, refraction in METHODS:
        # a surveyed marker's offset (reference.toml), found through refraction
        fixes, offline, _ = located(
            session, pixels, refraction, None, "auto" if refraction else "off"
        )
        print_warnings(session)
        (sess_dir / method).mkdir(parents=True, exist_ok=True)
        write_positions_csv(sess_dir / method / "positions.csv", fixes)
        err_ne = error_ne_m(fixes.t_unix, fixes.lat, fixes.lon, fixes.status == "ok", session.truth)
        err = np.hypot(*err_ne.T)
        runs[method] = (fixes, err)
        smoothed, status = offline_track(offline, *bounds)
        write_smoothed_csv(
            sess_dir / method / SMOOTHED_NAME,
            offline,
            smoothed,
            status,
            traced_back(fixes, offline),
        )
        sm_ne = error_ne_m(fixes.t_unix, smoothed.lat, smoothed.lon, smoothed.ok, session.truth)
        n = frames or len(fixes)
        s = replace(
            score(err, fixes.h_acc_m, n, err_ne).with_smoothed(
                score(np.hypot(*sm_ne.T), smoothed.h_acc_m, n, sm_ne)
            ),
            visible_coverage=visible_coverage(fixes, session.track),
            wave_mae_m=waves,
        )
        if np.isfinite(waves):
            s = s.with_allowed(s if allowed is None else true_pixel_scores(allowed, refraction, n))
        results.append((name, method, s))
    write_plots(
        sess_dir,
        name,
        {m: f for m, (f, _) in runs.items()},
        session.truth,
        {m: e for m, (_, e) in runs.items()},
    )
    return results


def visible_coverage(fixes: Fixes, track: dict | None) -> float:
    """The share of the frames where the UUV can be seen (track.csv has its pixel) that have an ok fix (the fix
    nearest each such frame's time, within half a frame); NaN without track.csv or a frame it is seen in."""
    if track is None or len(fixes) < 2:
        return float("nan")
    seen_t = track["t"][np.isfinite(track["u"])]
    if not len(seen_t):
        return float("nan")
    t = fixes.t_unix
    j = np.clip(np.searchsorted(t, seen_t), 1, len(t) - 1)
    j = np.where(np.abs(t[j - 1] - seen_t) <= np.abs(t[j] - seen_t), j - 1, j)
    near = np.abs(t[j] - seen_t) <= 0.5 * float(np.median(np.diff(t)))
    return float(np.mean(near & (fixes.status[j] == "ok")))


def wave_mae_m(path: Path) -> float:
    """The scene's waves' own error (m): the mean length of ``truth_waves.csv``'s ``(wave_dn_m, wave_de_m)`` over
    the frames that have one; NaN without the file (no waves)."""
    if not path.is_file():
        return float("nan")
    w = read_table(path, ("t", "wave_dn_m", "wave_de_m"), allow_empty=("wave_dn_m", "wave_de_m"))
    d = np.hypot(w["wave_dn_m"], w["wave_de_m"])
    d = d[np.isfinite(d)]
    return float(np.mean(d)) if len(d) else float("nan")


def true_pixel_scores(session, refraction: bool, frames: int) -> Scores:
    """What the session's telemetry allows: the scores of the true pixel (track.csv) located with the telemetry as
    the session reports it, as ``--use-track`` locates it (``session``: loaded afresh, none of a tracked run's
    alignment; its warnings are the tracked run's and are not printed again)."""
    fixes = locate_frames(session, frame_pixels(session, True), refraction)
    err_ne = error_ne_m(fixes.t_unix, fixes.lat, fixes.lon, fixes.status == "ok", session.truth)
    return score(np.hypot(*err_ne.T), fixes.h_acc_m, frames, err_ne)


def write_table_csv(path: Path, results: list[tuple[str, str, Scores]]) -> None:
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(("session", "method", *(fl.name for fl in fields(Scores))))
        for name, method, s in results:
            w.writerow((name, method, *asdict(s).values()))


def run(args) -> int:
    """Evaluate every session it can; a session that fails is reported and skipped (exit code 2)."""
    out = output_dir(args.out)
    results, failed = [], 0
    for path in args.sessions:
        try:
            results.extend(
                evaluate_session(
                    path,
                    out,
                    use_track=args.use_track,
                    tracker=args.tracker,
                    progress=not args.quiet,
                    motion=not args.no_motion_offset,
                    height_from_size=args.height_from_size,
                    uuv=args.uuv,
                    bounds=(args.uuv_max_speed_mps, args.uuv_max_accel_mps2),
                )
            )
        except (SessionError, ConfigError) as e:
            print(f"skyfix evaluate: error: {e}", file=sys.stderr)
            failed += 1
    if results:
        print(format_table(results))
        write_table_csv(out / "evaluation.csv", results)
        print(f"positions, plots and evaluation.csv -> {out}")
    return 2 if failed else 0


def register(subparsers, name: str, help: str | None = None) -> None:
    """Adds the subcommand ``name`` with its one-line ``help`` (both from :data:`groundstation.cli.COMMANDS`)."""
    p = subparsers.add_parser(name, help=help)
    p.add_argument(
        "sessions", nargs="+", metavar="SESSION", help="session directories with truth.csv"
    )
    p.add_argument("--out", default="out/evaluate", help="output directory (default: out/evaluate)")
    p.add_argument(
        "--use-track",
        action="store_true",
        help="take pixels from track.csv (geometry only) instead of tracking the video",
    )
    p.add_argument(
        "--tracker", default="default", choices=TRACKERS, help="tracker backend for video tracking"
    )
    add_size_argument(p)
    add_uuv_argument(
        p,
        "evaluate this UUV of each session only (default: every UUV, each against its own truth)",
        default=None,
    )
    add_uuv_bounds(p)
    p.add_argument("--quiet", action="store_true", help="no progress output")
    add_motion_offset_flag(p)
    p.set_defaults(func=run)

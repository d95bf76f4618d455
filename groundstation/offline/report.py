"""``skyfix report SESSION|positions.csv [--truth truth.csv] [--mosaic PATH] [--out DIR]``: PNG plots of a run's fixes.

Reads ``positions.csv`` (a recorded session's, or ``skyfix process``'s output) and, when
there is one (``--truth``, or ``truth.csv`` beside positions.csv), the truth; writes
``top_view.png``, ``timeline.png`` and ``status.png`` (see :mod:`groundstation.offline.plots`)
into ``--out`` (default: ``report/`` beside positions.csv) and prints a summary. The top view is
drawn over the bottom's mosaic: ``--mosaic``, or ``mosaic.tif`` beside positions.csv (``skyfix mosaic``'s,
or the one ``skyfix export --qgis`` made).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from groundstation.offline.evaluate import errors_m
from groundstation.offline.export import positions_path
from groundstation.offline.mosaic import NAME as MOSAIC_NAME
from groundstation.offline.plots import frame_gaps, write_plots
from groundstation.session.positions import read_positions_csv
from groundstation.session.read import SessionError, read_table
from localizer.status import runs


def summary(fixes, err: np.ndarray | None) -> str:
    """One paragraph: coverage, accuracy claimed (and achieved), the longest gap."""
    ok = fixes.status == "ok"
    lines = [
        f"{len(fixes)} frames, {ok.sum()} with a fix ({ok.mean():.1%})"
        if len(fixes)
        else "no frames"
    ]
    if ok.any():
        lines.append(
            f"h_acc (2·h_acc holds 95 %) median {np.median(fixes.h_acc_m[ok]):.3f} m, "
            f"max {np.nanmax(fixes.h_acc_m[ok]):.3f} m"
        )
    if err is not None and np.isfinite(err).any():
        e = err[np.isfinite(err)]
        lines.append(
            f"error against truth: mean {e.mean():.3f} m, p95 {np.percentile(e, 95):.3f} m, "
            f"max {e.max():.3f} m"
        )
    gaps = [
        (fixes.t_unix[b - 1] - fixes.t_unix[a], w) for a, b, w in runs(fixes.status) if w != "ok"
    ]
    if gaps:
        longest, word = max(gaps)
        lines.append(f"{len(gaps)} stretches without a fix, longest {longest:.1f} s ({word})")
    stops = frame_gaps(fixes.t_unix)
    if stops:
        lines.append(
            f"{len(stops)} pauses in the frames (video stopped), longest {max(b - a for a, b in stops):.1f} s"
        )
    return "; ".join(lines)


def report(path, truth_path=None, out=None, mosaic=None) -> tuple[list[Path], str]:
    src = positions_path(Path(path))
    if mosaic is not None and not Path(mosaic).is_file():
        raise SessionError(f"--mosaic {mosaic}: no such file")
    beside = src.with_name(MOSAIC_NAME)
    mosaic = Path(mosaic) if mosaic is not None else beside if beside.is_file() else None
    fixes = read_positions_csv(src)
    if len(fixes) == 0:
        raise SessionError(f"{src}: no rows")
    truth_file = Path(truth_path) if truth_path else src.with_name("truth.csv")
    truth = None
    if truth_path or truth_file.is_file():
        truth = read_table(truth_file, ("t", "lat", "lon", "depth_m"))
        if len(truth["t"]) == 0:
            raise SessionError(f"{truth_file}: no rows")
    err = errors_m(fixes, truth) if truth is not None else None
    name = src.parent.resolve().name
    out_dir = Path(out) if out else src.with_name("report")
    paths = write_plots(
        out_dir, name, {"fixes": fixes}, truth, None if err is None else {"fixes": err}, mosaic
    )
    return paths, summary(fixes, err)


def run(args) -> int:
    paths, text = report(args.session, args.truth, args.out, args.mosaic)
    print(text)
    print(f"plots -> {', '.join(str(p) for p in paths)}")
    return 0


def register(subparsers, name: str, help: str | None = None) -> None:
    """Adds the subcommand ``name`` with its one-line ``help`` (both from :data:`groundstation.cli.COMMANDS`)."""
    p = subparsers.add_parser(
        name,
        help=help,
        description="Writes top_view.png (the fixes from above, origin and north stated, over the "
        "bottom's mosaic when there is one), timeline.png "
        "(error against truth, when there is one, and the claimed accuracy over time, gaps "
        "shaded by cause) and status.png (frames per status) and prints a summary.",
    )
    p.add_argument(
        "session",
        metavar="SESSION|positions.csv",
        help="a folder with positions.csv (a recorded session, skyfix process's output) or the file",
    )
    p.add_argument(
        "--truth",
        metavar="FILE",
        help="truth.csv (t,lat,lon,depth_m); default: beside positions.csv",
    )
    p.add_argument(
        "--mosaic",
        metavar="PATH",
        help="the bottom's mosaic (GeoTIFF) to draw the top view over (default: mosaic.tif beside "
        "positions.csv, if there is one)",
    )
    p.add_argument(
        "--out", metavar="DIR", help="output folder (default: report/ beside positions.csv)"
    )
    p.set_defaults(func=run)

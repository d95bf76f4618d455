"""``positions.csv``: one row per processed frame (session format v1 output).

Columns: the spec's ``t,lat,lon,depth_m,h_acc_m,status`` first, then skyfix's
``alt_amsl_m,v_acc_m,u,v,north_m,east_m,t_gnss,alt_ellipsoid_m,sigma_n_m,sigma_e_m,cov_ne_m2``
and each input's provenance ``height_m,sigma_height_m,sigma_depth_m,sigma_time_s,height_source,depth_source,time_source``,
then the tracker's pixel 1-sigma ``sigma_pixel_px`` (the fix message's names; ``t`` is the frame's exposure on the station clock). Empty
cells where there is no value (lat/lon are empty whenever status is not ``ok``;
``alt_ellipsoid_m`` without GPS_RAW_INT ``alt_ellipsoid``; ``t_gnss`` before the
station clock's offset from GNSS time is known). Written to a temporary file and
renamed, so a reader never sees a half-written table passed off as complete. Read
back as :class:`~localizer.fix.Fixes`; a file from another tool needs only the spec's
six columns.
"""

from __future__ import annotations

import csv
import math
import os
from pathlib import Path

from groundstation.session.read import read_table
from localizer.fix import WORDS, Fixes

SPEC_COLUMNS = ("t", "lat", "lon", "depth_m", "h_acc_m", "status")
COLUMNS = (
    *SPEC_COLUMNS,
    "alt_amsl_m",
    "v_acc_m",
    "u",
    "v",
    "north_m",
    "east_m",
    "t_gnss",
    "alt_ellipsoid_m",
    "sigma_n_m",
    "sigma_e_m",
    "cov_ne_m2",
    "height_m",
    "sigma_height_m",
    "sigma_depth_m",
    "sigma_time_s",
    *WORDS,
    "sigma_pixel_px",
)
#: column → (Fix attribute, decimals)
_FIELDS = {
    "t": ("t_unix", 6),
    "lat": ("lat", 9),
    "lon": ("lon", 9),
    "depth_m": ("depth_m", 4),
    "h_acc_m": ("h_acc_m", 4),
    "alt_amsl_m": ("alt_amsl_m", 4),
    "v_acc_m": ("v_acc_m", 4),
    "u": ("u", 3),
    "v": ("v", 3),
    "north_m": ("north_m", 4),
    "east_m": ("east_m", 4),
    "t_gnss": ("t_gnss", 6),
    "alt_ellipsoid_m": ("alt_ellipsoid_m", 4),
    "sigma_n_m": ("sigma_n_m", 4),
    "sigma_e_m": ("sigma_e_m", 4),
    "cov_ne_m2": ("cov_ne_m2", 6),
    "height_m": ("height_m", 4),
    "sigma_height_m": ("sigma_height_m", 4),
    "sigma_depth_m": ("sigma_depth_m", 4),
    "sigma_time_s": ("sigma_time_s", 4),
    "sigma_pixel_px": ("sigma_pixel_px", 3),
}


def _cell(value: float, digits: int) -> str:
    return "" if not math.isfinite(value) else f"{value:.{digits}f}"


def format_row(fix) -> list[str]:
    """The CSV cells of one :class:`~localizer.fix.Fix`."""
    row = []
    for col in COLUMNS:
        if col == "status" or col in WORDS:
            row.append(getattr(fix, col))
        else:
            attr, digits = _FIELDS[col]
            if col in ("lat", "lon") and fix.status != "ok":
                row.append("")
            else:
                row.append(_cell(float(getattr(fix, attr)), digits))
    return row


def write_positions_csv(path: Path, fixes: Fixes) -> None:
    """Write all fixes atomically (temporary file, then rename)."""
    write_table(path, COLUMNS, (format_row(f) for f in fixes.each(range(len(fixes)))))


def write_table(path: Path, header, rows) -> None:
    """A CSV of ``header`` and ``rows`` written atomically (a temporary file, then renamed)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".partial")
    with open(tmp, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        w.writerows(rows)
    os.replace(tmp, path)


def read_positions_csv(path: Path) -> Fixes:
    """A positions.csv as :class:`~localizer.fix.Fixes` (columns it lacks are NaN); bad cells are SessionError."""
    numbers = [c for c in COLUMNS if c not in ("t", "status", *WORDS)]
    table = read_table(
        Path(path),
        SPEC_COLUMNS,
        allow_empty=(*numbers, *WORDS),
        optional=COLUMNS[6:],
        text=("status", *WORDS),
    )
    return Fixes.of(
        table["t"],
        table["status"],
        **{
            _FIELDS[c][0] if c in numbers else c: v
            for c, v in table.items()
            if c in (*numbers, *WORDS)
        },
    )

"""``positions.csv``: one row per processed frame (session format v1 output).

Columns: the spec's ``t,lat,lon,depth_m,h_acc_m,status`` first, then skyfix's
``alt_amsl_m,v_acc_m,u,v,north_m,east_m``. Empty cells where there is no value
(lat/lon are empty whenever status is not ``ok``). Written to a temporary file
and renamed, so a reader never sees a half-written table passed off as complete.
"""

from __future__ import annotations

import csv
import math
import os
from pathlib import Path

import numpy as np

from localizer.fix import Fixes

COLUMNS = ("t", "lat", "lon", "depth_m", "h_acc_m", "status", "alt_amsl_m", "v_acc_m", "u", "v", "north_m", "east_m")
_FIELDS = {"t": ("t_unix", 6), "lat": ("lat", 9), "lon": ("lon", 9), "depth_m": ("depth_m", 4),
           "h_acc_m": ("h_acc_m", 4), "alt_amsl_m": ("alt_amsl_m", 4), "v_acc_m": ("v_acc_m", 4),
           "u": ("u", 3), "v": ("v", 3), "north_m": ("north_m", 4), "east_m": ("east_m", 4)}


def _cell(value: float, digits: int) -> str:
    return "" if not math.isfinite(value) else f"{value:.{digits}f}"


def format_row(fix) -> list[str]:
    """The CSV cells of one :class:`~localizer.fix.Fix`."""
    row = []
    for col in COLUMNS:
        if col == "status":
            row.append(fix.status)
        else:
            attr, digits = _FIELDS[col]
            if col in ("lat", "lon") and fix.status != "ok":
                row.append("")
            else:
                row.append(_cell(float(getattr(fix, attr)), digits))
    return row


def write_positions_csv(path: Path, fixes: Fixes) -> None:
    """Write all fixes atomically (temporary file, then rename)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".partial")
    with open(tmp, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(COLUMNS)
        for i in range(len(fixes)):
            w.writerow(format_row(fixes[i]))
    os.replace(tmp, path)


def read_positions_csv(path: Path) -> dict[str, np.ndarray]:
    """Columns of a positions.csv as arrays (numbers as float with NaN for empty; status as str)."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    out = {}
    for col in rows[0].keys() if rows else COLUMNS:
        if col == "status":
            out[col] = np.array([r[col] for r in rows], dtype=object)
        else:
            out[col] = np.array([float(r[col]) if r[col] != "" else np.nan for r in rows])
    return out

"""``depth.jsonl``: the UUV's depth as recorded, one JSON object a line, read once here.

Each line holds ``t`` (the UUV's stamp, UNIX s) and ``depth_m``, and may hold ``t_recv`` (its arrival at the
station), ``source``, ``sigma_m`` and ``vspeed_mps`` (what a live recording knew). A truncated last line (a log
being written when power went) is skipped with a warning. Strict (``skyfix process``): any other malformed
line, a non-finite or out-of-range value, or a ``t`` that does not increase is a one-line
:class:`SessionError`. Lenient (``skyfix replay``): such lines are skipped, each with a warning.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

from groundstation.session import SessionError
from localizer.depth import DEPTH_RANGE_M


@dataclass(frozen=True)
class DepthRecord:
    t: float
    depth_m: float
    t_recv: float | None
    source: str | None
    sigma_m: float  # NaN: not recorded
    vspeed_mps: float  # NaN: not recorded


def _number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _optional(value) -> float:
    """An extra key's number, NaN where it is absent or not a finite number (extra keys are not checked)."""
    return float(value) if _number(value) and math.isfinite(value) else math.nan


def _record(line: str) -> DepthRecord | str:
    """The line's record, or what is wrong with it."""
    try:
        rec = json.loads(line)
        t, depth, t_recv = rec["t"], rec["depth_m"], rec.get("t_recv")
        shaped = all(_number(x) for x in (t, depth, t_recv or 0.0))
    except (ValueError, KeyError, TypeError, AttributeError):
        shaped = False
    if not shaped:
        return f'expected {{"t": number, "depth_m": number}}, got {line[:80]!r}'
    if not (math.isfinite(t) and math.isfinite(depth) and math.isfinite(t_recv or 0.0)):
        return f"non-finite value in {line[:80]!r}"
    if not DEPTH_RANGE_M[0] <= depth <= DEPTH_RANGE_M[1]:
        return f"depth_m = {depth!r} out of range [{DEPTH_RANGE_M[0]:g}, {DEPTH_RANGE_M[1]:g}]"
    source = rec.get("source")
    return DepthRecord(
        float(t),
        float(depth),
        None if t_recv is None else float(t_recv),
        source if isinstance(source, str) else None,
        _optional(rec.get("sigma_m")),
        _optional(rec.get("vspeed_mps")),
    )


def read_depth(path: Path, warnings: list[str], strict: bool = True) -> list[DepthRecord]:
    """Every record of ``path`` in file order (see the module doc for strict and lenient)."""
    try:
        text = path.read_text()
    except OSError as e:
        raise SessionError(f"{path}: cannot read: {e.strerror}") from None
    lines = text.split("\n")
    out: list[DepthRecord] = []
    last_t = -math.inf
    for i, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        rec = _record(line)
        if isinstance(rec, DepthRecord) and strict and rec.t <= last_t:
            rec = f"t = {rec.t!r} does not increase"
        if isinstance(rec, str):
            if i == len(lines) and not text.endswith("\n"):
                warnings.append(f"{path}:{i}: truncated last line ignored: {line[:60]!r}")
                continue
            if strict:
                raise SessionError(f"{path}:{i}: {rec}")
            warnings.append(f"{path}:{i}: skipped: {rec}")
            continue
        last_t = rec.t
        out.append(rec)
    return out

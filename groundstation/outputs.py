"""Where a command's outputs go, checked before any work: a bad ``--out`` is one line, not a traceback."""

from __future__ import annotations

import os
from pathlib import Path

from localizer.calibration import ConfigError


def output_dir(path, option: str = "--out") -> Path:
    """``path`` as a directory that exists and is writable (created if missing); ConfigError otherwise."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise ConfigError("options", option, str(p), "exists and is not a directory")
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise ConfigError("options", option, str(p), f"cannot create it: {e.strerror}") from None
    if not os.access(p, os.W_OK | os.X_OK):
        raise ConfigError("options", option, str(p), "not writable")
    return p

"""Where a command's outputs go, checked before any work: a bad ``--out`` is one line, not a traceback; and a
command that wrote nothing there leaves no empty folder behind (:func:`tidied`)."""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from localizer.calibration import ConfigError

#: Folders :func:`output_dir` made: (the output folder, the first of its ancestors that was missing, or itself)
_made: list[tuple[Path, Path]] = []


def output_dir(path, option: str = "--out") -> Path:
    """``path`` as a directory that exists and is writable (created if missing); ConfigError otherwise."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise ConfigError("options", option, str(p), "exists and is not a directory")
    missing = [q for q in (p, *p.parents) if not q.exists()]
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise ConfigError("options", option, str(p), f"cannot create it: {e.strerror}") from None
    if missing:
        _made.append((p, missing[-1]))
    if not os.access(p, os.W_OK | os.X_OK):
        raise ConfigError("options", option, str(p), "not writable")
    return p


@contextmanager
def tidied() -> Iterator[None]:
    """Around a command: each folder :func:`output_dir` made within, and its ancestors it made, removed at the end
    when still empty (a command that failed before writing leaves nothing behind)."""
    start = len(_made)
    try:
        yield
    finally:
        for leaf, top in reversed(_made[start:]):
            for folder in (leaf, *leaf.parents):
                try:
                    folder.rmdir()  # only an empty one
                except OSError:
                    break
                if folder == top:
                    break
        del _made[start:]

"""A bench's printed result, also written to ``--out`` when given."""

from __future__ import annotations

import json
from pathlib import Path


def emit(lines: list[str], out: Path | None, data=None) -> None:
    """Print ``lines``; with ``out``, write them there, and ``data`` (JSON-ready) beside it as ``.json``."""
    text = "\n".join(lines).rstrip("\n")
    print(text)
    if out:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(text + "\n")
        if data is not None:
            out.with_suffix(".json").write_text(json.dumps(data, indent=1))

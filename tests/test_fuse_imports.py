"""The fuser imports no module of the live service: what both run on is in ``groundstation.runtime``."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_no_fuse_module_names_the_live_service():
    found = []
    for path in sorted((ROOT / "groundstation" / "fuse").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            names = (
                [a.name for a in node.names]
                if isinstance(node, ast.Import)
                else [node.module or ""]
                if isinstance(node, ast.ImportFrom)
                else []
            )
            found += [
                f"{path.name}:{node.lineno} {n}"
                for n in names
                if n.startswith("groundstation.live")
            ]
    assert found == []


def test_importing_the_fuser_loads_no_module_of_the_live_service():
    code = (
        "import sys, groundstation.fuse.service, groundstation.fuse.fuser\n"
        "print(sorted(m for m in sys.modules if m.startswith('groundstation.live')))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"

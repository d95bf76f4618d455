"""The benches import the installed package, never the tests: no file under bench/ imports ``tests`` or a module of
tests/ (run as a script, a bench sees bench/ on its path, the package from the install), nor edits ``sys.path``."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TEST_MODULES = {"tests"} | {p.stem for p in (ROOT / "tests").glob("*.py")}


def offences(source: str) -> list[str]:
    """What in this Python source imports the tests or touches ``sys.path``, one line each."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module]
        else:
            names = []
        found += [
            f"line {node.lineno}: imports {n}" for n in names if n.split(".")[0] in TEST_MODULES
        ]
        if (
            isinstance(node, ast.Attribute)
            and node.attr == "path"
            and isinstance(node.value, ast.Name)
            and node.value.id == "sys"
        ):
            found.append(f"line {node.lineno}: sys.path")
    return sorted(found)


def test_the_check_sees_an_import_of_the_tests_and_a_path_edit():
    source = (
        "import sys\nsys.path.insert(0, 'tests')\nfrom live_helpers import skyfix\nimport tests.x\n"
    )
    assert offences(source) == [
        "line 2: sys.path",
        "line 3: imports live_helpers",
        "line 4: imports tests.x",
    ]
    assert (
        offences("from groundstation.testing.live import skyfix\nimport sys\nsys.exit(0)\n") == []
    )


def test_no_bench_imports_the_tests_or_edits_sys_path():
    found = {
        str(p.relative_to(ROOT)): offences(p.read_text())
        for p in sorted((ROOT / "bench").rglob("*.py"))
    }
    assert {path: lines for path, lines in found.items() if lines} == {}

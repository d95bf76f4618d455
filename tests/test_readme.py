"""The README stays a front page: at most 200 lines, the two commands first, every relative link alive.

Everything else lives in the docs site (docs/, built by ``mkdocs build --strict`` in ``./dev test``).
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
MAX_LINES = 200
#: the first code block must begin within this many lines: the commands come before any prose
COMMANDS_WITHIN_LINES = 5


def _lines() -> list[str]:
    return README.read_text(encoding="utf-8").splitlines()


def _first_code_block(lines: list[str]) -> tuple[int, list[str]]:
    """``(index of its opening fence, its lines)`` of the README's first fenced code block."""
    start = next(i for i, line in enumerate(lines) if line.startswith("```"))
    end = next(i for i in range(start + 1, len(lines)) if lines[i].startswith("```"))
    return start, lines[start + 1 : end]


def test_readme_is_at_most_200_lines():
    assert len(_lines()) <= MAX_LINES, (
        f"README.md has {len(_lines())} lines: move the detail to docs/"
    )


def test_the_two_commands_are_at_the_top():
    start, block = _first_code_block(_lines())
    assert start < COMMANDS_WITHIN_LINES, f"the first code block starts at line {start + 1}"
    commands = [line.split("#")[0].strip() for line in block]
    assert commands[:2] == ["./dev demo", "./dev test"], block


def test_the_dev_script_has_both_commands():
    dev = (ROOT / "dev").read_text(encoding="utf-8")
    assert re.search(r"^\s*demo\)", dev, re.MULTILINE) and re.search(
        r"^\s*test\)", dev, re.MULTILINE
    )


def test_relative_links_exist():
    text = README.read_text(encoding="utf-8")
    targets = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text)
    local = [t for t in targets if "://" not in t]
    assert local, "the README links into the docs"
    missing = [t for t in local if not (ROOT / t).exists()]
    assert not missing, f"README.md links to files that do not exist: {missing}"

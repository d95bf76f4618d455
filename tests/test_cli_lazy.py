"""``skyfix`` imports only the chosen subcommand's module: ``skyfix process`` starts without the live stack."""

from __future__ import annotations

import argparse
import importlib
import subprocess
import sys

import pytest
from live_helpers import ROOT

from groundstation.cli import COMMANDS, main

LIVE_STACK = ("zenoh", "pymavlink", "mavsdk", "aiohttp", "matplotlib")


def _loaded_after(argv: list[str], names) -> list[str]:
    """Which of the modules ``names`` a fresh interpreter has loaded after ``skyfix ARGV`` (``--help``: exits)."""
    code = (
        "import sys\nfrom groundstation.cli import main\ntry:\n    main(sys.argv[1:])\nexcept SystemExit:\n"
        f"    pass\nprint('loaded:', *(n for n in {tuple(names)!r} if n in sys.modules), file=sys.stderr)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code, *argv],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
        check=True,
    )
    return out.stderr.splitlines()[-1].split()[1:]


def test_process_help_loads_no_live_stack():
    assert _loaded_after(["process", "--help"], LIVE_STACK) == []


def test_top_level_help_loads_no_subcommand():
    assert _loaded_after(["--help"], sorted({module for _, module, _ in COMMANDS})) == []


def test_top_level_help_lists_every_subcommand(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--help"])
    assert e.value.code == 0
    listed = " ".join(capsys.readouterr().out.split())
    for name, _, help_line in COMMANDS:
        assert f"{name} {help_line}" in listed


def test_each_module_registers_its_name_with_the_tables_help():
    for name, module, help_line in COMMANDS:
        sub = argparse.ArgumentParser().add_subparsers()
        importlib.import_module(module).register(sub, name, help_line)
        assert list(sub.choices) == [name]
        assert [a.help for a in sub._choices_actions] == [help_line]


def test_unknown_subcommand_is_argparses_error(capsys):
    with pytest.raises(SystemExit) as e:
        main(["procss"])
    assert e.value.code == 2
    assert "invalid choice: 'procss' (choose from 'process'," in capsys.readouterr().err

"""``skyfix deploy`` prints the shipped deployment files byte for byte (the source tree's ``deploy/``) and copies them
all; ``skyfix --version`` is the installed distribution's version."""

from __future__ import annotations

import subprocess
import sys
from importlib.metadata import version

import pytest
from live_helpers import ROOT

from groundstation.cli import main

DEPLOY = ROOT / "deploy"


def _tracked_deploy_files() -> list[str]:
    """The deploy files git holds (the ones a wheel ships), relative to ``deploy/``."""
    out = subprocess.run(
        ["git", "ls-files", "deploy"], cwd=ROOT, capture_output=True, text=True, check=True
    )
    return sorted(line.removeprefix("deploy/") for line in out.stdout.splitlines())


@pytest.mark.parametrize(
    "argv, path",
    [
        (["unit"], "skyfix.service"),
        (["config"], "field.toml"),
        (["config", "calibration"], "calibration.toml"),
        (["certs"], "make_certs.sh"),
        (["zenoh", "peer"], "zenoh/peer.json5"),
        (["zenoh", "vehicle-router"], "zenoh/vehicle-router.json5"),
    ],
)
def test_deploy_prints_the_file(capsys, argv, path):
    assert main(["deploy", *argv]) == 0
    assert capsys.readouterr().out == (DEPLOY / path).read_text()


def test_deploy_zenoh_lists_every_zenoh_file(capsys):
    assert main(["deploy", "zenoh"]) == 0
    names = [line.split()[0] for line in capsys.readouterr().out.splitlines()]
    expected = [f.name.removesuffix(".json5") for f in (DEPLOY / "zenoh").iterdir() if f.is_file()]
    assert names == sorted(expected)


def test_deploy_unknown_zenoh_name_is_argparses_error(capsys):
    with pytest.raises(SystemExit) as e:
        main(["deploy", "zenoh", "no-such-file"])
    assert e.value.code == 2
    assert "invalid choice: 'no-such-file'" in capsys.readouterr().err


def test_deploy_all_copies_every_tracked_file_and_never_overwrites(tmp_path, capsys):
    out = tmp_path / "etc"
    assert main(["deploy", "all", "--out", str(out)]) == 0
    copied = sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())
    tracked = _tracked_deploy_files()
    assert set(tracked) <= set(copied)
    for rel in tracked:
        assert (out / rel).read_bytes() == (DEPLOY / rel).read_bytes()
    for rel in tracked:
        (out / rel).unlink()
    (out / "field.toml").write_text("mine")
    capsys.readouterr()
    assert main(["deploy", "all", "--out", str(out)]) == 2
    assert "field.toml exists: not overwritten" in capsys.readouterr().err
    assert (out / "field.toml").read_text() == "mine"
    assert not (out / "skyfix.service").exists()  # nothing copied once one file is taken


def test_version_is_the_installed_distributions():
    out = subprocess.run(
        [sys.executable, "-m", "groundstation.cli", "--version"],
        capture_output=True,
        text=True,
        check=True,
        timeout=60,
    )
    assert out.stdout.strip() == f"skyfix {version('skyfix')}"

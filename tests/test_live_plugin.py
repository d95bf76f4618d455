"""A depth source of another distribution: one module registered by name, chosen by a config file, run by ``skyfix
run`` with no module of skyfix edited.

The plugin is installed the way pip installs one: its module and a ``dist-info`` folder whose entry point (group
``skyfix.parts``) names the module, on the interpreter's path. The registry then offers its name to the
configuration (the ``depth_source`` choices and the JSON Schema's enum) and the service builds and runs it: its
depth reaches the telemetry and its status is the run's ``depth`` section."""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from live_helpers import ROOT, skyfix, stop, wait_for

from groundstation.live import config
from localizer.contract import ConfigError

DEPTH_M = 2.75  # the plugin's constant depth
READY_SAMPLES = 5  # the plugin touches its ready file once the telemetry has taken this many

PLUGIN = textwrap.dedent(
    f'''
    """A constant depth, stamped now, every 50 ms: a depth source outside skyfix."""

    import asyncio
    import os
    import time
    from pathlib import Path

    from groundstation.live.registry import DepthInput, register


    class ConstantDepth:
        def __init__(self, depth: DepthInput):
            self.depth = depth
            self.listeners = []
            self.received = 0
            self.last_recv = None

        async def run(self) -> None:
            while True:
                now = time.time()
                if self.depth.gate.check(now, {DEPTH_M}) is None and self.depth.tel.add_depth(
                    now, {DEPTH_M}, now
                ):
                    self.received += 1
                    self.last_recv = now
                    if self.received == {READY_SAMPLES}:
                        Path(os.environ["CONSTANT_DEPTH_READY"]).touch()
                await asyncio.sleep(0.05)

        def status(self, now: float) -> dict:
            age = None if self.last_recv is None else round(now - self.last_recv, 3)
            return {{
                "key": None, "url": None, "shape": "constant", "received": self.received, "bad": 0,
                "refused": 0, "jumps": 0, "other": 0, "age_s": age, "t": self.depth.tel.depth.last_t,
                "depth_m": {DEPTH_M} if self.received else None, "sigma_m": None, "source": "skyfix",
                "vertical_speed_mps": None, "rates_hz": None, "rate_requests": None, "ardusub": None,
                "link": None,
            }}


    @register("depth", "constant", "a constant depth (a plugin)")
    def build(depth: DepthInput) -> ConstantDepth:
        return ConstantDepth(depth)
    '''
)


#: prints the run configuration's JSON Schema of depth_source
SCHEMA_ENUM = (
    "import json; from groundstation.contracts import GROUNDSTATION as g; "
    "print(json.dumps(g.json_schema('run-config')['properties']['depth_source']))"
)


def _install_plugin(site: Path) -> None:
    """The plugin's module and its distribution's metadata with the entry point, as pip would leave them."""
    (site / "skyfix_constant_depth.py").write_text(PLUGIN)
    info = site / "skyfix_constant_depth-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(
        "Metadata-Version: 2.1\nName: skyfix-constant-depth\nVersion: 0.1\n"
    )
    (info / "entry_points.txt").write_text("[skyfix.parts]\nconstant = skyfix_constant_depth\n")


def _config(tmp_path: Path) -> Path:
    cfg = tmp_path / "run.toml"
    cfg.write_text(
        f'calibration = "{ROOT / "sim_fixtures" / "bundled" / "oblique_2m" / "session.toml"}"\n'
        'mavlink = "udpin:127.0.0.1:0"\nvideo = "none"\ngps_input = "none"\n'
        'zenoh_listen = ["tcp/127.0.0.1:0"]\nno_ui = true\nduration_s = 120\n'
        f'stats = "{tmp_path / "stats.json"}"\ndepth_source = "constant"\n'
    )
    return cfg


def test_a_plugins_depth_source_is_chosen_by_name_and_runs(tmp_path):
    site = tmp_path / "site"
    site.mkdir()
    _install_plugin(site)
    cfg = _config(tmp_path)
    ready = tmp_path / "ready"
    env = dict(os.environ, PYTHONPATH=str(site), CONSTANT_DEPTH_READY=str(ready))

    # without the plugin the name is no choice: one line naming the file, the key and the value
    refused = subprocess.run(
        skyfix("run", "--config", str(cfg)),
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
        check=False,
    )
    assert refused.returncode == 2
    assert f"skyfix run: error: {cfg}: depth_source = 'constant'" in refused.stderr

    # with it, the configuration's schema offers it
    schema = subprocess.run(
        [
            sys.executable,
            "-c",
            SCHEMA_ENUM,
        ],
        capture_output=True,
        text=True,
        check=True,
        env=env,
        timeout=120,
    )
    assert "constant" in json.loads(schema.stdout)["enum"]

    # and the service runs it: its depth in the telemetry, its status the run's depth section
    with open(tmp_path / "run.log", "w") as log:
        proc = subprocess.Popen(
            skyfix("run", "--config", str(cfg)),
            stdout=log,
            stderr=subprocess.STDOUT,
            cwd=ROOT,
            env=env,
        )
    try:
        wait_for(ready.exists, 60, f"the plugin's {READY_SAMPLES} depths")
    finally:
        stop(proc)
    assert proc.returncode == 0, (tmp_path / "run.log").read_text()
    final = json.loads((tmp_path / "stats.json").read_text())
    assert final["depth"]["shape"] == "constant"
    assert final["depth"]["received"] >= READY_SAMPLES
    assert final["depth"]["depth_m"] == DEPTH_M
    assert "depth" not in final["problems"]


def test_a_part_whose_module_is_missing_is_refused_saying_what_to_install(monkeypatch):
    """The mavsdk backend without MAVSDK-Python (``sys.modules`` entry None: not importable)."""
    monkeypatch.setitem(sys.modules, "mavsdk", None)
    parser = argparse.ArgumentParser()
    config.add_arguments(parser)
    args = parser.parse_args(["--calibration", "cal.toml", "--mavlink-backend", "mavsdk"])
    with pytest.raises(ConfigError) as e:
        config.run_config(args)
    assert str(e.value) == (
        "options: --mavlink-backend = 'mavsdk': needs mavsdk: pip install 'skyfix[mavsdk]'"
    )

"""A depth source and an output of another distribution: each one module registered by name, chosen by a config
file, run by ``skyfix run`` with no module of skyfix edited.

The plugin is installed the way pip installs one: its module and a ``dist-info`` folder whose entry point (group
``skyfix.parts``) names the module, on the interpreter's path. The registry then offers its name to the
configuration (the ``depth_source`` or ``outputs`` choices and the JSON Schema's enum) and the service builds and
runs it: the depth source's depth reaches the telemetry and its status is the run's ``depth`` section; the output
gets every fix the service makes (the same the Zenoh output publishes) and its status is ``outputs.NAME``."""

from __future__ import annotations

import argparse
import json
import os
import socket
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from conftest import T0_UNIX
from live_helpers import (
    ROOT,
    free_port,
    read_jsonl,
    replay_shift,
    skyfix,
    start,
    stop,
    truth_errors_m,
    wait_for,
)

from groundstation.live import config
from localizer.contract import ConfigError
from localizer.fix import locate
from localizer.pose import camera_pose
from localizer.telemetry import Telemetry

DEPTH_M = 2.75  # the plugin's constant depth
READY_SAMPLES = 5  # the plugin touches its ready file once the telemetry has taken this many

PLUGIN = textwrap.dedent(
    f'''
    """A constant depth, stamped now, every 50 ms: a depth source outside skyfix (its table [parts.constant]: the
    file it touches once ready)."""

    import asyncio
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
                        Path(self.depth.settings["ready"]).touch()
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


def _install_plugin(
    site: Path, module: str = "skyfix_constant_depth", text: str = PLUGIN, name: str = "constant"
) -> None:
    """The plugin's module and its distribution's metadata with the entry point, as pip would leave them."""
    (site / f"{module}.py").write_text(text)
    info = site / f"{module}-0.1.dist-info"
    info.mkdir()
    dist = module.replace("_", "-")
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(f"[skyfix.parts]\n{name} = {module}\n")


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
    cfg.write_text(cfg.read_text() + f'[parts.constant]\nready = "{ready}"\n')
    env = dict(os.environ, PYTHONPATH=str(site))

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


OUTPUT_PLUGIN = textwrap.dedent(
    '''
    """Each fix as one JSON line in a file (its table [parts.fix_file]: path): an output outside skyfix."""

    import asyncio
    import json

    from pydantic.dataclasses import dataclass

    from groundstation.live.registry import OutputInput, register
    from localizer.contract import CLOSED, Text


    @dataclass(frozen=True, config=CLOSED)
    class Settings:
        path: Text  # the file the fixes are written to


    class FixFile:
        def __init__(self, out: OutputInput):
            self.path = out.settings.path
            self.uuv = out.options.id
            self.file = open(self.path, "w")  # its start: the file is there before the first fix
            self.written = 0

        async def run(self) -> None:
            try:
                await asyncio.get_running_loop().create_future()
            finally:  # its stop
                self.file.close()

        def on_fix(self, fix, info) -> None:
            row = {"uuv": self.uuv, "t": fix.t_unix, "status": fix.status, "lat": fix.lat, "lon": fix.lon}
            self.file.write(json.dumps(row) + "\\n")
            self.written += 1

        def status(self, now: float) -> dict:
            return {"path": self.path, "written": self.written}


    @register("output", "fix_file", "each fix as a JSON line in a file (a plugin)", settings=Settings)
    def build(out: OutputInput) -> FixFile:
        return FixFile(out)
    '''
)
SESSION = ROOT / "sim_fixtures" / "bundled" / "nadir_hover"


def test_a_plugins_output_is_chosen_by_name_and_gets_every_fix_of_a_run(tmp_path):
    """``skyfix replay`` of a bundled session into ``skyfix run`` whose run.toml names the plugin's output beside
    Zenoh's: the plugin's file holds every fix the run published on Zenoh, in order, the valid ones on the UUV."""
    site = tmp_path / "site"
    site.mkdir()
    _install_plugin(site, "skyfix_fix_file", OUTPUT_PLUGIN, "fix_file")
    fixes_file = tmp_path / "fixes.jsonl"
    env = dict(os.environ, PYTHONPATH=str(site))
    mav, video = free_port(), free_port()
    zenoh_ep = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    cfg = tmp_path / "run.toml"
    cfg.write_text(
        f'calibration = "{SESSION / "session.toml"}"\n'
        f'mavlink = "udpin:127.0.0.1:{mav}"\nvideo = "udp://127.0.0.1:{video}"\n'
        f'video_latency_ms = 0\ngps_input = "none"\nzenoh_listen = ["{zenoh_ep}"]\nno_ui = true\n'
        f'duration_s = 120\nstats = "{tmp_path / "stats.json"}"\noutputs = ["zenoh", "fix_file"]\n'
        f'[parts.fix_file]\npath = "{fixes_file}"\n'
    )
    replay_cmd = skyfix(
        "replay",
        str(SESSION),
        *("--mavlink-out", f"udpout:127.0.0.1:{mav}", "--video-out", f"udp://127.0.0.1:{video}"),
        *("--zenoh-connect", zenoh_ep, "--uuv-listen", "", "--tail-s", "1.0"),
    )
    run = subprocess.Popen(
        skyfix("run", "--config", str(cfg)),
        stdout=(tmp_path / "run.log").open("w"),
        stderr=subprocess.STDOUT,
        cwd=ROOT,
        env=env,
    )
    try:
        wait_for(fixes_file.exists, 60, "the plugin's file (the service built its outputs)")
        replay = start(replay_cmd, tmp_path / "replay.log")
        replay.wait(60)
    finally:
        stop(run)
    run_log = (tmp_path / "run.log").read_text()
    assert run.returncode == 0, run_log[-3000:]
    assert replay.returncode == 0, (tmp_path / "replay.log").read_text()[-3000:]
    final = json.loads((tmp_path / "stats.json").read_text())
    rows = read_jsonl(fixes_file)
    assert final["outputs"] == {
        "zenoh": {"key": "skyfix/uuv/fix", "published": final["fixes_published"]},
        "fix_file": {"path": str(fixes_file), "written": len(rows)},
    }
    assert len(rows) == final["fixes_published"] == final["pipeline"]["processed"] > 0
    assert [r["t"] for r in rows] == sorted(r["t"] for r in rows)
    assert {r["uuv"] for r in rows} == {"uuv1"}
    ok = [r for r in rows if r["status"] == "ok"]
    assert len(ok) >= 0.5 * len(rows), {r["status"] for r in rows}
    shift = replay_shift(tmp_path / "replay.log")
    err = truth_errors_m(
        SESSION,
        np.array([r["t"] for r in ok]) - shift,
        np.array([r["lat"] for r in ok]),
        np.array([r["lon"] for r in ok]),
    )
    assert float(np.median(err)) < 0.5, err
    # gps_input = "none": the default's GPS_INPUT has nothing to send
    assert "gps_input" not in final


def test_a_plugins_depth_is_recorded_under_its_registered_name(make_cal, make_telemetry):
    """The service names the telemetry's depth after the part it built (``Telemetry.name_depth_source``): a depth its
    source adds without a word is that name's, in the pose and the fix; a word never named is refused."""
    cal = make_cal()
    tel = make_telemetry(duration_s=3.0)
    tel.depth.clear()
    assert tel.add_depth(T0_UNIX + 0.5, 2.0, T0_UNIX + 0.55)  # before: skyfix's
    tel.name_depth_source("constant")
    assert tel.add_depth(T0_UNIX + 1.5, 2.1, T0_UNIX + 1.55)
    assert not tel.add_depth(T0_UNIX + 2.0, 2.1, T0_UNIX + 2.05, source="sonar")
    pose = camera_pose(cal, tel, [T0_UNIX + 0.6, T0_UNIX + 1.6])
    assert list(pose.depth_source) == ["skyfix", "constant"]
    assert list(locate(cal, pose, [960.0] * 2, [540.0] * 2).depth_source) == ["skyfix", "constant"]
    assert Telemetry().add_depth(1.0, 2.0) and Telemetry().depth_source == "skyfix"


@pytest.mark.parametrize(
    "flags,why",
    [
        (
            ["--outputs", "zenoh", "--outputs", "zenoh", "--gps-input", "none"],
            "--outputs = ['zenoh', 'zenoh']: zenoh named twice",
        ),
        (
            ["--outputs", "zenoh", "--gps-input", "udpout:127.0.0.1:14660"],
            (
                "--outputs = ['zenoh']: gps_input = 'udpout:127.0.0.1:14660' names a link, but gps_input is "
                'not among the outputs: add it, or say gps_input = "none"'
            ),
        ),
        (["--outputs", "sonar"], "--outputs = 'sonar': expected one of 'zenoh' or 'gps_input'"),
    ],
)
def test_outputs_each_once_and_gps_input_among_them_else_one_line(flags, why):
    parser = argparse.ArgumentParser()
    config.add_arguments(parser)
    args = parser.parse_args(["--calibration", "cal.toml", *flags])
    with pytest.raises(ConfigError) as e:
        config.run_config(args)
    assert str(e.value) == f"options: {why}"


def test_the_default_outputs_are_zenoh_and_gps_input_for_each_uuv(tmp_path):
    cfg = tmp_path / "run.toml"
    cfg.write_text(
        'calibration = "cal.toml"\n'
        '[[uuv]]\nid = "a"\ngps_input = "udpout:127.0.0.1:14660"\n'
        '[[uuv]]\nid = "b"\ngps_input = "none"\noutputs = ["zenoh"]\ndepth_key = "uuv/b/depth"\n'
    )
    parser = argparse.ArgumentParser()
    config.add_arguments(parser)
    run = config.run_config(parser.parse_args(["--config", str(cfg)]))
    assert [u.outputs for u in run.uuvs] == [("zenoh", "gps_input"), ("zenoh",)]


def test_a_plugin_whose_output_is_no_output_stops_the_start_in_one_line(tmp_path):
    """A part registered as an output whose build returns something without on_fix: exit 2, one line naming it."""
    site = tmp_path / "site"
    site.mkdir()
    broken = (
        "from groundstation.live.registry import register\n\n\n"
        '@register("output", "broken", "builds no output")\n'
        "def build(out):\n    return object()\n"
    )
    _install_plugin(site, "skyfix_broken_output", broken, "broken")
    cfg = _config(tmp_path)
    cfg.write_text(
        cfg.read_text().replace('depth_source = "constant"', 'outputs = ["zenoh", "broken"]')
    )
    run = subprocess.run(
        skyfix("run", "--config", str(cfg)),
        capture_output=True,
        text=True,
        cwd=ROOT,
        env=dict(os.environ, PYTHONPATH=str(site)),
        timeout=120,
        check=False,
    )
    assert run.returncode == 2, run.stderr[-3000:]
    assert run.stderr.strip().splitlines()[-1] == (
        "skyfix run: error: output broken (skyfix_broken_output): build() = 'object': not an output: it "
        "needs run(), status(now) and on_fix(fix, info)"
    )


#: validates each config file given and prints one line each: its UUVs' part settings, or the error
CHECK_CONFIGS = textwrap.dedent(
    """
    import argparse, sys
    from groundstation.live import config
    for path in sys.argv[1:]:
        parser = argparse.ArgumentParser()
        config.add_arguments(parser)
        try:
            print([u.parts for u in config.run_config(parser.parse_args(["--config", path])).uuvs])
        except config.ConfigError as e:
            print(e)
    """
)


def test_a_plugins_settings_are_its_table_checked_at_start_else_one_line(tmp_path):
    """``[parts.fix_file]`` (one UUV) or ``[uuv.parts.fix_file]`` (each [[uuv]] table) checked against the settings
    the plugin declares: a wrong, missing or unknown key, or a table for a part the UUV does not run, one line
    naming the file, the key and the value."""
    site = tmp_path / "site"
    site.mkdir()
    _install_plugin(site, "skyfix_fix_file", OUTPUT_PLUGIN, "fix_file")
    one = 'calibration = "cal.toml"\noutputs = ["zenoh", "fix_file"]\n'
    uuvs = 'calibration = "cal.toml"\n[[uuv]]\nid = "a"\noutputs = ["fix_file"]\n'
    cases = {
        one + '[parts.fix_file]\npath = "a.jsonl"\n': "[{'fix_file': {'path': 'a.jsonl'}}]",
        one + "[parts.fix_file]\npath = 3\n": "parts.fix_file.path = 3: expected a string",
        one: "parts.fix_file.path = None: missing",
        one + '[parts.fix_file]\npath = "a"\nmode = "w"\n': (
            "parts.fix_file.mode = 'w': unknown key (known: path)"
        ),
        'calibration = "cal.toml"\noutputs = ["zenoh"]\n[parts.fix_file]\npath = "a"\n': (
            "parts.fix_file = {'path': 'a'}: fix_file is not a part this UUV runs (depth_source 'skyfix', "
            "outputs zenoh)"
        ),
        uuvs
        + "[uuv.parts.fix_file]\npath = 3\n": "uuv[0].parts.fix_file.path = 3: expected a string",
        uuvs + '[uuv.parts.fix_file]\npath = "a"\n[[uuv]]\nid = "b"\noutputs = ["zenoh"]\n'
        'depth_key = "b/depth"\n': "[{'fix_file': {'path': 'a'}}, {}]",
        'calibration = "cal.toml"\n[parts.fix_file]\npath = "a"\n[[uuv]]\nid = "a"\n': (
            "parts = {'fix_file': {'path': 'a'}}: set per UUV, in each [[uuv]] table, when there are several"
        ),
    }
    files = []
    for i, text in enumerate(cases):
        files.append(tmp_path / f"run{i}.toml")
        files[-1].write_text(text)
    checked = subprocess.run(
        [sys.executable, "-c", CHECK_CONFIGS, *map(str, files)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env=dict(os.environ, PYTHONPATH=str(site)),
        timeout=120,
        check=True,
    )
    lines = checked.stdout.splitlines()
    assert len(lines) == len(cases), checked.stdout
    for path, want, got in zip(files, cases.values(), lines):
        assert got == (want if want.startswith("[") else f"{path}: {want}")

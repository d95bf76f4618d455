"""The height from the UUV's size in a run: which measurements reach the height's fusion, the warning, the summary.

Synthetic measurements with a known bias go through :meth:`HeightFromSize.take`; the real Telemetry
receives what ``auto`` hands over. And ``skyfix process`` on a generated session whose configured
height is 1 m too high (the take-off height written wrong): the estimate it prints finds that metre,
and its warning says so.
"""

import math
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from live_helpers import wait_until

from groundstation.height_from_size import HeightFromSize
from localizer.calibration import Calibration
from localizer.size_range import MIN_FRAMES, SizeHeight
from localizer.telemetry import Telemetry
from sim_fixtures.generate import generate
from sim_fixtures.scenario import load_scenario, with_overrides

ROOT = Path(__file__).resolve().parents[1]


def _cal(cal_dict):
    return Calibration.from_dict(cal_dict())


def _heights(bias, n=60, hz=5.0, sigma=0.05, t0=1000.0, outlier_at=()):
    rng = np.random.default_rng(3)
    out = []
    for k in range(n):
        measured = 10.0 - bias + rng.normal() * sigma + (2.0 if k in outlier_at else 0.0)
        out.append(SizeHeight(t0 + k / hz, measured, sigma, 0.04, 10.0, 0.3, 0.2))
    return out


def test_auto_hands_over_only_agreeing_measurements_once_sure(cal_dict):
    tel = Telemetry()
    work = HeightFromSize(_cal(cal_dict), tel, "auto")
    heights = _heights(0.8, outlier_at=(3, 45))
    for k, h in enumerate(heights):
        work.take(h)
        if not work.estimate.sure:
            assert "size" not in tel.height_fixes  # nothing before it is sure
    assert work.estimate.sure and abs(work.estimate.bias_m - 0.8) < 2 * work.estimate.sigma_m
    fixes = tel.height_fixes["size"]
    # all but the two outliers, the early ones too
    assert len(fixes) == work.applied == len(heights) - 2
    t = [h.t_unix for h in heights]
    assert t[3] not in fixes.times and t[45] not in fixes.times and fixes.times[0] == t[0]
    values = fixes.values
    assert np.allclose(
        values[:, 0], [h.uav_height_m for k, h in enumerate(heights) if k not in (3, 45)]
    )
    assert np.allclose(values[:, 1], [math.hypot(0.05, 0.04)] * len(values))
    work.take("poor_fit")
    assert work.rejected == {"poor_fit": 1} and work.status()["rejected"] == {"poor_fit": 1}


def test_check_hands_nothing_over_and_warns_once(cal_dict, caplog):
    tel = Telemetry()
    work = HeightFromSize(_cal(cal_dict), tel, "check")
    for h in _heights(0.8, n=100):
        work.take(h)
    assert "size" not in tel.height_fixes and work.applied == 0
    assert (
        len(work.warnings) == 1 and len([r for r in caplog.records if r.name == "skyfix.size"]) == 1
    )
    assert re.search(r"configured height above the water is 0\.[78]\d m above", work.warnings[0]), (
        work.warnings[0]
    )
    s = work.status()
    assert (
        s["sure"] and s["frames"] == 100 and s["mode"] == "check" and s["at_surface_share"] == 1.0
    )
    assert abs(s["bias_m"] - 0.8) < 0.05 and s["last_height_m"] == pytest.approx(
        work.last.uav_height_m, abs=1e-3
    )
    assert "configured - measured +0.8" in work.summary() and "sure" in work.summary()


def test_no_warning_when_the_configured_height_agrees(cal_dict):
    work = HeightFromSize(_cal(cal_dict), Telemetry(), "check")
    for h in _heights(0.1, n=100):  # within twice the configured height's own 0.3 m
        work.take(h)
    assert work.estimate.sure and not work.warnings


def test_rate_of_measured_frames(cal_dict):
    work = HeightFromSize(_cal(cal_dict), Telemetry(), "check", measure_hz=5.0, sure_hz=1.0)
    due = [work.due(1000.0 + k / 30.0) for k in range(90)]  # 3 s at 30 fps
    assert sum(due) == 15 and due[0] and due[6] and not any(due[1:6])
    for h in _heights(0.1, n=40, t0=1000.0):  # 8 s at 5 Hz: sure
        work.take(h)
    assert work.estimate.sure
    due = [work.due(1010.0 + k / 30.0) for k in range(90)]  # sure: a frame a second
    assert sum(due) == 3 and due[0] and due[30] and due[60]
    for h in _heights(
        3.0, n=40, t0=1011.0, sigma=1.0
    ):  # a scatter that unsettles it: back to measuring at 5 Hz
        work.take(h)
    assert not work.estimate.sure
    due = [work.due(1030.0 + k / 30.0) for k in range(30)]
    assert sum(due) == 5


def test_off_is_not_a_measuring_mode(cal_dict):
    with pytest.raises(ValueError, match="height_from_size = 'off'"):
        HeightFromSize(_cal(cal_dict), Telemetry(), "off")


@pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="needs the ffmpeg CLI")
def test_process_finds_the_configured_heights_error(tmp_path):
    sc = with_overrides(
        load_scenario(ROOT / "sim_fixtures" / "scenarios" / "size_surface.toml"),
        duration_s=7.0,
        camera={"width": 960, "height": 540},
        uav={"height_m": 9.0},
    )
    out = tmp_path / "session"
    generate(sc, out)
    toml = out / "session.toml"
    # the configured height 2 m too high: beyond twice its own sigma (the barometer's drift since the autopilot's boot,
    # localizer/height.py) and the estimate's, so the disagreement is worth a warning
    wrong = sc.site.takeoff_height_above_surface_m + 2.0
    toml.write_text(
        re.sub(
            r"takeoff_height_above_surface_m = [-\d.e]+",
            f"takeoff_height_above_surface_m = {wrong!r}",
            toml.read_text(),
        )
    )
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "groundstation.cli",
            "process",
            str(out),
            "--out",
            str(tmp_path / "p"),
            "--quiet",
        ],
        check=False,
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=600,
    )
    assert run.returncode == 0, run.stderr
    m = re.search(
        r"height from the UUV's size: configured - measured ([-+][\d.]+) ± ([\d.]+) m over (\d+) frames.*"
        r", (sure|not sure)",
        run.stdout,
    )
    assert m, run.stdout
    bias, sigma, frames, sure = float(m[1]), float(m[2]), int(m[3]), m[4]
    assert (
        sure == "sure" and frames >= MIN_FRAMES and abs(bias - 2.0) <= 2 * sigma and sigma < 0.2
    ), run.stdout
    assert "m above what the UUV's size in the image says" in run.stderr, run.stderr


MEASURING_POOL = """
import multiprocessing, os, time
from concurrent.futures import ProcessPoolExecutor
from groundstation.height_from_size import start_measuring_process
pool = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"), initializer=start_measuring_process)
print(pool.submit(os.getpid).result(), flush=True)
time.sleep(120)
"""


def _running(pid: int) -> bool:
    """Whether process ``pid`` exists and is not a zombie (an exited child nobody reaped)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


@pytest.mark.skipif(sys.platform != "linux", reason="the parent-death signal is Linux's")
def test_the_measuring_process_ends_when_the_service_is_killed():
    """``kill -9`` of a service leaves no measuring process behind (its pool's initializer, as the service uses it)."""
    service = subprocess.Popen(
        [sys.executable, "-c", MEASURING_POOL], stdout=subprocess.PIPE, text=True, cwd=ROOT
    )
    try:
        child = int(service.stdout.readline())
        assert _running(child)
    finally:
        service.kill()
        service.wait()
    assert wait_until(lambda: not _running(child), 20), (
        f"measuring process {child} outlived its killed service"
    )

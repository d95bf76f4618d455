"""``skyfix report``: plots a field engineer reads, and a summary whose numbers are checked against
independent computations (pyproj's geodesic for the errors); progress with an ETA on long runs."""

from __future__ import annotations

import re
import subprocess
import sys

import numpy as np
import pytest
from matplotlib.image import imread
from pyproj import Geod

from groundstation.cli import main
from groundstation.session.positions import read_positions_csv
from sim_fixtures.bundle import BUNDLED_DIR

GEOD = Geod(ellps="WGS84")
SESSION = BUNDLED_DIR / "occlusion"


def _pngs(folder):
    for name in ("top_view.png", "timeline.png", "status.png"):
        img = imread(folder / name)
        assert img.ndim == 3 and img.shape[0] > 150 and img.shape[1] > 600, name
        assert img[..., :3].std() > 0.05, f"{name} is blank"


def test_report_with_truth(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["process", str(SESSION), "--out", str(out), "--use-track", "--quiet"]) == 0
    capsys.readouterr()
    assert main(["report", str(out), "--truth", str(SESSION / "truth.csv")]) == 0
    text = capsys.readouterr().out
    _pngs(out / "report")
    pos = read_positions_csv(out / "positions.csv")
    ok = pos.status == "ok"
    truth = np.genfromtxt(SESSION / "truth.csv", delimiter=",", names=True)
    lat, lon = (
        np.interp(pos.t_unix[ok], truth["t"], truth["lat"]),
        np.interp(pos.t_unix[ok], truth["t"], truth["lon"]),
    )
    err = GEOD.inv(pos.lon[ok], pos.lat[ok], lon, lat)[2]
    assert f"{len(pos)} frames, {ok.sum()} with a fix ({ok.mean():.1%})" in text
    assert (
        f"error against truth: mean {err.mean():.3f} m, p95 {np.percentile(err, 95):.3f} m" in text
    )
    gap = pos.t_unix[~ok]
    assert f"1 stretches without a fix, longest {gap[-1] - gap[0]:.1f} s (no_track)" in text


def test_report_without_truth_names_each_gap(tmp_path, capsys):
    rows = ["t,lat,lon,depth_m,h_acc_m,status"]
    statuses = (
        ["ok"] * 10
        + ["lost"] * 5
        + ["ok"] * 3
        + ["stale_attitude"] * 12
        + ["no_depth"] * 2
        + ["ok"] * 8
    )
    for i, s in enumerate(statuses):
        ll = f"{63.44 + i * 1e-6:.9f},{10.4 + i * 2e-6:.9f}" if s == "ok" else ","
        # the video stops for 2 s before frame 35
        t = 1763800000 + i * 0.1 + (2.0 if i >= 35 else 0.0)
        rows.append(f"{t:.3f},{ll},1.0,{0.2 if s == 'ok' else ''},{s}")
    (tmp_path / "positions.csv").write_text("\n".join(rows) + "\n")
    assert main(["report", str(tmp_path), "--out", str(tmp_path / "plots")]) == 0
    text = capsys.readouterr().out
    _pngs(tmp_path / "plots")
    assert "40 frames, 21 with a fix (52.5%)" in text and "error against truth" not in text
    assert "3 stretches without a fix, longest 1.1 s (stale_attitude)" in text
    assert "1 pauses in the frames (video stopped), longest 2.1 s" in text


def test_report_of_nothing_is_one_line(tmp_path, capsys):
    (tmp_path / "positions.csv").write_text("t,lat,lon,depth_m,h_acc_m,status\n")
    assert main(["report", str(tmp_path)]) == 2
    assert (
        capsys.readouterr().err.strip()
        == f"skyfix report: error: {tmp_path / 'positions.csv'}: no rows"
    )


def _skyfix(*args):
    return subprocess.run(
        [sys.executable, "-m", "groundstation.cli", *args],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )


ETA = re.compile(
    r"tiny: (rendering|tracking): 100% (\d+)/\2 frames \[\d\d:\d\d elapsed, ETA 00:00, +[\d.]+ frames/s\]"
)


def test_long_runs_show_progress_with_an_eta_unless_quiet(tmp_path):
    scenario = tmp_path / "tiny.toml"
    scenario.write_text('name = "tiny"\nduration_s = 0.5\n')
    res = _skyfix("sim", str(scenario), "--out", str(tmp_path / "tiny"))
    assert res.returncode == 0, res.stderr
    assert ETA.search(res.stderr) and "rendering" in ETA.search(res.stderr).group(0)
    res = _skyfix("process", str(tmp_path / "tiny"), "--out", str(tmp_path / "o"))
    assert res.returncode == 0 and "tracking" in ETA.search(res.stderr).group(0), res.stderr
    quiet = [
        _skyfix("sim", str(scenario), "--out", str(tmp_path / "tiny"), "--quiet"),
        _skyfix("process", str(tmp_path / "tiny"), "--out", str(tmp_path / "o"), "--quiet"),
    ]
    assert all(r.returncode == 0 and "ETA" not in r.stderr for r in quiet)


@pytest.mark.parametrize("argv", [["evaluate", str(SESSION), "--use-track", "--quiet"]])
def test_evaluate_writes_the_same_plots(tmp_path, argv):
    assert main([*argv, "--out", str(tmp_path)]) == 0
    _pngs(tmp_path / "occlusion")


def test_every_status_word_has_a_cause_colour():
    from groundstation.offline.plots import cause
    from localizer.status import STATUSES

    assert [w for w in STATUSES if w != "ok" and cause(w) == "other"] == []

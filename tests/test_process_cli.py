"""`skyfix process --use-track` on real session files: good output, and every bad-input case.

Each bad case starts from a copy of a bundled scenario, breaks one thing, and
checks: exit code 2, one line on stderr naming the file and the offending value,
and no positions.csv left behind.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from test_uncertainty_h_acc import share_within

from groundstation.cli import main
from groundstation.session.positions import read_positions_csv
from groundstation.session.read import SessionError
from localizer.geodesy import horizontal_error_m

BUNDLED = Path(__file__).resolve().parents[1] / "sim_fixtures" / "bundled"


def _bundled(name: str) -> Path:
    path = BUNDLED / name
    if not (path / "session.toml").is_file():
        pytest.fail(f"bundled fixture {path} missing: regenerate with sim_fixtures/bundle.py")
    return path


@pytest.fixture
def session(tmp_path) -> Path:
    dst = tmp_path / "session"
    shutil.copytree(
        _bundled("oblique_2m"), dst, ignore=shutil.ignore_patterns("video.*", "video_frames.csv")
    )
    return dst


def _run(capsys, *argv) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def _edit(path: Path, pattern: str, repl: str) -> None:
    text = path.read_text()
    new, n = re.subn(pattern, repl, text, flags=re.MULTILINE)
    assert n == 1, f"pattern {pattern!r} not found once in {path}"
    path.write_text(new)


def test_positions_match_truth_and_spec_columns(session, tmp_path, capsys):
    out = tmp_path / "out"
    code, _, _ = _run(capsys, "process", str(session), "--out", str(out), "--use-track")
    assert code == 0
    header = (out / "positions.csv").read_text().splitlines()[0].split(",")
    assert header[:6] == ["t", "lat", "lon", "depth_m", "h_acc_m", "status"]
    pos = read_positions_csv(out / "positions.csv")
    track = np.loadtxt(session / "track.csv", delimiter=",", skiprows=1, ndmin=2)
    assert len(pos.t_unix) == len(track)
    ok = pos.status == "ok"
    assert ok.mean() > 0.9
    assert np.all(np.isnan(pos.lat[~ok]))
    truth = np.genfromtxt(session / "truth.csv", delimiter=",", names=True)
    lat = np.interp(pos.t_unix[ok], truth["t"], truth["lat"])
    lon = np.interp(pos.t_unix[ok], truth["t"], truth["lon"])
    err = horizontal_error_m(pos.lat[ok], pos.lon[ok], lat, lon)
    assert err.mean() < 0.005, f"geometry-only MAE {err.mean():.4f} m"


def test_straight_ray_is_worse_off_nadir(session, tmp_path, capsys):
    """The paper's method (--no-refraction) misses an oblique 2 m deep target by decimetres."""
    for flag, name in (([], "bent"), (["--no-refraction"], "straight")):
        assert (
            _run(
                capsys, "process", str(session), "--out", str(tmp_path / name), "--use-track", *flag
            )[0]
            == 0
        )
    bent = read_positions_csv(tmp_path / "bent" / "positions.csv")
    straight = read_positions_csv(tmp_path / "straight" / "positions.csv")
    ok = (bent.status == "ok") & (straight.status == "ok")
    shift = horizontal_error_m(bent.lat[ok], bent.lon[ok], straight.lat[ok], straight.lon[ok])
    assert np.median(shift) > 0.15


def test_real_console_script(session, tmp_path):
    """The installed entry point, as a user runs it."""
    exe = Path(sys.executable).with_name("skyfix")
    res = subprocess.run(
        [str(exe), "process", str(session), "--out", str(tmp_path / "o"), "--use-track"],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert res.returncode == 0, res.stderr
    assert "positions.csv" in res.stdout


BAD_CASES = {
    "not a directory": (lambda s: shutil.rmtree(s), "not a session directory"),
    "no session.toml": (lambda s: (s / "session.toml").unlink(), "session.toml: missing"),
    "malformed TOML": (
        lambda s: _edit(s / "session.toml", r"^version = 1$", "version = = 1"),
        "malformed TOML",
    ),
    "wrong version": (
        lambda s: _edit(s / "session.toml", r"^version = 1$", "version = 7"),
        "version = 7",
    ),
    "NaN focal length": (
        lambda s: _edit(s / "session.toml", r"^fx = .*$", "fx = nan"),
        "camera.fx = nan",
    ),
    "negative refractive index": (
        lambda s: _edit(s / "session.toml", r"^refractive_index = .*$", "refractive_index = -1.34"),
        "water.refractive_index = -1.34",
    ),
    "unknown attitude source": (
        lambda s: _edit(
            s / "session.toml", r"^attitude_source = .*$", 'attitude_source = "compass"'
        ),
        "mount.attitude_source = 'compass'",
    ),
    "no uav.tlog": (lambda s: (s / "uav.tlog").unlink(), "uav.tlog: missing"),
    "garbage uav.tlog": (
        lambda s: (s / "uav.tlog").write_bytes(np.random.default_rng(1).bytes(20000)),
        "no ATTITUDE message",
    ),
    "no depth.jsonl": (lambda s: (s / "depth.jsonl").unlink(), "depth.jsonl: missing"),
    "garbage depth line": (
        lambda s: _insert_line(s / "depth.jsonl", 3, "{not json"),
        "depth.jsonl:4: expected",
    ),
    "NaN depth": (
        lambda s: _insert_line(s / "depth.jsonl", 3, '{"t": 1.0, "depth_m": NaN}'),
        "non-finite",
    ),
    "depth out of range": (
        lambda s: _replace_depth(s / "depth.jsonl", 2, 99999.0),
        "depth_m = 99999.0 out of range",
    ),
    "non-numeric pixel": (
        lambda s: _replace_track_cell(s / "track.csv", 2, "abc"),
        "u = 'abc': not a number",
    ),
    "ray never reaches the water": (lambda s: _camera_looks_up(s / "session.toml"), "no_water"),
}


def _camera_looks_up(path: Path) -> None:
    """A rigid camera pitched 45° above the horizon: no ray can reach the water."""
    text = re.sub(r"^fixed_rpy_deg = .*\n", "", path.read_text(), flags=re.MULTILINE)
    path.write_text(text)
    _edit(
        path,
        r"^attitude_source = .*$",
        'attitude_source = "fixed"\nfixed_rpy_deg = [0.0, 45.0, 0.0]',
    )


def _insert_line(path: Path, index: int, line: str) -> None:
    lines = path.read_text().splitlines()
    lines.insert(index, line)
    path.write_text("\n".join(lines) + "\n")


def _replace_depth(path: Path, index: int, depth: float) -> None:
    lines = path.read_text().splitlines()
    lines[index] = re.sub(r'"depth_m":\s*[-0-9.eE]+', f'"depth_m": {depth}', lines[index])
    path.write_text("\n".join(lines) + "\n")


def _replace_track_cell(path: Path, row: int, value: str) -> None:
    lines = path.read_text().splitlines()
    cells = lines[row].split(",")
    cells[1] = value
    lines[row] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize("case", sorted(BAD_CASES))
def test_bad_session_is_one_clear_line_and_no_output(case, session, tmp_path, capsys):
    breaker, expected = BAD_CASES[case]
    breaker(session)
    out = tmp_path / "out"
    code, _, err = _run(capsys, "process", str(session), "--out", str(out), "--use-track")
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert expected in lines[0]
    assert not (out / "positions.csv").exists()
    assert not out.exists() or not list(out.glob("*.partial"))


def test_truncated_last_depth_line_is_a_warning(session, tmp_path, capsys):
    """A log cut mid-write (power loss) loses one sample, not the session."""
    with open(session / "depth.jsonl", "a") as f:
        f.write('{"t": 17')
    code, _, err = _run(
        capsys, "process", str(session), "--out", str(tmp_path / "o"), "--use-track"
    )
    assert code == 0
    assert "truncated last line" in err


def test_positions_csv_round_trip_and_other_tools_files(session, tmp_path, capsys):
    """skyfix's extra columns come back as they went out; a file with only the spec's six columns reads too."""
    out = tmp_path / "out"
    assert _run(capsys, "process", str(session), "--out", str(out), "--use-track")[0] == 0
    header = (out / "positions.csv").read_text().splitlines()[0].split(",")
    assert header[6:] == [
        "alt_amsl_m",
        "v_acc_m",
        "u",
        "v",
        "north_m",
        "east_m",
        "t_gnss",
        "alt_ellipsoid_m",
        "sigma_n_m",
        "sigma_e_m",
        "cov_ne_m2",
        "height_m",
        "sigma_height_m",
        "sigma_depth_m",
        "sigma_time_s",
        "height_source",
        "depth_source",
        "time_source",
        "sigma_pixel_px",
    ]
    pos = read_positions_csv(out / "positions.csv")
    ok = pos.status == "ok"
    # pixels from track.csv have no tracker of their own: the calibration's [uncertainty] pixel_px
    assert np.all(pos.sigma_pixel_px[ok] == 2.0)
    # words come back as words; the bundled take-off sessions' GPS_RAW_INT altitudes follow the barometer's drift
    assert set(pos.height_source[ok]) == {"baro+gnss"} and all(pos.time_source[ok])
    # the bundled sessions carry GPS_RAW_INT with alt_ellipsoid: 40 m of geoid separation (scenario default)
    assert np.allclose(pos.alt_ellipsoid_m[ok] - pos.alt_amsl_m[ok], 40.0, atol=2e-4)
    # h_acc: 2·h_acc holds 95 % of a normal error of the row's covariance (as written: 4 decimals)
    for sn, se, c, h in zip(
        pos.sigma_n_m[ok], pos.sigma_e_m[ok], pos.cov_ne_m2[ok], pos.h_acc_m[ok]
    ):
        assert share_within(2 * h, [[sn**2, c], [c, se**2]]) == pytest.approx(0.95, abs=3e-3)
    spec_only = tmp_path / "spec_only.csv"
    spec_only.write_text(
        "t,lat,lon,depth_m,h_acc_m,status\n1.5,63.4,10.4,1.0,0.2,ok\n2.5,,,1.0,,lost\n"
    )
    other = read_positions_csv(spec_only)
    assert (
        list(other.status) == ["ok", "lost"]
        and other.lat[0] == 63.4
        and np.isnan(other.alt_ellipsoid_m).all()
    )
    spec_only.write_text("t,lat,lon,depth_m,h_acc_m,status\n1.5,63.4,north,1.0,0.2,ok\n")
    with pytest.raises(SessionError, match=r"spec_only.csv:2: lon = 'north': not a number"):
        read_positions_csv(spec_only)

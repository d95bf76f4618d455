"""Tracking a generated session's video end to end, and what damaged sessions do to it."""

import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from groundstation.cli import main as skyfix
from groundstation.offline.process import process_session
from groundstation.offline.track import track_session
from groundstation.session.read import SessionError, load_session, read_table
from localizer.geodesy import horizontal_error_m
from sim_fixtures.generate import generate
from sim_fixtures.scenario import load_scenario, with_overrides

SCENARIOS = Path(__file__).resolve().parents[1] / "sim_fixtures" / "scenarios"
HIDDEN_S = (1.2, 2.0)

pytestmark = pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="needs the ffmpeg CLI")


@pytest.fixture(scope="module")
def session_dir(tmp_path_factory):
    """3 s of the occlusion scenario (oblique, glint), hidden from 1.2 s to 2.0 s."""
    sc = with_overrides(
        load_scenario(SCENARIOS / "occlusion.toml"), duration_s=3.0, occlusions=(HIDDEN_S,)
    )
    out = tmp_path_factory.mktemp("sessions") / "occl"
    generate(sc, out)
    return out


def _copy(session_dir, tmp_path):
    dst = tmp_path / "s"
    shutil.copytree(session_dir, dst)
    return dst


def _hidden(t):
    tau = t - t[0]
    return (tau >= HIDDEN_S[0]) & (tau < HIDDEN_S[1])


def test_tracks_the_uuv_loses_it_while_hidden_and_finds_it_again(session_dir):
    session = load_session(session_dir)
    tracked = track_session(session)
    hidden = _hidden(tracked.t)
    ok = tracked.status == "ok"
    assert not np.any(ok & hidden)
    assert set(tracked.status[hidden]) == {"lost"}
    assert np.all(np.isnan(tracked.u[~ok]))
    visible = ~hidden
    assert ok[visible].mean() > 0.95  # a few frames to re-acquire after the occlusion
    after = np.flatnonzero(~hidden & (np.arange(len(ok)) > np.flatnonzero(hidden)[-1]))
    assert ok[after[5:]].all()
    # pixels against the exact pixel of the truth point
    tr = session.track
    u_true = np.interp(tracked.t[ok], tr["t"], tr["u"])
    v_true = np.interp(tracked.t[ok], tr["t"], tr["v"])
    err = np.hypot(tracked.u[ok] - u_true, tracked.v[ok] - v_true)
    assert err.mean() < 1.0 and err.max() < 3.0


def test_process_with_the_tracker_gives_fixes_near_truth_and_says_why_not(session_dir):
    session = load_session(session_dir)
    fixes = process_session(session, use_track=False, tracker="default")
    ok = fixes.status == "ok"
    assert set(fixes.status[_hidden(fixes.t_unix)]) == {"lost"}
    tr = session.truth
    lat_t, lon_t = (
        np.interp(fixes.t_unix, tr["t"], tr["lat"]),
        np.interp(fixes.t_unix, tr["t"], tr["lon"]),
    )
    err = horizontal_error_m(fixes.lat[ok], fixes.lon[ok], lat_t[ok], lon_t[ok])
    assert err.mean() < 0.05


def test_cli_process_with_tracker_writes_positions(session_dir, tmp_path, capsys):
    assert (
        skyfix(
            ["process", str(session_dir), "--out", str(tmp_path), "--tracker", "default", "--quiet"]
        )
        == 0
    )
    lines = (tmp_path / "positions.csv").read_text().splitlines()
    assert len(lines) == 1 + 90
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:
        skyfix(["process", str(session_dir), "--out", str(tmp_path), "--tracker", "nope"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "invalid choice: 'nope'" in err and "mil" in err


def test_truncated_video_gives_no_video_status_for_the_missing_frames(session_dir, tmp_path):
    s = _copy(session_dir, tmp_path)
    data = (s / "video.mp4").read_bytes()
    (s / "video.mp4").write_bytes(data[: len(data) // 2])
    session = load_session(s)
    tracked = track_session(session)
    n = len(tracked.t)
    decoded = tracked.status != "no_video"
    assert 10 < decoded.sum() < n
    assert np.all(tracked.status[-10:] == "no_video")
    assert any("not in the video" in w for w in tracked.warnings)
    # frames that did decode were tracked at their own time: nothing shifted
    ok = tracked.status == "ok"
    u_true = np.interp(tracked.t[ok], session.track["t"], session.track["u"])
    assert ok.sum() > 10 and np.all(np.abs(tracked.u[ok] - u_true) < 3.0)


def test_video_of_another_size_is_refused(session_dir, tmp_path):
    s = _copy(session_dir, tmp_path)
    subprocess.run(
        [
            "ffmpeg",
            "-v",
            "error",
            "-y",
            "-i",
            str(session_dir / "video.mp4"),
            "-vf",
            "scale=320:180",
            "-c:v",
            "libx264",
            str(s / "video.mp4"),
        ],
        check=True,
    )
    with pytest.raises(
        SessionError, match="320x180 pixels differs from the calibration's camera 640x360"
    ):
        track_session(load_session(s))


def test_missing_video_file_is_named(session_dir, tmp_path):
    session = load_session(_copy(session_dir, tmp_path))
    session.video_path.unlink()
    with pytest.raises(SessionError, match=r"video\.mp4: missing"):
        track_session(session)


def test_init_time_matching_no_frame_is_refused(session_dir, tmp_path):
    s = _copy(session_dir, tmp_path)
    toml = (s / "session.toml").read_text()
    (s / "session.toml").write_text(re.sub(r"init_t = .*", "init_t = 1000.0", toml))
    with pytest.raises(SessionError, match="tracker.init_t = .* matches no frame"):
        track_session(load_session(s))


def test_mil_backend_runs_on_the_session(session_dir):
    """MIL has no loss signal: it follows the water where the UUV is hidden as if it were there. The lock's colour
    check (localizer/tracking/colour.py) gives those frames no fix; the visible ones stay ok."""
    tracked = track_session(load_session(session_dir), tracker_name="mil")
    truth = read_table(session_dir / "track.csv", ("t", "u", "v"), allow_empty=("u", "v"))
    visible, ok = np.isfinite(truth["u"]), tracked.status == "ok"
    assert 0 < (~visible).sum() and ok[visible].mean() > 0.9
    assert not ok[~visible].any(), ok.astype(int)

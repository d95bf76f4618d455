"""Generation end to end: a session the project reads, deterministic from the seed."""

import subprocess
import sys

import numpy as np
import pytest

from groundstation.session.read import load_session
from localizer.calibration import ConfigError
from sim_fixtures.generate import generate
from sim_fixtures.scenario import scenario_from_dict

TINY = {
    "name": "tiny",
    "seed": 5,
    "duration_s": 1.0,
    "fps": 10.0,
    "camera": {"width": 160, "height": 96},
    "mount": {"pitch_deg": -70.0},
    "uav": {"height_m": 6.0},
    "occlusions": [[0.5, 0.7]],
}


def files(path):
    return {p.name: p.read_bytes() for p in sorted(path.iterdir())}


def test_same_seed_same_session_other_seed_other_session(tmp_path):
    a = generate(scenario_from_dict(TINY), tmp_path / "a").session
    b = generate(scenario_from_dict(TINY), tmp_path / "b").session
    c = generate(scenario_from_dict({**TINY, "seed": 6}), tmp_path / "c").session
    fa, fb, fc = files(a), files(b), files(c)
    assert set(fa) == {
        "session.toml",
        "uav.tlog",
        "depth.jsonl",
        "video.mp4",
        "video_frames.csv",
        "track.csv",
        "truth.csv",
    }
    assert fa == fb
    assert fa["uav.tlog"] != fc["uav.tlog"] and fa["video.mp4"] != fc["video.mp4"]


def test_generated_session_loads_and_video_matches_frames(tmp_path):
    session = load_session(generate(scenario_from_dict(TINY), tmp_path / "s").session)
    assert not session.warnings
    assert len(session.frames["t"]) == 10 and np.allclose(np.diff(session.frames["t"]), 0.1)
    assert np.array_equal(np.isnan(session.track["u"]), [False] * 5 + [True] * 2 + [False] * 3)
    x, y, w, h = session.calibration.init_bbox
    assert (
        abs(x + w / 2 - session.track["u"][0]) < w / 2
        and abs(y + h / 2 - session.track["v"][0]) < h / 2
    )
    probe = subprocess.run(
        [
            "ffprobe",
            "-v",
            "error",
            "-count_frames",
            "-select_streams",
            "v:0",
            "-show_entries",
            "stream=nb_read_frames,width,height,codec_name,pix_fmt",
            "-of",
            "csv=p=0",
            str(session.video_path),
        ],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    assert probe == "h264,160,96,yuv420p,10"


def test_cli_writes_session(tmp_path):
    scenario = tmp_path / "tiny.toml"
    scenario.write_text(
        'name = "tiny"\nduration_s = 0.5\nfps = 10.0\n[camera]\nwidth = 96\nheight = 64\n'
    )
    code = (
        "import argparse, sys; from sim_fixtures import cli; p = argparse.ArgumentParser(); "
        "cli.register(p.add_subparsers(), 'sim'); a = p.parse_args(sys.argv[1:]); sys.exit(a.func(a))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code, "sim", str(scenario), "--out", str(tmp_path / "s")],
        capture_output=True,
        text=True,
        check=False,
    )
    assert out.returncode == 0, out.stderr
    assert "tiny: 5 frames 96x64" in out.stdout
    assert (tmp_path / "s" / "scenario.toml").read_text() == scenario.read_text()
    load_session(tmp_path / "s")


def test_refuses_to_overwrite_a_recording(tmp_path):
    rec = tmp_path / "flight"
    rec.mkdir()
    (rec / "session.toml").write_text("version = 1\n")
    (rec / "uav.tlog").write_bytes(b"precious")
    with pytest.raises(ConfigError, match="refusing to overwrite"):
        generate(scenario_from_dict(TINY), rec)
    assert (rec / "uav.tlog").read_bytes() == b"precious"


def test_frames_rendered_apart_are_the_frames_rendered_in_turn():
    """Two rendering processes (each with a copy of the renderer, each frame given its noise offset) make the same
    frames and boxes as one renderer in turn: the encoder is given the same frames, track.csv the same boxes."""
    from sim_fixtures import generate as gen

    sc = scenario_from_dict(TINY)
    camera = gen.camera_of(sc)
    truth = gen.frame_truth(sc, gen.Motion(sc), camera)
    renderer = gen.Renderer(sc, camera)
    # copies of the renderer, its noise not drawn yet
    apart = list(gen._frames(renderer, sc, truth, workers=2))
    in_turn = list(gen._frames(renderer, sc, truth, workers=1))
    assert len(in_turn) == len(apart) == 10
    for (img_a, boxes_a), (img_b, boxes_b) in zip(in_turn, apart, strict=True):
        assert np.array_equal(img_a, img_b) and boxes_a == boxes_b
    assert len({img.tobytes() for img, _ in in_turn}) == 10  # the noise differs frame to frame


def test_init_bbox_is_where_the_uuv_is_first_wholly_in_view(tmp_path):
    """A UUV entering the view across the top edge: its first box is drawn once the vehicle is wholly in view, clear
    of the edge (a box cut by the edge would hold part of it, and skyfix refuses one on the edge)."""
    enters = {
        **TINY,
        "duration_s": 1.5,
        "mount": {"pitch_deg": -90.0},
        "uav": {"height_m": 6.0, "standoff": "given", "yaw_deg": 0.0, "yaw_swing_deg": 0.0},
        "uuv": {"path": "cruise", "north_m": 2.6, "speed_mps": 1.2, "course_deg": 180.0},
        "occlusions": [],
    }
    session = load_session(generate(scenario_from_dict(enters), tmp_path / "s").session)
    t, v = session.frames["t"], session.track["v"]
    seen = np.flatnonzero(np.isfinite(v))
    assert seen[0] > 0 and v[seen[0]] < 3.0  # seen first at the top edge, cut by it
    x, y, w, h = session.calibration.init_bbox
    first = int(np.searchsorted(t, session.calibration.init_t))
    assert first > seen[0] + 1  # not while it is cut
    assert x >= 1 and y >= 1 and x + w <= 159 and y + h <= 95
    assert y <= v[first] <= y + h and x <= session.track["u"][first] <= x + w

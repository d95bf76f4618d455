"""A UUV that dives out of sight in turbid water and comes back up: marked hidden, lost, re-acquired.

5.5 s of the ``dive`` scenario compressed: murkier water (so a 3 m dive is enough
to fade the vehicle below the sensor noise) and a quick dive from 1 m to 4 m and
back. The generator must mark the frames where the UUV cannot be seen (empty
pixels in track.csv) and the video must really not show it there; the default
tracker must say "lost" there instead of fixing on the water, and find the UUV
again on its own when it comes back up.
"""

import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from groundstation.offline.process import process_session
from groundstation.session.read import load_session
from groundstation.video.file import open_video
from localizer.geodesy import horizontal_error_m
from sim_fixtures.generate import camera_of, frame_truth, generate
from sim_fixtures.motion import Motion
from sim_fixtures.scenario import load_scenario, with_overrides

SCENARIOS = Path(__file__).resolve().parents[1] / "sim_fixtures" / "scenarios"
PROFILE = ((0.8, 1.0), (2.2, 4.0), (3.0, 4.0), (4.4, 1.0))  # (t_s, depth_m)
REACQUIRE_FRAMES = 10  # the track resumes within this many frames of the UUV being visible again

pytestmark = pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="needs the ffmpeg CLI")


@pytest.fixture(scope="module")
def dive(tmp_path_factory):
    sc = with_overrides(
        load_scenario(SCENARIOS / "dive.toml"),
        duration_s=5.5,
        site={"attenuation_bgr_per_m": (1.3, 1.2, 2.0), "floor_depth_m": 8.0},
        uuv={"depth_profile": PROFILE},
    )
    out = tmp_path_factory.mktemp("sessions") / "dive"
    generate(sc, out)
    session = load_session(out)
    visible = np.isfinite(session.track["u"])
    depth = np.interp(session.track["t"], session.truth["t"], session.truth["depth_m"])
    return sc, session, visible, depth


def _runs(mask):
    """(start, end) index pairs of the runs of True in a boolean array."""
    edges = np.flatnonzero(np.diff(np.r_[0, mask.astype(int), 0]))
    return list(zip(edges[::2], edges[1::2]))


def test_generator_marks_the_deep_uuv_hidden_and_the_video_does_not_show_it(dive):
    sc, session, visible, depth = dive
    ((a, b),) = _runs(~visible)  # one hidden stretch, in the middle of the dive
    assert 0 < a and b < len(visible) and b - a > 30
    assert depth[a:b].min() > 2.0 and depth[visible].min() < 1.05
    assert np.all(np.diff(depth[:a]) >= -1e-9)  # the UUV went out of sight on the way down...
    assert np.all(np.diff(depth[b - 1 :]) <= 1e-9)  # ... and came back on the way up
    assert len(session.truth["t"]) == len(visible)
    truth = frame_truth(sc, Motion(sc), camera_of(sc))  # the reference point's pixel in every frame
    assert np.allclose(truth.u[visible], session.track["u"][visible], atol=1e-3)
    spread = []  # grey-level spread of a square a little larger than the vehicle, on its reference point
    with open_video(session.video_path, expected_size=(sc.camera.width, sc.camera.height)) as video:
        for frame in video:
            i = frame.index
            grey = cv2.cvtColor(frame.image, cv2.COLOR_BGR2GRAY).astype(float)
            x, y = round(truth.u[i]), round(truth.v[i])
            spread.append(grey[y - 15 : y + 16, x - 15 : x + 16].std())
    spread = np.array(spread)
    deep = ~visible & (depth > depth[a] + 0.5)
    assert deep.sum() > 20
    # where it is deep and hidden, the square is as flat as the water (below the sensor noise)...
    assert spread[deep].max() < sc.render.noise_sigma
    # ... and near the surface the vehicle stands out by far more
    assert spread[depth < 1.05].min() > 4 * spread[deep].max()


def test_tracker_is_lost_while_the_uuv_is_deep_and_finds_it_again(dive):
    _, session, visible, depth = dive
    fixes = process_session(session, use_track=False, tracker="default")
    ok = fixes.status == "ok"
    lat_t = np.interp(fixes.t_unix, session.truth["t"], session.truth["lat"])
    lon_t = np.interp(fixes.t_unix, session.truth["t"], session.truth["lon"])
    err = np.full(len(ok), np.nan)
    err[ok] = horizontal_error_m(fixes.lat[ok], fixes.lon[ok], lat_t[ok], lon_t[ok])
    ((a, b),) = _runs(~visible)
    # hidden: no fix more than 1 m off; none at all once the UUV is well below sight
    assert not np.any(err[~visible] > 1.0)
    assert not np.any(ok[~visible & (depth > depth[a] + 0.75)])
    assert (~ok[a:b]).mean() > 0.8
    # a lost track gives no position
    assert set(fixes.status[~ok]) == {"lost"}
    assert np.all(np.isnan(fixes.lat[~ok]) & np.isnan(fixes.lon[~ok]))
    # re-acquired on its own soon after it is visible again, and kept from then on
    back = b + np.flatnonzero(ok[b:])[0]
    assert back - b <= REACQUIRE_FRAMES
    assert ok[back:].all()
    assert ok[:a].all()
    # accurate where visible
    seen = ok & visible
    assert seen.sum() >= 0.95 * visible.sum() - REACQUIRE_FRAMES
    assert err[seen].mean() < 0.03 and err[seen].max() < 0.15

"""The tracker through wind waves (issue 28): the UUV's image wobbles, breaks up and flickers, and is still the UUV.

A short generated nadir hover (640x360, 3 s, the UUV ~35 px) is seen through :mod:`wave_proxy`'s waves (2 px RMS of
refraction's displacement, caustic flicker, 1 Mbit/s x264 without B-frames, as 4 Mbit/s at 720p). The tracker before
issue 28 located it on 4 of 90 frames (each frame's score fell below the level of the first frames, and no
re-acquisition reached 0.7).
"""

from __future__ import annotations

import math
import shutil

import numpy as np
import pytest
from wave_proxy import through_waves

from groundstation.session.read import load_session
from groundstation.video.file import open_video
from localizer.pose import camera_pose
from localizer.tracking.session import TrackingSession
from sim_fixtures.generate import generate
from sim_fixtures.scenario import scenario_from_dict

pytestmark = pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="needs the ffmpeg CLI")

HOVER = {
    "name": "waves_proxy_hover",
    "description": "nadir hover for the wave proxy",
    "seed": 21,
    "duration_s": 3.0,
    "mount": {"attitude_source": "gimbal_device", "gimbal_frame": "earth", "pitch_deg": -90.0},
    "uav": {"height_m": 8.0},
    "uuv": {"depth_m": 1.5},
}


def _track(path):
    """(ok per frame, the UUV visible per frame, pixel error per ok frame) tracking from the session's first box, and
    what :func:`_back` needs: the tracking session after the last frame, the frames, their poses, the true pixels."""
    session = load_session(path)
    cal, t = session.calibration, session.frames["t"]
    pose = camera_pose(cal, session.telemetry, t)
    with open_video(session.video_path) as video:
        frames = [f.image for f in video]
    u, v = (np.interp(t, session.track["t"], session.track[c]) for c in ("u", "v"))  # NaN: hidden
    ts = TrackingSession(cal)
    results = [ts.select(frames[0], pose, 0, box=cal.init_bbox)]
    results += [ts.step(frames[i], pose, i) for i in range(1, len(frames))]
    ok = np.array([r.ok for r in results])
    # NaN: hidden
    err = np.array([math.hypot(r.u - u[i], r.v - v[i]) for i, r in enumerate(results) if r.ok])
    return ok, np.isfinite(u), err, (ts, frames, pose, u, v)


def _back(ts, frames, pose, u, v):
    """(the sea state the tracker read, ok per frame, pixel error per ok frame) of a tracker started from the last
    frame's sighting by :meth:`TrackingSession.back_from` and stepped back to the first frame."""
    last = len(frames) - 1
    back = ts.back_from(frames[last], pose, last)
    waves = back.target.waves
    results = {i: back.step(frames[i], pose, i) for i in range(last - 1, -1, -1)}
    ok = np.array([results[i].ok for i in range(last)])
    err = np.array([math.hypot(r.u - u[i], r.v - v[i]) for i, r in results.items() if r.ok])
    return waves, ok, err


@pytest.mark.parametrize("occluded", [False, True], ids=["visible", "hidden_from_1.8s"])
def test_the_uuv_is_located_through_waves_and_lost_when_gone(tmp_path, occluded):
    scenario = dict(HOVER, occlusions=[[1.8, 3.0]] if occluded else [])
    generate(scenario_from_dict(scenario), tmp_path / "flat")
    ok, visible, err, tracked = _track(
        through_waves(tmp_path / "flat", tmp_path / "waves", shift_px=2.0, flicker=0.5, kbps=1000)
    )
    assert ok[visible].mean() >= 0.95, ok.astype(int)
    if not occluded:
        # offline, back in time from the last frame (groundstation.offline.track's both ways): the copy reads the
        # waves as the forward tracker does (a tracker started afresh on the frame's box reads a still surface)
        waves, back_ok, back_err = _back(*tracked)
        assert waves == tracked[0].target.waves >= 0.5
        assert back_ok.mean() >= 0.95, back_ok.astype(int)
        assert np.median(back_err) < 3.0 and back_err.max() < 10.0
    # the waves move its image from the true pixel by 2 px RMS per axis (2.8 px in all), at times 3 times that
    if (
        occluded
    ):  # gone: lost (the water where it was still passes for it in a few frames: 2 of 36 here)
        assert ok[~visible].mean() <= 0.1, ok.astype(int)
    err = err[np.isfinite(err)]
    assert np.median(err) < 3.0 and err.max() < 10.0

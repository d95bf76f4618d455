"""A tracking session on rendered video: select → track → lose (occlusion) → re-acquire → release, clicks,
and acquisition from the UUV's own position estimate without any selection.

The bundled sessions' videos are rendered by the simulator with its own geometry; ``track.csv`` holds the
true pixel of the UUV's reference point in every frame (empty while it cannot be seen), ``truth.csv`` its
true position. The UUV's "own estimate" is the truth moved a few metres (pymap3d, not the localizer).
"""

from __future__ import annotations

import math
import re
import shutil
from pathlib import Path

import numpy as np
import pymap3d
import pytest

from groundstation.session.read import load_session
from groundstation.video.file import open_video
from localizer.pose import camera_pose, take
from localizer.tracking import TrackResult
from localizer.tracking.predict import window
from localizer.tracking.session import (
    STOOD_OUT_WITHIN_S,
    Prior,
    SelectionError,
    TrackingSession,
)
from localizer.tracking.target import TargetParams, TargetState

BUNDLED = Path(__file__).resolve().parents[1] / "sim_fixtures" / "bundled"
HIDDEN = (75, 120)  # occlusion: frames in which the UUV is hidden (2.5 s to 4.0 s at 30 fps)
CONFIRM = TargetParams().confirm_frames

pytestmark = pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="needs the ffmpeg CLI")


class Clip:
    """A bundled session's decoded frames, poses and true pixels."""

    def __init__(self, name: str):
        self.session = load_session(BUNDLED / name)
        self.cal = self.session.calibration
        self.t = self.session.frames["t"]
        self.pose = camera_pose(self.cal, self.session.telemetry, self.t)
        with open_video(self.session.video_path) as video:
            self.frames = [f.image for f in video]
        assert len(self.frames) == len(self.t)
        tr = self.session.track
        self.u = np.interp(self.t, tr["t"], tr["u"])  # NaN where the UUV cannot be seen
        self.v = np.interp(self.t, tr["t"], tr["v"])

    def truth_moved(self, i: int, north_m: float, east_m: float) -> tuple[float, float]:
        tr = self.session.truth
        lat, lon = (
            np.interp(self.t[i], tr["t"], tr["lat"]),
            np.interp(self.t[i], tr["t"], tr["lon"]),
        )
        lat2, lon2, _ = pymap3d.enu2geodetic(east_m, north_m, 0.0, lat, lon, 0.0)
        return float(lat2), float(lon2)

    def error_px(self, i: int, result) -> float:
        return math.hypot(result.u - self.u[i], result.v - self.v[i])


@pytest.fixture(scope="module")
def occlusion():
    return Clip("occlusion")


def _run(clip: Clip, ts: TrackingSession, frames, prior: Prior | None = None) -> dict:
    return {i: ts.step(clip.frames[i], clip.pose, i, prior) for i in frames}


def test_select_track_lose_reacquire_release_and_click(occlusion):
    clip = occlusion
    ts = TrackingSession(clip.cal)
    assert ts.state is TargetState.AWAITING_TARGET
    # no selection, no prior
    assert ts.step(clip.frames[0], clip.pose, 0).status == "awaiting_target"

    # the simulator's own box around the whole vehicle in frame 0, selected on frame 1's successor frame 0
    first = ts.select(clip.frames[0], clip.pose, 0, box=clip.cal.init_bbox)
    assert (
        first.ok
        and first.confidence == 1.0
        and ts.state is TargetState.TRACKING
        and ts.origin == "box"
    )
    assert clip.error_px(0, first) < 1.5  # the box's centre moved to the top face's
    results = _run(clip, ts, range(1, 170))
    before = [i for i in range(1, HIDDEN[0])]
    assert all(results[i].ok for i in before)
    assert max(clip.error_px(i, results[i]) for i in before) < 2.0
    hidden = range(HIDDEN[0], HIDDEN[1])
    assert {results[i].status for i in hidden} == {"lost"}
    back = next(i for i in range(HIDDEN[1], 170) if results[i].ok)
    assert back - HIDDEN[1] <= 2 + CONFIRM, "re-acquired within a few frames of reappearing"
    assert all(results[i].ok for i in range(back, 170))
    assert max(clip.error_px(i, results[i]) for i in range(back, 170)) < 2.0
    assert ts.status()["state"] == "tracking" and ts.status()["seen_t"] == pytest.approx(
        clip.t[169], abs=1e-3
    )

    ts.release()
    released = _run(clip, ts, range(170, 180))
    assert {r.status for r in released.values()} == {
        "released"
    } and ts.state is TargetState.RELEASED
    ts.acquire()
    assert ts.step(clip.frames[180], clip.pose, 180).status == "awaiting_target"

    # a click a few pixels off the vehicle: the object there is outlined and tracked
    click = ts.select(
        clip.frames[181], clip.pose, 181, point=(clip.u[181] + 3.0, clip.v[181] - 2.0)
    )
    assert click.ok and ts.origin == "click" and clip.error_px(181, click) < 2.5
    results = _run(clip, ts, range(182, len(clip.t)))
    assert all(r.ok for r in results.values())
    assert np.mean([clip.error_px(i, r) for i, r in results.items()]) < 2.0


def _named(box) -> str:
    return re.escape("box [" + ", ".join(str(c) for c in box) + "]")


def test_bad_selections_are_refused_and_change_nothing(occlusion):
    clip = occlusion
    ts = TrackingSession(clip.cal)
    ts.select(clip.frames[0], clip.pose, 0, box=clip.cal.init_bbox)
    with pytest.raises(
        SelectionError, match=r"box \(630, 10, 40, 40\) does not lie inside the 640x360 frame"
    ):
        ts.select(clip.frames[1], clip.pose, 1, box=(630, 10, 40, 40))
    with pytest.raises(
        SelectionError, match=r"point \[40, 320\]: no vehicle-sized object stands out there"
    ):
        ts.select(clip.frames[1], clip.pose, 1, point=(40.0, 320.0))  # open water, far from the UUV
    with pytest.raises(SelectionError, match="either a box"):
        ts.select(clip.frames[1], clip.pose, 1)
    with pytest.raises(
        SelectionError, match=r"point \[-50, 20\]: bad_pixel: not a place on the water in the image"
    ):
        ts.select(clip.frames[1], clip.pose, 1, point=(-50.0, 20.0))
    with pytest.raises(SelectionError, match=r"point \[nan, 20.0\]: expected finite pixels"):
        ts.select(clip.frames[1], clip.pose, 1, point=(math.nan, 20.0))
    with pytest.raises(
        SelectionError, match=r"box \[40, 300, 33, 34\]: no vehicle-sized object stands out"
    ):
        # an operator's box on water
        ts.select(clip.frames[1], clip.pose, 1, box=(40, 300, 33, 34), verify=True)
    # a box on the frame's edge (first or last row or column): the UUV may be cut off there, and a template of part
    # of it would fix off its centre; refused however it is selected, a box one pixel in is not refused for it
    for edge in ((0, 100, 33, 34), (300, 0, 33, 34), (607, 100, 33, 34), (300, 326, 33, 34)):
        for how in ({}, {"verify": True, "keep_drawn": True, "steady": True}):
            with pytest.raises(SelectionError, match=rf"{_named(edge)} is on the frame's edge"):
                ts.select(clip.frames[1], clip.pose, 1, box=edge, **how)
    inside = TrackingSession(clip.cal).select(clip.frames[1], clip.pose, 1, box=(1, 1, 33, 34))
    assert inside.ok
    # the UUV cut off by the frame's left edge (the frame cropped 6 px left of its centre): a box around what shows
    # of it is outlined on the edge, and refused for that
    cut = np.ascontiguousarray(clip.frames[1][:, round(clip.u[1]) - 6 :])
    drawn = (1, round(clip.v[1]) - 17, 22, 34)
    with pytest.raises(SelectionError, match=r"box \[0, .* is on the frame's edge"):
        ts.select(cut, clip.pose, 1, box=drawn, verify=True)
    no_pose = camera_pose(clip.cal, clip.session.telemetry, [clip.t[-1] + 60.0])
    with pytest.raises(SelectionError, match=r"no camera pose at that frame \(stale_attitude\)"):
        ts.select(clip.frames[1], no_pose, 0, point=(clip.u[1], clip.v[1]))
    result = ts.step(clip.frames[1], clip.pose, 1)
    assert ts.state is TargetState.TRACKING and result.ok and clip.error_px(1, result) < 2.0
    # a box around the UUV passes the same check, and the matcher's window is reported with the next frame
    w, h = 33, 34
    ts.select(
        clip.frames[2],
        clip.pose,
        2,
        box=(clip.u[2] - (w - 1) / 2, clip.v[2] - (h - 1) / 2, w, h),
        verify=True,
    )
    assert ts.prediction is None
    result = ts.step(clip.frames[3], clip.pose, 3)
    x, y, ww, wh = window(ts.prediction)
    assert result.ok and x < clip.u[3] < x + ww and y < clip.v[3] < y + wh and ww < 200, (
        x,
        y,
        ww,
        wh,
    )


@pytest.mark.parametrize("bad", [30, 50])
def test_a_frame_without_a_pose_never_sends_the_search_back_to_an_old_anchor(occlusion, bad):
    """Frame ``bad`` has no camera pose (stale attitude): its sighting cannot be located. The next frame's
    prediction starts from the last sighting that could (one frame older), not from the anchor located at the
    selection, which the moving UUV left long ago."""
    clip = occlusion
    pose = take(clip.pose, slice(None))
    pose.status = pose.status.copy()
    pose.status[bad] = "stale_attitude"
    ts = TrackingSession(clip.cal)
    ts.select(clip.frames[0], pose, 0, box=clip.cal.init_bbox)
    results = _run(clip, ts, range(1, bad + 2))
    assert all(r.ok for r in results.values())
    p = ts.prediction
    assert math.hypot(p.u - clip.u[bad + 1], p.v - clip.v[bad + 1]) < 3.0
    assert clip.error_px(bad + 1, results[bad + 1]) < 2.0


@pytest.mark.parametrize(
    ("name", "north_m", "east_m"),
    [("nadir_hover", 2.5, -2.0), ("oblique_2m", -3.0, 1.5), ("vehicle_yaw", 1.0, 3.5)],
)
def test_acquires_near_the_uuvs_own_estimate_and_confirms_before_any_fix(name, north_m, east_m):
    clip = Clip(name)
    ts = TrackingSession(clip.cal)
    prior = Prior(*clip.truth_moved(0, north_m, east_m), sigma_m=3.0)
    results = _run(clip, ts, range(len(clip.t)), prior)
    first_ok = next(i for i, r in results.items() if r.ok)
    assert first_ok >= CONFIRM - 1, "confirmed over several frames before the first fix"
    assert first_ok <= 8
    assert {results[i].status for i in range(first_ok)} == {"awaiting_target"}
    # as from an operator's box: a short loss where the vehicle turns fast is allowed (vehicle_yaw reverses the
    # UUV's heading within 3 frames, ~1700°/s, where a BlueROV2 turns at most 200°/s: the tracker, which seeks it
    # only at headings it can have turned to, finds it again 7 frames later)
    assert np.mean([r.ok for i, r in results.items() if i >= first_ok]) > 0.96
    err = np.array([clip.error_px(i, r) for i, r in results.items() if r.ok])
    assert err.mean() < 3.0 and err.max() < 4.0
    assert ts.origin == "prior" and ts.state is TargetState.TRACKING


def test_no_acquisition_while_hidden_nor_far_from_the_estimate(occlusion):
    clip = occlusion
    # the estimate is right but the UUV is hidden: nothing until it shows, then acquired
    ts = TrackingSession(clip.cal)
    prior = Prior(*clip.truth_moved(HIDDEN[0] + 5, 1.0, 1.0), sigma_m=3.0)
    results = _run(clip, ts, range(HIDDEN[0] + 5, 160), prior)
    assert all(results[i].status == "awaiting_target" for i in range(HIDDEN[0] + 5, HIDDEN[1]))
    first_ok = next(i for i, r in results.items() if r.ok)
    assert HIDDEN[1] + CONFIRM - 1 <= first_ok <= HIDDEN[1] + 8
    assert max(clip.error_px(i, r) for i, r in results.items() if r.ok) < 3.5
    # an estimate 40 m off puts the search window away from the UUV: it is never taken
    ts = TrackingSession(clip.cal)
    far = Prior(*clip.truth_moved(0, 40.0, 0.0), sigma_m=3.0)
    results = _run(clip, ts, range(60), far)
    assert {r.status for r in results.values()} == {"awaiting_target"}


class _Scripted:
    """A stand-in for the session's target, through waves: each frame's result and the matcher's ``distinct`` as
    scripted (never a held match); it keeps the prediction each frame was looked for with."""

    held = None

    def __init__(self, script):
        self.script, self.state, self.waves, self.distinct, self.looked = (
            list(script),
            TargetState.TRACKING,
            0.8,
            math.nan,
            [],
        )

    def update(self, frame, prediction):
        self.looked.append(prediction)
        result, self.distinct = self.script.pop(0)
        return result


def test_through_waves_a_follow_that_does_not_stand_out_does_not_move_where_the_uuv_is_looked_for(
    occlusion,
):
    """A follow whose vehicle stands out of the seafloor less than ``STOOD_OUT_DISTINCT`` (slid onto a patch beside
    the UUV) leaves the next frames looking where the last sighting that stood out, moved by the camera, puts the
    UUV; the prediction itself (what the reported pixel is filtered against) starts from the latest sighting. Once a
    follow stands out again, or the last that did is older than ``STOOD_OUT_WITHIN_S``, both are the same."""
    clip = occlusion
    ts = TrackingSession(clip.cal)
    ts.select(clip.frames[0], clip.pose, 0, box=clip.cal.init_bbox)

    def on(i, du=0.0):
        return TrackResult("ok", clip.u[i] + du, clip.v[i], (0, 0, 10, 10), 0.7)

    slid = 12.0
    late = math.ceil(STOOD_OUT_WITHIN_S / (clip.t[1] - clip.t[0])) + 2
    steps = [(on(1), 1.5), (on(2, slid), 0.5), (on(3, slid), 0.6), (on(4), 1.2), (on(5, slid), 0.5)]
    steps += [(on(i, slid), 0.5) for i in range(6, 7 + late)]
    ts.target = target = _Scripted(steps)
    errors = []  # per frame: where it was looked for, and the prediction, off the true pixel
    for i in range(1, 7 + late):
        ts.step(clip.frames[i], clip.pose, i)
        looked, p = target.looked[-1], ts.prediction
        errors.append(
            (
                math.hypot(looked.u - clip.u[i], looked.v - clip.v[i]),
                math.hypot(p.u - clip.u[i], p.v - clip.v[i]),
            )
        )
    # frame 2 predicted from frame 1 (stood out): both on the UUV
    assert errors[1][0] < 3.0 and errors[1][1] < 3.0
    # frames 3, 4: looked for from frame 1's sighting, predicted from the slid ones
    assert all(looked < 3.0 and p > slid - 3.0 for looked, p in errors[2:4])
    # frame 5 after frame 4 stood out again: the same
    assert errors[4][0] < 3.0 and errors[4][1] < 3.0
    # frame 6 and on, slid from frame 5: looked for from frame 4's sighting while it is recent enough, then the latest
    assert errors[5][0] < 3.0 and errors[5][1] > slid - 3.0
    assert errors[-1][0] > slid - 3.0 and errors[-1] == errors[-1][::-1]

"""The live pipeline's queue and the fix JSON sent on Zenoh."""

from __future__ import annotations

import json
import re
from dataclasses import fields

import numpy as np
import pytest
from conftest import T0_UNIX
from live_helpers import until

from groundstation.config_files import load_calibration
from groundstation.live.pipeline import FramePoses, Pipeline
from groundstation.runtime.zenoh_fix import fix_to_json
from groundstation.video.frames import LiveFrame
from localizer.calibration import Calibration
from localizer.fix import Fix
from localizer.pose import CameraPose, camera_pose
from localizer.telemetry import Telemetry
from localizer.tracking.session import STEADY_S

CAL = """
[camera]
width = 64
height = 48
fx = 50.0
fy = 50.0
cx = 31.5
cy = 23.5
[mount]
attitude_source = "fixed"
[water]
takeoff_height_above_surface_m = 2.0
[tracker]
init_bbox = [10, 10, 8, 6]
"""


def _frame(i):
    return LiveFrame(i, 100.0 + i / 30, 100.0 + i / 30, np.zeros((48, 64, 3), np.uint8))


def test_queue_drops_oldest_but_keeps_the_init_frame(tmp_path):
    (tmp_path / "cal.toml").write_text(CAL)
    p = Pipeline(
        load_calibration(str(tmp_path / "cal.toml")), Telemetry(), "default", [], queue_len=3
    )
    for i in range(6):
        p.submit(_frame(i))
    assert [f.index for f in p._queue] == [0, 4, 5] and p.dropped == 3
    p._started = True  # once the init frame was taken, the oldest waiting frame goes first
    p.submit(_frame(6))
    assert [f.index for f in p._queue] == [4, 5, 6] and p.dropped == 4


def test_without_init_bbox_no_frame_is_kept_for_it(tmp_path):
    (tmp_path / "cal.toml").write_text(CAL.replace("init_bbox = [10, 10, 8, 6]\n", ""))
    p = Pipeline(
        load_calibration(str(tmp_path / "cal.toml")), Telemetry(), "default", [], queue_len=3
    )
    for i in range(6):
        p.submit(_frame(i))
    assert [f.index for f in p._queue] == [3, 4, 5] and p.dropped == 3


def test_fix_json_has_no_nan_and_no_position_without_fix():
    ok = fix_to_json(
        Fix(t_unix=1.5, status="ok", lat=63.4, lon=10.4, h_acc_m=0.2, u=3.0, v=4.0, frame=7)
    )
    assert ok["lat"] == 63.4 and ok["frame"] == 7 and ok["confidence"] is None
    lost = fix_to_json(Fix(t_unix=1.5, status="lost", lat=63.4, lon=10.4))
    assert lost["lat"] is None and lost["lon"] is None and lost["status"] == "lost"
    json.dumps(ok, allow_nan=False)
    json.dumps(lost, allow_nan=False)


def test_operator_commands_run_between_frames_on_held_frames():
    """A release before the first frame wins over init_bbox; a selection on a held frame catches up; a frame no
    longer held is refused; after a release every frame is released. Real frames and telemetry of a bundled session."""
    import asyncio
    from pathlib import Path

    import pytest

    from groundstation.session.read import load_session
    from groundstation.video.file import open_video
    from localizer.tracking.session import SelectionError

    session = load_session(
        Path(__file__).resolve().parents[1] / "sim_fixtures" / "bundled" / "nadir_hover"
    )
    cal, t = session.calibration, session.frames["t"]
    with open_video(session.video_path) as video:
        images = [f.image for f in video][:60]
    fixes = []

    class Collect:
        def on_fix(self, fix, info):
            fixes.append(fix)

    async def feed(pipeline, frames):
        for i in frames:  # one at a time: nothing is dropped
            pipeline.submit(LiveFrame(i, float(t[i]), float(t[i]), images[i]))
            await until(lambda n=i + 1: len(fixes) >= n, 30.0, f"frame {i}'s fix")

    async def scenario():
        pipeline = Pipeline(cal, session.telemetry, "default", [Collect()], history_s=0.5)
        task = asyncio.create_task(pipeline.run())
        try:
            released = await pipeline.release()
            assert released["target"]["state"] == "released"
            await feed(pipeline, range(20))
            assert {f.status for f in fixes} == {"released"}  # init_bbox did not take over
            tr = session.track
            w, h = cal.init_bbox[2:]

            def box(i, off=0.0):  # the UUV's box on frame i, ``off`` box widths to its right
                u, v = np.interp(t[i], tr["t"], tr["u"]), np.interp(t[i], tr["t"], tr["v"])
                return (u - (w - 1) / 2 + off * w, v - (h - 1) / 2, w, h)

            refused = r"no vehicle-sized object stands out .* over \d+ of \d+ frames"
            # a box on the seafloor three box sizes off the UUV: refused on the held frames it was followed in
            with pytest.raises(SelectionError, match=refused):
                await pipeline.select(9, box=box(9, 3.0))
            assert pipeline.target["state"] == "awaiting_target"
            # the held frames after frame 9 span STEADY_S (0.3 s): checked on them
            answer = await pipeline.select(9, box=box(9))
            assert (
                answer["frame"] == 9
                and answer["caught_up"] == 10
                and answer["target"]["state"] == "tracking"
            )
            with pytest.raises(
                SelectionError,
                match=r"frame 3 is not held \(held: frames [45]…19, the last 0.5 s\)",
            ):
                await pipeline.select(3, box=box(3))
            await feed(pipeline, range(20, 25))
            # a box on the newest frame: the answer waits for the check's verdict on the frames to come
            seafloor, _ = await asyncio.gather(
                pipeline.select(24, box=box(24, 3.0)),
                feed(pipeline, range(25, 37)),
                return_exceptions=True,
            )
            assert isinstance(seafloor, SelectionError) and re.search(refused, str(seafloor)), (
                seafloor
            )
            assert pipeline.target["state"] == "awaiting_target"
            answer, _ = await asyncio.gather(
                pipeline.select(36, box=box(36)), feed(pipeline, range(37, 55))
            )
            assert answer["frame"] == 36 and answer["caught_up"] == 0, answer
            assert answer["target"]["state"] == "tracking" and answer["latest_frame"] > 36, answer
            assert not any(f.ok for f in fixes[25:37]) and all(f.ok for f in fixes[-5:])
            await pipeline.release()
            await feed(pipeline, range(55, 60))
            assert {f.status for f in fixes[55:]} == {"released"}
        finally:
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)

    asyncio.run(scenario())


def _same(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    if a.dtype == object:
        return a.tolist() == b.tolist()
    return np.array_equal(a, b, equal_nan=True)


def test_a_frames_pose_is_computed_once_for_every_uuv(cal_dict, make_telemetry):
    """Two UUVs' pipelines share each frame's pose (FramePoses): computed once, each with its own UUV's depth,
    field for field what camera_pose gives that UUV alone; asked again for a frame that was early, computed anew
    once."""
    cal = Calibration.from_dict(cal_dict())
    tel = make_telemetry(depth_m=2.0)
    other = make_telemetry(depth_m=3.5).depth  # the second UUV's depth series
    poses = FramePoses(cal, tel)
    a = Pipeline(cal, tel, "default", [], poses=poses)
    b = Pipeline(cal, tel, "default", [], poses=poses, depth=other)
    frame = LiveFrame(0, T0_UNIX + 1.0, T0_UNIX + 1.0, np.zeros((48, 64, 3), np.uint8))
    pa, pb = a._pose(frame), b._pose(frame)
    assert (poses.computed, poses.shared) == (1, 1)
    assert pa.depth_m[0] == pytest.approx(2.0) and pb.depth_m[0] == pytest.approx(3.5)
    for pose, depth in ((pa, tel.depth), (pb, other)):
        alone = camera_pose(cal, tel, frame.t_unix, None, depth)
        assert alone.status[0] == "ok"
        for f in fields(CameraPose):
            assert _same(getattr(pose, f.name), getattr(alone, f.name)), f.name
    b._pose(frame, again=True), a._pose(frame, again=True)
    assert (poses.computed, poses.shared) == (2, 2)


def test_a_grey_tracker_reads_the_luma_plane_as_skyfix_process_does():
    """Frames handed over with their luma plane beside BGR (as the live reader hands them) are tracked as ``skyfix
    process`` tracks the video: the same status and pixel, frame for frame, through an occlusion; the same frames
    in BGR alone are tracked on the conversion's other grey levels, and some pixels differ. Live, ``init_bbox`` is
    checked over the frames of its first ``STEADY_S`` (no fix meanwhile); from then on the same as offline."""
    import asyncio
    from pathlib import Path

    from groundstation.offline.track import track_session
    from groundstation.session.read import load_session
    from groundstation.video.file import open_video

    session = load_session(
        Path(__file__).resolve().parents[1] / "sim_fixtures" / "bundled" / "occlusion"
    )
    cal, t = session.calibration, session.frames["t"]
    offline = track_session(session)
    with open_video(session.video_path, grey=True) as video:
        frames = list(video)
    assert all(f.image.ndim == 2 for f in frames)  # yuv420p: read as its luma plane

    async def live(with_grey: bool) -> list[Fix]:
        pipeline = Pipeline(cal, session.telemetry, "default", [])
        return [
            await pipeline.process(
                LiveFrame(
                    f.index,
                    float(t[f.index]),
                    float(t[f.index]),
                    f.bgr(),
                    grey=f.image if with_grey else None,
                )
            )
            for f in frames
        ]

    seen, bgr_only = asyncio.run(live(True)), asyncio.run(live(False))
    checked = next(i for i, f in enumerate(seen) if f.status != "awaiting_target")
    assert checked - round(STEADY_S * 30) in (
        0,
        1,
    )  # the first frame STEADY_S on (30 fps, the times' rounding)
    ok = offline.status[checked:] == "ok"
    assert 0 < ok.sum() < len(ok)  # tracked, and lost while hidden
    assert [np.isfinite(f.u) for f in seen[checked:]] == ok.tolist()
    assert np.array_equal([f.u for f in seen[checked:]], offline.u[checked:], equal_nan=True)
    assert np.array_equal([f.v for f in seen[checked:]], offline.v[checked:], equal_nan=True)
    assert not np.array_equal([f.u for f in bgr_only], offline.u, equal_nan=True)


def _nadir_hover_boxed(dx_px: int, attitude_from_frame: int = 0):
    """nadir_hover with its ``init_bbox`` moved ``dx_px`` right, its first 20 frames (luma and BGR) and its
    telemetry, whose attitude starts after frame ``attitude_from_frame - 1`` (the frames before it have no pose)."""
    import copy
    from dataclasses import replace
    from pathlib import Path

    from groundstation.session.read import load_session
    from groundstation.video.file import open_video

    session = load_session(
        Path(__file__).resolve().parents[1] / "sim_fixtures" / "bundled" / "nadir_hover"
    )
    t = session.frames["t"]
    tel = session.telemetry
    if attitude_from_frame:
        tel = copy.deepcopy(tel)
        att = tel.attitude
        kept = att.times > float(tel.uav_time(t[attitude_from_frame - 1])) + 1e-3
        times, values = att.times[kept].copy(), att.values[kept].copy()
        att.clear()
        for ti, vi in zip(times, values, strict=True):
            assert att.append(float(ti), vi)
    x, y, w, h = session.calibration.init_bbox
    box = (x + dx_px, y, w, h)
    cal = replace(session.calibration, tracker=replace(session.calibration.tracker, init_bbox=box))
    with open_video(session.video_path, grey=True) as video:
        frames = [f for f, _ in zip(video, range(20), strict=False)]
    return session, cal, tel, box, frames


def _live_boxed(session, cal, tel, frames):
    """The frames through a live pipeline: the pipeline, each frame's fix and ``target.init_bbox`` after it."""
    import asyncio

    t = session.frames["t"]

    async def live():
        pipeline = Pipeline(cal, tel, "default", [])
        fixes, said = [], []
        for f in frames:
            frame = LiveFrame(f.index, float(t[f.index]), float(t[f.index]), f.bgr(), grey=f.image)
            fixes.append(await pipeline.process(frame))
            said.append(pipeline.target["init_bbox"])
        return pipeline, fixes, said

    return asyncio.run(live())


def _assert_on_the_vehicle(ok: list[Fix], truth) -> None:
    """Each ok fix's pixel within 3 px of the simulator's (the vehicle is about 28 px long)."""
    du = [f.u - np.interp(f.t_unix, truth["t"], truth["u"]) for f in ok]
    dv = [f.v - np.interp(f.t_unix, truth["t"], truth["v"]) for f in ok]
    assert np.all(np.abs(du) < 3.0) and np.all(np.abs(dv) < 3.0), (du, dv)


@pytest.mark.parametrize("dx_px", [0, 20, -35])
def test_a_configured_init_bbox_off_the_vehicle_is_snapped_or_refused(dx_px, caplog):
    """``[tracker] init_bbox`` is checked from the first frame as an operator's box is, over the frames of
    ``STEADY_S`` (``confirming`` meanwhile, no fix): on the vehicle it is kept as drawn; 20 px to the right (still
    over the vehicle's edge) it is snapped onto the vehicle's outline; 35 px to the left (open water) it is refused,
    and the run awaits a target. No fix is ok with the box's offset, whichever: each ok fix's pixel is within 3 px of
    the simulator's (the vehicle is about 28 px long). nadir_hover's frames. (The box is 33 px wide: 25 px either
    side it still holds the vehicle's edge, about 5 px of it, and the one-frame check took or refused it by the
    frame: 25 px to the right it refused it on frames 5 and 10, 25 px to the left on frame 0 alone.)"""
    session, cal, tel, box, frames = _nadir_hover_boxed(dx_px)
    with caplog.at_level("WARNING", logger="skyfix.pipeline"):
        pipeline, fixes, said_then = _live_boxed(session, cal, tel, frames)
    ok = [f for f in fixes if f.ok]
    _assert_on_the_vehicle(ok, session.track)
    # the frames of the check (no fix): up to the first STEADY_S on (at 30 fps, with the times' rounding)
    checking = next((i for i, s in enumerate(said_then) if not s.startswith("confirming")), None)
    assert checking in (round(STEADY_S * 30), round(STEADY_S * 30) + 1), said_then
    assert not any(f.ok for f in fixes[:checking])
    said = pipeline.target["init_bbox"]
    if dx_px == 0:
        assert said == "kept" and len(ok) == len(frames) - checking and not caplog.records
    elif dx_px > 0:
        assert said.startswith(f"snapped: {list(box)} is off the vehicle")
        assert len(ok) == len(frames) - checking
        assert [r.getMessage() for r in caplog.records] == [f"tracker.init_bbox on frame 0: {said}"]
    else:
        assert not ok and pipeline.target["state"] == "awaiting_target"
        assert said.startswith(f"refused: box {list(box)}: no vehicle-sized object")
        (record,) = caplog.records
        assert f"tracker.init_bbox on frame 0: box {list(box)}" in record.getMessage()


@pytest.mark.parametrize("dx_px", [0, 20, -35])
def test_an_init_bbox_taken_without_a_pose_is_checked_on_the_first_frame_with_one(dx_px, caplog):
    """The UAV's attitude arrives after the first frames (the video starts first): ``init_bbox`` cannot be checked
    from frame 0 (no pose to size the vehicle) and is tracked unchecked; from the first frame tracked with a pose it
    is checked as it would have been: on the vehicle kept, 20 px right snapped onto the outline, 35 px left (open
    water, tracked as the seafloor until then) refused. Without the late check a box on open water
    gives ok fixes off the vehicle once the attitude arrives. nadir_hover's frames."""
    session, cal, tel, _, frames = _nadir_hover_boxed(dx_px, attitude_from_frame=4)
    with caplog.at_level("WARNING", logger="skyfix.pipeline"):
        pipeline, fixes, said = _live_boxed(session, cal, tel, frames)
    # the frames of the check from frame 4 (no fix): up to the first STEADY_S on (30 fps, the times' rounding)
    checked = next(i for i, s in enumerate(said) if i > 4 and not s.startswith("confirming"))
    assert checked - 4 in (round(STEADY_S * 30), round(STEADY_S * 30) + 1), said
    assert not any(f.ok for f in fixes[:checked])  # no pose, no fix; then checking
    assert all(s.startswith("unchecked: no camera pose on frame 0") for s in said[:4]), said[:4]
    assert all(s.endswith("from frame 4, the first with a camera pose") for s in said[4:checked])
    ok = [f for f in fixes if f.ok]
    _assert_on_the_vehicle(ok, session.track)
    final = said[-1]
    if dx_px == 0:
        assert final == "kept: checked on frame 4, the first with a camera pose"
        assert len(ok) == len(frames) - checked and not caplog.records
    elif dx_px > 0:
        assert final.startswith("snapped on frame 4, the first with a camera pose: the tracked box")
        assert len(ok) == len(frames) - checked
        assert [r.getMessage() for r in caplog.records] == [f"tracker.init_bbox: {final}"]
    else:
        assert not ok and pipeline.target["state"] == "awaiting_target"
        assert final.startswith("refused on frame 4, the first with a camera pose: box ")
        assert "no vehicle-sized object" in final
        (record,) = caplog.records
        assert record.getMessage() == f"tracker.init_bbox: {final}; awaiting a target"

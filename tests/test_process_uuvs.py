"""``skyfix process --uuv all``: every UUV of a session tracked in one pass over the video, each into its own folder,
each with the files processing that UUV alone writes, byte for byte.

The session: ``two_uuvs_crossing`` as :mod:`crossing` generates it (6 s, without TIMESYNC and with the camera
wobbling, so the link's delay is unknown and the frames' offset to the telemetry is estimated from the video's
motion, once for both UUVs). The UAV 12 m up, 1 m south of the scenario's place: both vehicles wholly in view
from the first frame (at the scenario's place, 10 m up, uuv1 is first seen as a sliver at the frame's bottom edge:
``test_tracking_frame_edge.py``).
"""

from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest
from crossing import crossing_session

from groundstation.cli import main
from groundstation.height_from_size import HeightFromSize
from groundstation.offline import process, track, uuv_workers
from groundstation.session import read
from groundstation.session.read import Session, SessionError, load_session, uuv_ids
from localizer.height import HeightEstimator

FILES = ("positions.csv", "positions_smoothed.csv")

pytestmark = pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="needs the ffmpeg CLI")


@pytest.fixture(scope="module")
def crossing(tmp_path_factory) -> Path:
    return crossing_session(tmp_path_factory, north_m=-1.0, height_m=12.0)


def _counted(monkeypatch, owner, name: str) -> list:
    """Calls of ``owner.name`` (still the real one) counted, one list entry each."""
    calls, real = [], getattr(owner, name)

    def counting(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(owner, name, counting)
    return calls


def test_all_uuvs_in_one_pass_give_each_uuvs_own_files(crossing, tmp_path, capsys, monkeypatch):
    ids = uuv_ids(crossing)
    assert len(ids) == 2
    opened = _counted(monkeypatch, Session, "open_video")
    poses = _counted(monkeypatch, track, "uav_pose")
    tlogs = _counted(monkeypatch, read, "read_tlog")
    measured = _counted(monkeypatch, HeightFromSize, "measure")
    filters = _counted(monkeypatch, HeightEstimator, "_run")
    assert main(["process", str(crossing), "--uuv", "all", "--out", str(tmp_path / "all")]) == 0
    printed = capsys.readouterr()
    err = printed.err
    # one estimate of the camera's height for both UUVs, measured on one schedule
    assert printed.out.count("(one estimate for uuv1, uuv2;") == 2, printed.out
    measured_all = len(measured)
    measured.clear()
    # the video decoded once, each frame's UAV pose computed once, the UAV's log parsed once, its height filter run
    # once (causal and two-sided: localizer.height.share)
    assert (len(opened), len(poses), len(tlogs), len(filters)) == (1, 1, 1, 2)
    assert err.count("the frames' offset to the telemetry from the video's motion") == 1, err
    workers = tmp_path / "workers"  # each UUV tracked in a process of its own: the same files
    assert (
        main(["process", str(crossing), "--uuv", "all", "--track-workers", "--out", str(workers)])
        == 0
    )
    beside = (
        tmp_path / "beside"
    )  # the heights from size and each UUV's files in processes of their own
    capsys.readouterr()
    assert main(["process", str(crossing), "--uuv", "all", "--beside", "--out", str(beside)]) == 0
    # the same lines in the same order
    assert capsys.readouterr().out == printed.out.replace(str(tmp_path / "all"), str(beside))

    for uuv in ids:
        alone = tmp_path / "alone" / uuv
        assert main(["process", str(crossing), "--uuv", uuv, "--out", str(alone)]) == 0
        for name in FILES:
            assert (tmp_path / "all" / uuv / name).read_bytes() == (alone / name).read_bytes(), (
                uuv,
                name,
            )
            assert (workers / uuv / name).read_bytes() == (alone / name).read_bytes(), (uuv, name)
            assert (beside / uuv / name).read_bytes() == (alone / name).read_bytes(), (uuv, name)
        rows = [
            r
            for r in (alone / "positions.csv").read_text().splitlines()[1:]
            if "before_init" not in r
        ]
        # uuv1 is lost a while in this view (alone too)
        assert sum(",ok," in r for r in rows) > 0.6 * len(rows)
        assert all(",motion," in r for r in rows if ",ok," in r)  # the offset estimated and applied
    assert len(opened) == 3 + len(ids)
    # (the track workers' and --beside's measurements are counted in their processes, not here)
    assert 0 < measured_all < 0.7 * len(measured), (measured_all, len(measured))
    first, second = ((tmp_path / "all" / uuv / FILES[0]).read_bytes() for uuv in ids)
    assert first != second


def _tracked(path: Path, workers: bool, size_process: bool = False) -> tuple[list, list, list]:
    """Both UUVs of ``path`` tracked in one pass as ``skyfix process --uuv all`` tracks them (the motion measured,
    traced back, the height from size in ``auto``, at 10 Hz and 2 Hz once sure: sure 4.6 s in, the frames measured
    after depend on it): the results, each size's status, each telemetry's height fixes (times, values)."""
    sessions = [load_session(path, uuv) for uuv in uuv_ids(path)]
    sizes = [
        HeightFromSize(s.calibration, s.telemetry, "auto", measure_hz=10.0, sure_hz=2.0)
        for s in sessions
    ]
    videos = track.track_sessions(
        sessions,
        measure_motion=True,
        sizes=sizes,
        both_ways=True,
        workers=workers,
        size_process=size_process,
    )
    fixes = [
        [
            (series.times.tolist(), series.values.tolist())
            for series in s.telemetry.height_fixes.values()
        ]
        for s in sessions
    ]
    return videos, [size.status() for size in sizes], fixes


def test_worker_processes_give_the_same_results(crossing, monkeypatch):
    """Each UUV tracked in a process of its own, the frames through a shared ring of two (each slot written again
    as soon as both workers are done with it), and (the default) the heights from size measured in a process of
    their own through a ring of one slot (each measurement taken before the next is handed over): the same
    per-frame results, the same heights from size taken (and handed to the telemetry) as stepping and measuring
    both in this process."""
    monkeypatch.setattr(uuv_workers, "RING_SLOTS", 2)
    monkeypatch.setattr(uuv_workers, "SIZE_SLOTS", 1)
    with monkeypatch.context() as m:
        measured = _counted(m, HeightFromSize, "measure")
        alone_videos, alone_sizes, alone_fixes = _tracked(crossing, workers=False)
        assert len(measured) > 20
    # counted in this process only: the processes' steps and measurements are counted in theirs
    steps = _counted(monkeypatch, track.UuvTrack, "step")
    measured = _counted(monkeypatch, HeightFromSize, "measure")
    by_size_worker = _tracked(crossing, workers=False, size_process=True)
    assert measured == [] and len(steps) > 0
    steps.clear()
    for videos, sizes, fixes in (by_size_worker, _tracked(crossing, workers=True)):
        assert steps == [] and measured == []
        # both UUVs' heights from size are measured and applied
        assert sizes == alone_sizes and min(s["applied"] for s in sizes) > 10, sizes
        assert fixes == alone_fixes and fixes[1]
        _assert_same_videos(videos, alone_videos)


def _assert_same_videos(videos: list, alone_videos: list) -> None:
    for video, alone in zip(videos, alone_videos, strict=True):
        assert np.sum(video.status == "ok") > 0.6 * len(video.status)
        assert video.rotations and len(video.rotations) == len(alone.rotations)
        for name in ("u", "v", "sigma_px", "confidence"):
            np.testing.assert_array_equal(getattr(video, name), getattr(alone, name))
        for name in ("status", "causal_status", "bridged"):
            assert getattr(video, name).tolist() == getattr(alone, name).tolist()


def _job(i: int, fail: bool) -> None:
    print(f"out {i} {os.getpid()}")
    print(f"err {i}", file=sys.stderr)
    if fail:
        raise SessionError(f"job {i} failed")


def test_each_beside_prints_in_order_and_raises_the_first_error(capsys):
    """``--uuv all``'s UUVs after the pass: the first job here, the others in processes of their own, their output
    in the jobs' order, the first error raised (a later job's output and error dropped)."""
    with pytest.raises(SessionError, match="job 2 failed"):
        process.each_beside(_job, [(0, False), (1, False), (2, True), (3, True)])
    captured = capsys.readouterr()
    lines = captured.out.splitlines()
    assert [line.split()[:2] for line in lines] == [["out", "0"], ["out", "1"], ["out", "2"]]
    pids = [int(line.split()[2]) for line in lines]
    assert pids[0] == os.getpid() and len(set(pids)) == 3
    assert captured.err.splitlines() == ["err 0", "err 1", "err 2"]

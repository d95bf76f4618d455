"""The camera's rotation between frames measured in a thread of its own (MotionThread) is what the caller's thread
measures (RotationMeter), frame for frame; a failure inside the thread reaches the caller."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from groundstation.latency.video_motion import (
    PAIRS_PER_THIRD,
    MotionThread,
    RotationMeter,
    measured_every,
)
from localizer.camera import Camera

W, H = 640, 360
CAMERA = Camera(width=W, height=H, fx=600.0, fy=600.0, cx=319.5, cy=179.5)


def _frames(n: int) -> list[np.ndarray]:
    """A blurred random texture panned a few pixels a frame (a small rotation of the camera), grey uint8."""
    rng = np.random.default_rng(3)
    scene = cv2.GaussianBlur(rng.integers(0, 255, (H + 80, W + 80), dtype=np.uint8), (5, 5), 1.5)
    return [scene[40 - i : 40 - i + H, 40 + 2 * i : 40 + 2 * i + W].copy() for i in range(n)]


def test_the_thread_measures_what_the_caller_would():
    frames = _frames(12)
    meter = RotationMeter(CAMERA)
    expected = [r for i, f in enumerate(frames) if (r := meter.measure(i / 30, f)) is not None]
    thread = MotionThread(CAMERA, depth=2)
    for i, f in enumerate(frames):
        thread.feed(i / 30, f)
    got = thread.finish()
    assert len(expected) == len(frames) - 1
    assert [(r.t0, r.t1, r.tracks) for r in got] == [(r.t0, r.t1, r.tracks) for r in expected]
    assert all(np.array_equal(a.rotvec, b.rotvec) for a, b in zip(got, expected, strict=True))
    # the pan is a turn of the camera: about 2 px / 600 px a frame about its y axis, 1 px about x
    assert np.median([r.rotvec[1] for r in got]) == pytest.approx(-2 / 600, rel=0.2)


def test_a_failure_in_the_thread_is_raised_by_finish_and_never_blocks_feed():
    thread = MotionThread(CAMERA, depth=1)
    thread.feed(0.0, np.zeros((0, 0), np.uint8))  # an empty image: OpenCV refuses it
    for i in range(5):  # more than the queue holds: the failed thread keeps draining
        thread.feed((i + 1) / 30, _frames(1)[0])
    with pytest.raises(cv2.error):
        thread.finish()


def test_close_stops_the_thread_early():
    thread = MotionThread(CAMERA)
    thread.feed(0.0, _frames(1)[0])
    thread.close()
    assert not thread._thread.is_alive()


def test_every_third_frame_measured_is_the_meter_on_those_frames():
    frames = _frames(13)
    meter = RotationMeter(CAMERA)
    expected = [meter.measure(i / 30, f) for i, f in enumerate(frames) if i % 3 == 0][1:]
    thread = MotionThread(CAMERA, every=3)
    for i, f in enumerate(frames):
        thread.feed(i / 30, f)
    got = thread.finish()
    assert [(r.t0, r.t1) for r in got] == [(i / 30, (i + 3) / 30) for i in range(0, 10, 3)]
    assert all(np.array_equal(a.rotvec, b.rotvec) for a, b in zip(got, expected, strict=True))
    # three frames apart, the pan turns the camera three times as far
    assert np.median([r.rotvec[1] for r in got]) == pytest.approx(-6 / 600, rel=0.2)


@pytest.mark.parametrize(
    ("frames", "period_s", "every"),
    [
        (210, 1 / 30, 1),
        (720, 1 / 30, 1),
        (721, 1 / 30, 2),
        (1200, 1 / 30, 3),
        (36000, 1 / 30, 3),
        (36000, 1 / 10, 1),
        (36000, 1 / 60, 6),
        (1, float("inf"), 1),
    ],
)
def test_a_long_recording_is_measured_ten_times_a_second_each_third_keeping_its_pairs(
    frames, period_s, every
):
    assert measured_every(frames, period_s) == every
    if every > 1:  # each third keeps PAIRS_PER_THIRD pairs
        assert (frames - 1) // every // 3 >= PAIRS_PER_THIRD

"""``--record``'s video: frames encoded in-process with their exposure times as timestamps; read back
offline, each frame lands on its own row of ``video_frames.csv`` however irregular the times were."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from groundstation.live.sinks.recorder import VideoWriter
from groundstation.video.file import open_video

SIZE = (160, 120)
N = 60


def _image(i: int) -> np.ndarray:
    img = np.full((SIZE[1], SIZE[0], 3), 40, np.uint8)
    img[:, 2 * i : 2 * i + 6] = 230
    return img


def _bar_column(image) -> int:
    return int(np.argmax(image[:, :, 2].mean(axis=0) > 135))


def test_irregular_frame_times_map_each_frame_to_its_row(tmp_path):
    rng = np.random.default_rng(3)
    steps = rng.uniform(0.012, 0.070, N)  # a live stream's arrival-paced, jittery frame times
    steps[20] = 0.25  # and a stall
    t = 1_796_000_000.0 + np.cumsum(steps)
    writer = VideoWriter(tmp_path / "video.ts", tmp_path / "video_frames.csv", SIZE)
    for i in range(N):
        writer.write(float(t[i]), _image(i))
    # out of order (a reconnected stream on another clock): left out
    writer.write(float(t[N - 1]) - 0.5, _image(0))
    writer.close()
    assert writer.written == N and writer.dropped == 1

    with open(tmp_path / "video_frames.csv") as f:
        rows = list(csv.DictReader(f))
    assert [int(r["frame"]) for r in rows] == list(range(N))
    assert np.allclose([float(r["t"]) for r in rows], t, atol=1e-6, rtol=0)

    with open_video(tmp_path / "video.ts", expected_size=SIZE) as video:
        frames = list(video)
    assert [f.index for f in frames] == list(range(N))
    assert [_bar_column(f.image) for f in frames] == [2 * i for i in range(N)]
    # the container's timestamps are the exposure times (90 kHz ticks)
    assert [f.t_s for f in frames] == pytest.approx(list(t - t[0]), abs=2 / 90000)


def test_regular_times_with_skipped_frames_map_each_frame_to_its_row(tmp_path):
    """A live recording of a regular camera whose decoder fell behind: its times are the camera's 30 fps slots
    with gaps where frames were skipped, and every kept frame has its row. Read with the session's frame
    indices, each frame lands on its row; without them the gaps read as damage (frames lost in the file)."""
    slots = [0, 1, 2, 5, 6, 7, 11, 12, 20, 21, 22, 23, 30, 31, 32, 33, 34, 35, 40, 41]
    t = 1_796_000_000.0 + np.array(slots) / 30.0
    writer = VideoWriter(tmp_path / "video.ts", tmp_path / "video_frames.csv", SIZE)
    for i, ti in enumerate(t):
        writer.write(float(ti), _image(i))
    writer.close()
    assert writer.written == len(slots) and writer.dropped == 0
    with open(tmp_path / "video_frames.csv") as f:
        rows = [int(r["frame"]) for r in csv.DictReader(f)]
    assert rows == list(range(len(slots)))

    with open_video(tmp_path / "video.ts", expected_size=SIZE, indices=rows) as video:
        frames = list(video)
    assert [f.index for f in frames] == rows
    assert [_bar_column(f.image) for f in frames] == [2 * i for i in range(len(slots))]
    with open_video(tmp_path / "video.ts", expected_size=SIZE) as video:
        assert [f.index for f in video] == slots

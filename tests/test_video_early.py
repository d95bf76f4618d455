"""A video file decoding early (groundstation.video.file.decoding_early): taken by open_video as it is, numbered then."""

import shutil

import numpy as np
import pytest
from test_tracking_video import FPS, SIZE, N, _bar_column, _encode

from groundstation.video import file
from groundstation.video.file import decoding_early, open_video

pytestmark = pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="needs the ffmpeg CLI")


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    return _encode(tmp_path_factory.mktemp("early") / "clip.mp4")


def _read(video, prefetch: bool = True) -> list[tuple]:
    frames = video.prefetch(depth=3) if prefetch else iter(video.read, None)
    return [(f.index, f.t_s, _bar_column(f.bgr())) for f in frames]


@pytest.mark.parametrize(("grey", "prefetch"), [(False, True), (True, True), (True, False)])
def test_the_early_decoder_gives_the_frames_a_fresh_open_gives(clip, grey, prefetch):
    """The session's numbering (``indices``) is given after decoding started: the frames come out numbered by it,
    as from a video opened afterwards."""
    indices = [100 + 2 * i for i in range(N)]
    with open_video(clip, expected_size=SIZE, indices=indices, grey=grey) as fresh:
        expected = _read(fresh)
    with (
        decoding_early(clip, grey=grey),
        open_video(clip, expected_size=SIZE, indices=indices, grey=grey) as video,
    ):
        assert video._prefetching is not None  # taken decoding, not opened again
        frames = _read(video, prefetch)
    assert frames == expected
    assert [i for i, *_ in frames] == indices
    assert [c for *_, c in frames] == [2 * i for i in range(N)]
    np.testing.assert_allclose([t for _, t, _ in frames], np.arange(N) / FPS)


def test_only_the_same_reading_takes_it_and_an_untaken_one_is_closed(clip):
    with decoding_early(clip, grey=True):
        early = file._early[(clip.resolve(), True)].taken()
        with open_video(clip, grey=False) as colour:  # not grey: opened afresh
            assert colour is not early and colour._prefetching is None
        assert early._prefetching is not None
    assert early._prefetching is None and not file._early  # closed


def test_a_file_it_cannot_open_is_reported_by_the_readers_open(tmp_path):
    from groundstation.video.frames import VideoError

    bad = tmp_path / "video.mp4"
    bad.write_bytes(b"not a video")
    with decoding_early(bad), pytest.raises(VideoError, match="FFmpeg cannot open it"):
        open_video(bad)


def test_a_size_other_than_the_calibrations_is_still_an_error(clip):
    from groundstation.video.frames import VideoError

    with decoding_early(clip), pytest.raises(VideoError, match="differs from the calibration"):
        open_video(clip, expected_size=(SIZE[0] * 2, SIZE[1]))


def test_a_video_closed_before_its_end_is_freed_under_the_interpreters_lock():
    # read grey, the file decodes in FFmpeg's frame threads, which log through PyAV (each message takes the
    # interpreter's lock); a video closed with frames in flight and then collected by the garbage collector (which
    # holds the lock) waited forever for them. In a process of its own, with a bound on its time.
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    code = (
        "import gc\n"
        "from groundstation.video.file import open_video\n"
        f"path = {str(root / 'sim_fixtures' / 'bundled' / 'nadir_hover' / 'video.mp4')!r}\n"
        "for _ in range(20):\n"
        "    video = open_video(path, grey=True)\n"
        "    frames = [f for f, _ in zip(video, range(15), strict=False)]\n"
        "    video.close()\n"
        "    del video, frames\n"
        "    gc.collect()\n"
        "print('freed')\n"
    )
    try:
        done = subprocess.run(
            [sys.executable, "-c", code],
            check=False,
            cwd=root,
            capture_output=True,
            text=True,
            timeout=120,
        )
    except subprocess.TimeoutExpired:
        pytest.fail("closing and collecting a video read in part hung (its frame threads)")
    assert done.returncode == 0 and done.stdout.strip() == "freed", done.stderr[-2000:]

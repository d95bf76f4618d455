"""Reading video with groundstation.video.file: real files made by the ffmpeg CLI, damaged on purpose."""

import shutil
import subprocess

import av
import numpy as np
import pytest

from groundstation.video.file import open_video
from groundstation.video.frames import VideoError, decoder

pytestmark = pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="needs the ffmpeg CLI")

FPS = 25
N = 50
SIZE = (160, 120)


def _encode(path, frames=N, size=SIZE, gop=10, extra=()):
    """A clip whose frame i shows a bright bar at column 2·i (so each frame is recognisable)."""
    w, h = size
    raw = np.full((frames, h, w, 3), 40, np.uint8)
    for i in range(frames):
        raw[i, :, 2 * i : 2 * i + 6] = 230
    cmd = [
        "ffmpeg",
        "-v",
        "error",
        "-y",
        "-f",
        "rawvideo",
        "-pix_fmt",
        "bgr24",
        "-s",
        f"{w}x{h}",
        "-r",
        str(FPS),
        "-i",
        "-",
        "-c:v",
        "libx264",
        "-g",
        str(gop),
        "-pix_fmt",
        "yuv420p",
        *extra,
        str(path),
    ]
    subprocess.run(cmd, input=raw.tobytes(), check=True)
    return path


def _bar_column(image) -> int:
    return int(np.argmax(image[:, :, 2].mean(axis=0) > 135))


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    return _encode(tmp_path_factory.mktemp("video") / "clip.mp4", extra=("-movflags", "+faststart"))


def test_reads_every_frame_in_order(clip):
    with open_video(clip, expected_size=SIZE, threads=2) as video:
        assert video.size == SIZE and video.fps == pytest.approx(FPS)
        frames = list(video)
    assert [f.index for f in frames] == list(range(N))
    assert [_bar_column(f.image) for f in frames] == [2 * i for i in range(N)]
    assert frames[0].image.shape == (SIZE[1], SIZE[0], 3)


def test_prefetch_yields_the_same_frames(clip):
    with open_video(clip) as video:
        indices = [(f.index, _bar_column(f.image)) for f in video.prefetch(depth=3)]
    assert indices == [(i, 2 * i) for i in range(N)]


def test_missing_empty_and_non_video_files_are_named(tmp_path):
    with pytest.raises(VideoError, match=r"nothere\.mp4: missing"):
        open_video(tmp_path / "nothere.mp4")
    (tmp_path / "empty.mp4").write_bytes(b"")
    with pytest.raises(VideoError, match=r"empty\.mp4: empty file"):
        open_video(tmp_path / "empty.mp4")
    (tmp_path / "text.mp4").write_text("this is not a video\n" * 100)
    with pytest.raises(VideoError, match=r"text\.mp4: FFmpeg cannot open it"):
        open_video(tmp_path / "text.mp4")


def test_size_different_from_the_calibration_is_an_error(clip):
    with pytest.raises(
        VideoError, match=r"160x120 pixels differs from the calibration's camera 1920x1080"
    ):
        open_video(clip, expected_size=(1920, 1080))


def test_truncated_file_ends_early_without_error(clip, tmp_path):
    data = clip.read_bytes()
    cut = tmp_path / "cut.mp4"
    cut.write_bytes(data[: len(data) * 6 // 10])
    with open_video(cut) as video:
        frames = list(video)
    assert 5 < len(frames) < N
    # every frame that came out is the right one for its index
    assert all(_bar_column(f.image) == 2 * f.index for f in frames)


def test_truncated_file_without_index_cannot_be_opened(tmp_path):
    clip = _encode(tmp_path / "plain.mp4")  # moov atom at the end
    cut = tmp_path / "cut.mp4"
    data = clip.read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(VideoError, match="cut.mp4: FFmpeg cannot open it"):
        open_video(cut)


def test_corrupt_frames_leave_gaps_not_shifts(tmp_path):
    clip = _encode(tmp_path / "ts.ts", gop=5)  # MPEG-TS: damage stays local
    data = bytearray(clip.read_bytes())
    mid = len(data) // 2
    for i in range(mid, mid + 4000):
        data[i] = (data[i] * 7 + 13) & 0xFF
    bad = tmp_path / "bad.ts"
    bad.write_bytes(bytes(data))
    with open_video(bad) as video:
        frames = list(video)
    indices = [f.index for f in frames]
    assert len(frames) < N
    assert indices == sorted(set(indices))
    # frames that decoded carry the index of their own content (up to concealment blur)
    good = [f for f in frames if abs(_bar_column(f.image) - 2 * f.index) <= 2]
    assert len(good) >= 0.8 * len(frames)
    assert frames[-1].index >= N - 5


def test_closing_while_prefetching_stops_the_reader_first(clip):
    video = open_video(clip)
    frames = video.prefetch(depth=2)
    assert next(frames).index == 0
    video.close()  # the reader thread is still decoding: it must stop before the decoder goes
    rest = list(frames)  # what was already decoded, then the end (no hang, no crash)
    assert len(rest) <= 3


def _slice_decoded(path) -> list[int]:
    """The bar column of every frame a slice-threaded decoder makes of ``path`` (packets that fail skipped), in order."""
    columns = []
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        ctx = decoder(stream, threads=4)
        for packet in container.demux(stream):
            try:
                columns += [_bar_column(f.to_ndarray(format="bgr24")) for f in ctx.decode(packet)]
            except av.error.InvalidDataError:
                continue
            except av.error.EOFError:
                break
    return columns


def test_a_cut_packet_loses_no_decodable_frame_to_frame_threads(clip, tmp_path):
    """Frame threads decode several frames at once: the packet a cut recording ends inside fails, and took those in
    flight with it (3 here). Every frame slice threads decode comes out, with its own index and time."""
    data = clip.read_bytes()
    cut = tmp_path / "cut.mp4"
    cut.write_bytes(data[: len(data) * 3 // 4])
    with open_video(cut, threads=4) as video:
        frames = list(video)
        assert video.bad_reads >= 1
    assert 10 < len(frames) < N
    assert [_bar_column(f.image) for f in frames] == _slice_decoded(cut)
    assert all(_bar_column(f.image) == 2 * f.index for f in frames)
    assert [f.t_s for f in frames] == pytest.approx([f.index / FPS for f in frames])


def test_grey_frames_are_the_luma_plane_and_give_the_same_bgr(clip):
    """Read grey (the default tracker's frames), a yuv420p frame is its luma plane as decoded; ``bgr()`` is the
    frame as read without grey, with the same index and time."""
    with av.open(str(clip)) as container:
        lumas = [f.to_ndarray()[: SIZE[1]] for f in container.decode(video=0)]
    with open_video(clip) as colour, open_video(clip, grey=True) as grey:
        pairs = list(zip(colour, grey, strict=True))
    assert len(pairs) == N
    for (a, b), luma in zip(pairs, lumas, strict=True):
        assert (b.index, b.t_s) == (a.index, a.t_s)
        assert b.image.shape == (SIZE[1], SIZE[0]) and b.image.dtype == np.uint8
        np.testing.assert_array_equal(b.image, luma)
        np.testing.assert_array_equal(b.bgr(), a.image)
        assert int(np.argmax(b.image.mean(axis=0) > 135)) == _bar_column(a.image) == 2 * a.index

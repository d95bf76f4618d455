"""A decoded frame converted to BGR where it is read (:class:`~groundstation.video.frames.BgrRegions`) holds the
bytes FFmpeg's conversion of the whole frame holds there: on a bundled video as decoded, on random pictures of odd
sizes with the colour space and range tagged, and through the track workers' shared ring."""

from __future__ import annotations

import mmap
from pathlib import Path
from types import SimpleNamespace

import av
import numpy as np
import pytest

from groundstation.offline.uuv_workers import put_frame, ring_frame
from groundstation.video.frames import REGION_MARGIN_PX, VideoFrame

VIDEO = Path(__file__).resolve().parents[1] / "sim_fixtures" / "bundled" / "occlusion" / "video.mp4"


def _windows(rng, H: int, W: int, count: int):
    """Random (y0, y1, x0, x1) windows, odd and even bounds, the frame's edges among them."""
    out = [(0, H, 0, W), (0, 3, 0, 5), (H - 7, H, W - 5, W)]
    for _ in range(count):
        y0, x0 = int(rng.integers(0, H - 1)), int(rng.integers(0, W - 1))
        out.append((y0, int(rng.integers(y0 + 1, H + 1)), x0, int(rng.integers(x0 + 1, W + 1))))
    return out


def _check(frame: VideoFrame, whole: np.ndarray, rng, count: int = 30) -> None:
    """Each window read from regions of its own (its first read converts it)."""
    assert frame.bgr_regions() is frame.bgr_regions()  # shared by the UUVs measured in the frame
    for y0, y1, x0, x1 in _windows(rng, *whole.shape[:2], count):
        frame._regions = None
        regions = frame.bgr_regions()
        assert regions.shape == whole.shape
        np.testing.assert_array_equal(regions[y0:y1, x0:x1], whole[y0:y1, x0:x1])


def test_regions_of_a_decoded_video_are_the_whole_frames_bytes():
    rng = np.random.default_rng(1)
    with av.open(str(VIDEO)) as container:
        for i, decoded in zip(range(4), container.decode(video=0), strict=False):
            assert decoded.format.name == "yuv420p"
            _check(VideoFrame(i, None, 0.0, decoded), decoded.to_ndarray(format="bgr24"), rng)


@pytest.mark.parametrize(
    ("size", "colour"),
    [((640, 360), (2, 0)), ((321, 180), (1, 2)), ((101, 77), (5, 1)), ((320, 181), (2, 0))],
)
def test_regions_of_random_pictures_of_odd_sizes_and_tagged_colours(size, colour):
    """Noise in every plane (each chroma sample differs from its neighbours), colour space and range tagged: a
    region's pixels need their own chroma samples, converted as the whole frame is (a frame of odd height: whole)."""
    rng = np.random.default_rng(2)
    w, h = size
    decoded = av.VideoFrame(w, h, "yuv420p")
    decoded.colorspace, decoded.color_range = colour
    for plane in decoded.planes:
        view = np.frombuffer(plane, np.uint8).reshape(plane.height, plane.line_size)
        view[:, : plane.width] = rng.integers(0, 256, (plane.height, plane.width), np.uint8)
    _check(VideoFrame(0, None, 0.0, decoded), decoded.to_ndarray(format="bgr24"), rng)


def test_a_region_read_again_is_not_converted_again_and_the_ring_converts_alike():
    with av.open(str(VIDEO)) as container:
        decoded = next(container.decode(video=0))
    whole = decoded.to_ndarray(format="bgr24")
    frame = VideoFrame(0, decoded.to_ndarray()[: decoded.height], 0.0, decoded)
    regions = frame.bgr_regions()
    first = regions[100:140, 200:260]
    inner = regions[100 + REGION_MARGIN_PX // 2 : 140, 200 : 260 + REGION_MARGIN_PX // 2]
    assert len(regions._converted) == 1 and np.shares_memory(first, inner)
    assert not first.flags.writeable
    ring = mmap.mmap(-1, whole.nbytes)
    layout = put_frame(ring, 0, whole.nbytes, frame, VIDEO)
    in_ring = ring_frame(ring, 0, layout).bgr_regions()
    np.testing.assert_array_equal(in_ring[50:300, 10:500], whole[50:300, 10:500])
    bgr_only = SimpleNamespace(image=whole, decoded=None)
    assert (
        ring_frame(ring, 0, put_frame(ring, 0, whole.nbytes, bgr_only, VIDEO)).bgr_regions().shape
        == whole.shape
    )
    del in_ring, regions

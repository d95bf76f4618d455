"""The reported pixel through waves filtered in time (localizer.tracking.motion_filter), on synthetic tracks whose true
pixel is known by construction: the camera's motion given as the session's predictions give it, the vehicle moving
on its own, the tracker's pixel jittering about the true one."""

from __future__ import annotations

import numpy as np

from localizer.tracking import TrackResult
from localizer.tracking.centroid import CentroidSteer
from localizer.tracking.motion_filter import MotionFilter

FPS = 30.0
PX_PER_M = 50.0


def _scene(seconds: float = 6.0, jitter_px: float = 1.2, seed: int = 11):
    """Per frame: time, the true pixel, the tracker's pixel, and the camera's image motion since the frame before
    (the drone rocking in the wind: up to 20 px a second, turning back and forth). The vehicle moves 0.2 m/s along a slow curve; the
    tracker's error is the true pixel's plus a jitter that lasts a few frames (white noise run through a short
    running mean, as the waves' break-up does)."""
    rng = np.random.default_rng(seed)
    n = int(seconds * FPS)
    t = np.arange(n) / FPS
    heading = 0.3 * t
    own = np.cumsum(
        np.column_stack([np.cos(heading), np.sin(heading)]) * 0.2 * PX_PER_M / FPS, axis=0
    )
    camera = np.column_stack([8.0 * np.sin(2.5 * t), 6.0 * np.cos(3.1 * t)])
    truth = np.array([320.0, 180.0]) + own + camera
    white = rng.normal(0.0, jitter_px, (n + 3, 2))
    error = (white[3:] + white[2:-1] + white[1:-2] + white[:-3]) / 2.0
    return t, truth, truth + error, np.diff(camera, axis=0, prepend=camera[:1])


def _filtered(t, tracked, camera_step):
    """The filter's pixels, each frame predicted as the session predicts it: the previous tracked pixel moved by
    the camera's motion."""
    motion = MotionFilter()
    out = []
    for k in range(len(t)):
        predicted = None if k == 0 else (*(tracked[k - 1] + camera_step[k]), PX_PER_M)
        out.append(motion.step(tuple(tracked[k]), tuple(tracked[k]), predicted, 1.7e9 + t[k]))
    return np.array(out)


def test_the_filter_takes_the_jitter_out_without_lagging_the_vehicle_or_the_camera():
    t, truth, tracked, camera_step = _scene()
    filtered = _filtered(t, tracked, camera_step)
    late = slice(
        int(FPS), None
    )  # once the filter has measured the jitter and the vehicle's velocity
    before = np.hypot(*(tracked[late] - truth[late]).T).mean()
    after = np.hypot(*(filtered[late] - truth[late]).T).mean()
    assert after < 0.7 * before, (before, after)
    # no lag: the vehicle moves 10 px a second, the camera up to 20; a filter that lagged by a few frames would be
    # pixels behind on average along the vehicle's way
    assert np.hypot(*(filtered[late] - truth[late]).mean(axis=0)) < 0.3


def test_a_tracker_that_does_not_jitter_is_followed_as_it_is():
    t, truth, _, camera_step = _scene()
    filtered = _filtered(t, truth, camera_step)
    assert np.abs(filtered - truth).max() < 0.1  # the vehicle moves 0.33 px a frame


def test_the_steer_filters_in_waves_only_and_starts_again_after_a_loss():
    t, _, tracked, camera_step = _scene(seconds=3.0)
    grey = np.full((360, 640), 128, np.uint8)  # no silhouette: the steer itself leaves the pixel

    def run(waves: float, lost_at: int = -1):
        steer = CentroidSteer()
        out = []
        for k in range(len(t)):
            if k == lost_at:
                steer.step(grey, TrackResult("lost"), 1.7e9 + t[k], waves, 25.0)
                out.append((np.nan, np.nan))
                continue
            u, v = tracked[k]
            result = TrackResult("ok", u, v, (round(u) - 12, round(v) - 12, 25, 25), 0.8, 1.0)
            predicted = None if k == 0 else (*(tracked[k - 1] + camera_step[k]), PX_PER_M)
            r = steer.step(grey, result, 1.7e9 + t[k], waves, 25.0, predicted)
            assert r.sigma_px == result.sigma_px and r.status == "ok"
            out.append((r.u, r.v))
        return np.array(out)

    np.testing.assert_array_equal(run(0.0), tracked)  # a still surface: the tracker's pixel
    in_waves = run(1.0)
    assert not np.allclose(in_waves, tracked)
    np.testing.assert_allclose(in_waves, _filtered(t, tracked, camera_step))
    lost_at = 45
    after_loss = run(1.0, lost_at)
    # the frame after the loss starts the filter again at the tracker's pixel (its prediction from before the loss
    # is not taken as the camera's motion)
    np.testing.assert_array_equal(after_loss[lost_at + 1], tracked[lost_at + 1])


def test_the_smoothed_track_is_given_the_pixels_before_the_filter():
    """positions.csv's fixes are made from the filtered pixels (causal, as live); the smoothed track's from the ones
    before the filter, and from the frames traced back."""
    from groundstation.offline.process import _pixels_of
    from groundstation.offline.track import TrackedVideo

    n = 5
    t = 1.7e9 + np.arange(n) / FPS
    status = np.array(["ok", "ok", "lost", "ok", "ok"], dtype=object)
    u, v = np.array([10.0, 11.0, np.nan, 13.0, 14.0]), np.full(n, 20.0)
    sigma = np.full(n, 1.5)
    unfiltered = np.array([10.0, 11.5, np.nan, 12.0, 14.0])

    def video(u_unfiltered, bridged=None, causal_status=None):
        return TrackedVideo(
            np.arange(n), t, u, v, status, np.full(n, 0.8), sigma,
            bridged=bridged, causal_status=causal_status,
            u_unfiltered=u_unfiltered, v_unfiltered=v.copy(),
        )  # fmt: skip

    same = _pixels_of(video(u.copy()))  # nothing filtered (a still surface): one set of pixels
    assert same.offline is None
    np.testing.assert_array_equal(same.u, u)
    pixels = _pixels_of(video(unfiltered))
    np.testing.assert_array_equal(pixels.u, u)
    np.testing.assert_array_equal(pixels.offline.u, unfiltered)
    np.testing.assert_array_equal(pixels.status, status)
    # a frame traced back: offline only, as before the filter
    bridged = np.array([False, False, True, False, False])
    causal = np.array(["ok", "ok", "lost", "ok", "ok"], dtype=object)
    traced_u = unfiltered.copy()
    traced_u[2] = 12.5
    status[2] = "ok"
    pixels = _pixels_of(video(traced_u, bridged, causal))
    assert np.isnan(pixels.u[2]) and pixels.status[2] == "lost"
    np.testing.assert_array_equal(pixels.offline.u, traced_u)

"""The lock's colour check (localizer/tracking/colour.py): a place with the vehicle's grey levels but not its colour
is no fix.

Hand-made frames for the measure itself (a blue hull on mottled sand, a caustic-lit patch of the same sand), and
a bundled session's real frames for the session: from one frame on, the UUV's colour is washed out to its
surroundings' (its luma kept, so the grey-level tracker still follows it as before).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from groundstation.session.read import load_session
from groundstation.video.file import open_video
from localizer.pose import camera_pose
from localizer.tracking.colour import (
    LEARN_MIN_SEPARATION,
    MIN_SEPARATION,
    Chroma,
    ColourModel,
    find,
    learn,
    separation,
)
from localizer.tracking.session import TrackingSession

BUNDLED = Path(__file__).resolve().parents[1] / "sim_fixtures" / "bundled"


def _sand(rng, shape=(240, 320)) -> np.ndarray:
    """Mottled sand (BGR): smooth brightness blotches over a sandy hue, with pixel noise."""
    blotches = cv2.GaussianBlur(rng.normal(0, 1, shape).astype(np.float32), (0, 0), 4)
    level = 120 + 60 * blotches / blotches.std()
    sand = np.dstack((0.75 * level, 0.95 * level, level)) + rng.normal(0, 3, (*shape, 3))
    return np.clip(sand, 0, 255).astype(np.uint8)


def test_the_hull_stands_out_in_colour_and_a_caustic_does_not():
    rng = np.random.default_rng(1)
    frame = _sand(rng)
    frame[110:130, 90:130] = (150, 90, 40)  # a blue hull, 40 x 20 px, at (109.5, 119.5)
    # a caustic: the sand 1.8x brighter in a hull-sized patch, its hue the sand's
    patch = frame[110:130, 230:270].astype(np.float64) * 1.8
    frame[110:130, 230:270] = np.clip(patch, 0, 255).astype(np.uint8)
    half = 20.0
    model = learn(Chroma(bgr=frame), 109.5, 119.5, half)
    assert model is not None and model.separation > 3 * LEARN_MIN_SEPARATION
    hull = separation(model, Chroma(bgr=frame), 109.5, 119.5, half)
    caustic = separation(model, Chroma(bgr=frame), 249.5, 119.5, half)
    sand = separation(model, Chroma(bgr=frame), 200.0, 60.0, half)
    assert model.matches(hull) and hull == pytest.approx(model.separation)
    assert not model.matches(caustic) and not model.matches(sand), (caustic, sand)
    assert abs(caustic) < MIN_SEPARATION and abs(sand) < MIN_SEPARATION
    # the same read from a yuv420p frame's planes (half resolution), as decoded offline
    yuv = cv2.cvtColor(frame, cv2.COLOR_BGR2YUV_I420)
    rows, cols = frame.shape[:2]
    u = yuv[rows : rows + rows // 4].reshape(rows // 2, cols // 2)
    v = yuv[rows + rows // 4 :].reshape(rows // 2, cols // 2)
    planes = Chroma.of(yuv[:rows], [yuv[:rows], u, v])
    from_planes = learn(planes, 109.5, 119.5, half)
    assert from_planes.separation == pytest.approx(model.separation, rel=0.3)
    assert not from_planes.matches(separation(from_planes, planes, 249.5, 119.5, half))
    # nothing to tell a grey hull on grey sand by: no model, no check
    grey = np.repeat(cv2.cvtColor(_sand(rng), cv2.COLOR_BGR2GRAY)[:, :, None], 3, axis=2)
    grey[110:130, 90:130] = 40
    assert learn(Chroma(bgr=grey), 109.5, 119.5, half) is None
    assert Chroma.of(grey[:, :, 0]) is None  # a grey image alone has no colour to read


@pytest.mark.parametrize("half", [1.0, 3.3, 12.0, 70.0])
def test_separation_reads_the_central_half_against_the_ring_as_defined(half):
    """separation() (sums over rectangles) against the pixels gathered one by one as the module doc defines the
    regions: the central half of the vehicle's square (Chebyshev distance) and the ring beyond it out to three
    half-lengths, on random chroma planes, near the frame's edge too; learn()'s separation is its own place's."""
    rng = np.random.default_rng(int(half * 10))
    cb, cr = (rng.integers(0, 256, (300, 400), dtype=np.uint8) for _ in range(2))
    chroma = Chroma(cb, cr)
    weights = np.array([0.7, -0.4])
    for u, v in [(401.3, 298.8), (3.0, 5.5), (790.2, 590.7), (256.75, 300.25)]:
        cu, cv_ = (
            (u + 0.5) / 2 - 0.5,
            (v + 0.5) / 2 - 0.5,
        )  # yuv420p: one chroma sample per 2 x 2 pixels
        ys, xs = np.mgrid[:300, :400]
        dist = np.maximum(np.abs(xs - cu), np.abs(ys - cv_))
        reach = 3 * half / 2
        inner = dist <= max(half / 4, 0.5)
        ring = (dist > half / 2) & (xs >= np.floor(cu - reach)) & (xs <= np.ceil(cu + reach))
        ring &= (ys >= np.floor(cv_ - reach)) & (ys <= np.ceil(cv_ + reach))
        level = cb * weights[0] + cr * weights[1]
        expected = (level[inner].mean() - level[ring].mean()) / np.sqrt(level[ring].var() + 1e-6)
        got = separation(ColourModel(weights, 1.0), chroma, u, v, half)
        assert got == pytest.approx(expected, rel=1e-9, abs=1e-12), (u, v)
    model = learn(Chroma(cb, cr), 401.3, 298.8, half, min_separation=-np.inf)
    assert model.separation == pytest.approx(
        separation(model, chroma, 401.3, 298.8, half), rel=1e-12
    )


def test_the_hull_is_found_again_by_its_colour_and_a_second_hull_makes_it_ambiguous():
    """find(): the place in a window standing out most in the learnt colour is the hull's (its centre within 2 px,
    its separation what separation() reads there), not a caustic; a second hull of the same colour in the window
    stands out as much (the caller's ambiguity)."""
    rng = np.random.default_rng(2)
    first = _sand(rng)
    first[110:130, 90:130] = (150, 90, 40)
    model = learn(Chroma(bgr=first), 109.5, 119.5, 20.0)
    moved = _sand(rng)
    moved[150:170, 180:220] = (
        150,
        90,
        40,
    )  # the hull 90 px right and 40 px down, at (199.5, 159.5)
    caustic = np.clip(moved[60:80, 120:160].astype(np.float64) * 1.8, 0, 255)
    moved[60:80, 120:160] = caustic.astype(np.uint8)
    u, v, d, second = find(model, Chroma(bgr=moved), (100.0, 40.0, 160.0, 150.0), 20.0)
    assert abs(u - 199.5) <= 2 and abs(v - 159.5) <= 2, (u, v)
    assert d == pytest.approx(separation(model, Chroma(bgr=moved), u, v, 20.0))
    assert d > 3 * LEARN_MIN_SEPARATION and second < MIN_SEPARATION * 2, (d, second)
    moved[60:80, 120:160] = (150, 90, 40)  # a second hull where the caustic was
    _, _, d, second = find(model, Chroma(bgr=moved), (100.0, 40.0, 160.0, 150.0), 20.0)
    assert second > 0.5 * d, (d, second)


def _washed_out(frame: np.ndarray, u: float, v: float, reach: int) -> np.ndarray:
    """``frame`` with the colour within ``reach`` px of (u, v) replaced by the median colour round it; luma kept."""
    ycrcb = cv2.cvtColor(frame, cv2.COLOR_BGR2YCrCb)
    ys, xs = np.ogrid[: frame.shape[0], : frame.shape[1]]
    dist = np.hypot(xs - u, ys - v)
    near, ring = dist <= reach, (dist > reach) & (dist <= 2 * reach)
    for c in (1, 2):
        ycrcb[:, :, c][near] = np.median(ycrcb[:, :, c][ring])
    return cv2.cvtColor(ycrcb, cv2.COLOR_YCrCb2BGR)


def test_a_lock_on_the_uuvs_grey_levels_without_its_colour_is_no_fix():
    """nadir_hover: tracked as before with the colour; from frame 30 the UUV's colour is washed out (its luma
    kept): no frame is ok from then on, while the grey-level tracker follows on as before."""
    session = load_session(BUNDLED / "nadir_hover")
    cal, t = session.calibration, session.frames["t"]
    pose = camera_pose(cal, session.telemetry, t)
    track = session.track
    u, v = np.interp(t, track["t"], track["u"]), np.interp(t, track["t"], track["v"])
    with open_video(session.video_path) as video:
        frames = [f.image for f in video][:60]
    reach = max(cal.init_bbox[2:])
    tracking = TrackingSession(cal, "default")
    results = [tracking.select(frames[0], pose, 0, box=cal.init_bbox, chroma=Chroma.of(frames[0]))]
    states = []
    for i in range(1, len(frames)):
        frame = frames[i] if i < 30 else _washed_out(frames[i], u[i], v[i], reach)
        results.append(tracking.step(frame, pose, i, chroma=Chroma.of(frame)))
        states.append(tracking.state.value)
    assert all(r.ok for r in results[:30])
    assert not any(r.ok for r in results[30:]), [r.status for r in results[30:]]
    assert set(states) == {"tracking"}  # only the frames' word changed
    # the same frames without the colour to read: the grey-level tracker alone follows the UUV on
    blind = TrackingSession(cal, "default")
    blind.select(frames[0], pose, 0, box=cal.init_bbox)
    washed = [frames[i] if i < 30 else _washed_out(frames[i], u[i], v[i], reach) for i in range(60)]
    assert all(blind.step(washed[i], pose, i).ok for i in range(1, 60))

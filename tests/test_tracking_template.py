"""Matchers and the target's life in the image on generated frames: a textured seafloor, a rotating vehicle-like
target that moves, hides and returns; hand-made predictions stand in for the telemetry."""

import math

import cv2
import numpy as np
import pytest

from localizer.tracking import TRACKERS, WITHOUT_LOSS_SIGNAL, Prediction, make_matcher
from localizer.tracking.target import Target, TargetParams, TargetState
from localizer.tracking.template import TemplateMatcher

W, H = 320, 240
LENGTH, BEAM = 34, 24  # target size (pixels)


def _floor(seed: int) -> np.ndarray:
    """Smooth random texture, larger than the frame so the camera can pan over it (BGR uint8)."""
    rng = np.random.default_rng(seed)
    small = cv2.GaussianBlur(
        rng.normal(0.0, 1.0, (H // 3 + 40, W // 3 + 40)).astype(np.float32), (0, 0), 1.5
    )
    big = cv2.resize(small, None, fx=3, fy=3, interpolation=cv2.INTER_CUBIC)
    big = 125 + 22 * (big - big.mean()) / big.std()
    return np.clip(np.dstack([big * 0.9 + 15, big * 0.85 + 10, big * 0.55]), 0, 255).astype(
        np.uint8
    )


def _draw_target(img, cx, cy, heading_deg, scale=1.0):
    """Dark hull with a light stripe along it and a bright nose, rotated about (cx, cy) (sub-pixel)."""
    s = 8  # draw at 1/8 pixel precision

    def poly(pts):
        a = math.radians(heading_deg)
        rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
        p = (np.asarray(pts, float) @ rot.T + (cx, cy)) * s
        return np.round(p).astype(np.int32)

    L, B = scale * LENGTH / 2, scale * BEAM / 2
    cv2.fillPoly(
        img, [poly([(-L, -B), (L, -B), (L, B), (-L, B)])], (40, 38, 36), cv2.LINE_AA, shift=3
    )
    cv2.fillPoly(
        img,
        [
            poly(
                [(-0.7 * L, -0.3 * B), (0.7 * L, -0.3 * B), (0.7 * L, 0.3 * B), (-0.7 * L, 0.3 * B)]
            )
        ],
        (205, 200, 190),
        cv2.LINE_AA,
        shift=3,
    )
    cv2.fillPoly(
        img,
        [poly([(0.75 * L, -0.5 * B), (L, -0.5 * B), (L, 0.5 * B), (0.75 * L, 0.5 * B)])],
        (40, 200, 235),
        cv2.LINE_AA,
        shift=3,
    )


def make_clip(n=120, hidden=(), seed=3, noise=3.0, grow=0.0):
    """Frames, the target's true centre per frame (NaN when hidden) and the camera's pan per frame.

    The target's size grows by the fraction ``grow`` over the clip (the UAV descending).
    """
    floor = _floor(seed)
    rng = np.random.default_rng(seed + 1)
    frames, truth, pan = [], [], []
    for i in range(n):
        px, py = 30 + 12 * math.sin(i / 15), 30 + 10 * math.cos(i / 19)  # camera pan (pixels)
        x0, y0 = int(px), int(py)
        img = floor[y0 : y0 + H, x0 : x0 + W].copy()
        cx, cy = W / 2 + 70 * math.sin(i / 30), H / 2 + 50 * math.sin(i / 23)
        cx, cy = cx - (px - x0), cy - (py - y0)
        visible = not any(a <= i < b for a, b in hidden)
        if visible:
            # keeps turning
            _draw_target(img, cx, cy, heading_deg=25 + 1.5 * i, scale=1.0 + grow * i / n)
        img = np.clip(img + rng.normal(0, noise, img.shape), 0, 255).astype(np.uint8)
        frames.append(img)
        truth.append((cx, cy) if visible else (np.nan, np.nan))
        pan.append((x0, y0))
    return frames, np.array(truth), np.array(pan, float)


def _box(truth0):
    cx, cy = truth0
    side = math.ceil(math.hypot(LENGTH, BEAM)) + 2
    return (round(cx - (side - 1) / 2), round(cy - (side - 1) / 2), side, side)


def _target(name="default", params: TargetParams | None = None) -> Target:
    return Target(lambda: make_matcher(name), params)


def _run(target, frames, truth, predictions=None):
    target.select(frames[0], _box(truth[0]), point=tuple(truth[0]))
    out = []
    for i in range(1, len(frames)):
        out.append(target.update(frames[i], None if predictions is None else predictions[i]))
    return out


def _predictions(truth, sigma_px=6.0, seed=9):
    """What the telemetry would say: the true centre off by a few pixels; while hidden, the last one."""
    rng = np.random.default_rng(seed)
    preds, last = [], truth[0]
    for t in truth:
        if np.all(np.isfinite(t)):
            last = t
        else:
            sigma_px += 2.0  # uncertainty grows while unseen
        u, v = last + rng.normal(0, 2.0, 2)
        preds.append(Prediction(u, v, LENGTH, BEAM, sigma_px=sigma_px, px_per_m=100.0))
    return preds


@pytest.mark.parametrize("with_prediction", [True, False])
def test_template_follows_a_moving_turning_target(with_prediction):
    frames, truth, _ = make_clip(n=120)
    preds = _predictions(truth) if with_prediction else None
    results = _run(_target(), frames, truth, preds)
    assert all(r.ok for r in results)
    err = [math.hypot(r.u - t[0], r.v - t[1]) for r, t in zip(results, truth[1:])]
    assert np.mean(err) < 0.5 and max(err) < 1.5
    assert all(0 <= r.confidence <= 1 for r in results)


@pytest.mark.parametrize("with_prediction", [True, False])
def test_template_reports_loss_while_hidden_and_reacquires(with_prediction):
    hidden = (40, 70)
    frames, truth, _ = make_clip(n=110, hidden=[hidden])
    preds = _predictions(truth) if with_prediction else None
    target = _target()
    results = _run(target, frames, truth, preds)
    status = [r.status for r in results]  # results[i] is frame i + 1
    hidden_frames = range(hidden[0] - 1, hidden[1] - 1)
    assert not any(status[i] == "ok" for i in hidden_frames)
    assert all(status[i] == "lost" for i in hidden_frames)
    assert all(np.isnan(results[i].u) for i in hidden_frames)
    back = [i for i in range(hidden[1] - 1, len(status)) if status[i] == "ok"]
    assert back and back[0] <= hidden[1] - 1 + 6, "re-acquired within a few frames of reappearing"
    assert all(status[i] == "ok" for i in range(back[0], len(status)))
    err = [math.hypot(results[i].u - truth[i + 1][0], results[i].v - truth[i + 1][1]) for i in back]
    assert np.mean(err) < 1.0 and max(err) < 3.0
    assert target.state is TargetState.TRACKING


@pytest.mark.parametrize("with_prediction", [True, False])
def test_template_searches_less_often_the_longer_it_is_lost_and_still_reacquires(with_prediction):
    p = TargetParams()
    a = 20  # hidden from frame a to frame b - 1
    b = a + p.long_loss_frames + 8 * p.search_every_long + 3
    frames, truth, _ = make_clip(n=b + 20, hidden=[(a, b)])
    preds = _predictions(truth) if with_prediction else None
    results = _run(_target(params=p), frames, truth, preds)  # results[i] is frame i + 1
    assert not any(r.ok for r in results[a - 1 : b - 1])
    # a search while lost reports its best score; frames without one report none
    searched = [i + 1 for i in range(a, b - 1) if np.isfinite(results[i].confidence)]
    lost_for = np.array(searched) - a  # frames since the loss (declared at frame a)
    gaps = np.diff(lost_for)
    assert np.all(gaps[lost_for[1:] <= p.long_loss_frames] == p.search_every)
    assert np.all(gaps[lost_for[:-1] >= p.long_loss_frames] == p.search_every_long)
    back = next(i + 1 for i in range(b - 1, len(results)) if results[i].ok)
    assert back - b <= p.search_every_long + p.confirm_frames - 2, (
        "re-acquired by the first search after it is back"
    )
    assert all(r.ok for r in results[back - 1 :])


@pytest.mark.parametrize("scale_at_start", [True, False])
def test_template_follows_the_predicted_apparent_size(scale_at_start):
    """Without the image scale at the selection (no pose there), the first prediction's is the reference."""
    n, grow = 100, 0.5
    frames, truth, _ = make_clip(n=n, grow=grow)
    preds = [
        Prediction(
            p.u, p.v, p.width_px, p.height_px, p.sigma_px, px_per_m=100.0 * (1.0 + grow * i / n)
        )
        for i, p in enumerate(_predictions(truth))
    ]
    target = _target()
    target.select(
        frames[0],
        _box(truth[0]),
        tuple(truth[0]),
        preds[0].px_per_m if scale_at_start else math.nan,
    )
    results = [target.update(frames[i], preds[i]) for i in range(1, n)]
    assert all(r.ok for r in results)
    err = [math.hypot(r.u - t[0], r.v - t[1]) for r, t in zip(results, truth[1:])]
    assert np.mean(err) < 0.7 and max(err) < 2.0
    assert results[-1].box[2] > 1.4 * _box(truth[0])[2]  # the box grew with the target


def test_template_never_takes_the_floor_for_a_target_that_never_returns():
    frames, truth, _ = make_clip(n=90, hidden=[(20, 90)])
    results = _run(_target(), frames, truth, _predictions(truth))
    assert not any(r.ok for r in results[19:])


def test_a_box_outside_the_frame_is_refused_and_changes_nothing():
    frames, truth, _ = make_clip(n=2)
    with pytest.raises(
        ValueError, match=r"box \(310, 5, 30, 30\) does not lie inside the 320x240 frame"
    ):
        TemplateMatcher().start(frames[0], (W - 10, 5, 30, 30))
    target = _target()
    target.select(frames[0], _box(truth[0]), point=tuple(truth[0]))
    with pytest.raises(ValueError, match="does not lie inside"):
        target.select(frames[1], (W - 10, 5, 30, 30))
    assert target.state is TargetState.TRACKING and target.update(frames[1], None).ok


@pytest.mark.parametrize("name", TRACKERS)
def test_every_backend_tracks_a_short_clip(name):
    frames, truth, _ = make_clip(n=25)
    target = _target(name)
    # no matcher runs before a selection
    assert target.update(frames[0], None).status == "awaiting_target"
    results = _run(target, frames, truth)
    ok = [r for r in results if r.ok]
    assert len(ok) >= 20
    err = [math.hypot(r.u - t[0], r.v - t[1]) for r, t in zip(results, truth[1:]) if r.ok]
    assert np.median(err) < 6.0


@pytest.mark.parametrize("name", TRACKERS)
def test_only_the_backends_listed_without_a_loss_signal_go_on_reporting_a_hidden_target(name):
    """What ``WITHOUT_LOSS_SIGNAL`` (refused for GPS_INPUT) rests on: hidden for 30 frames, the UUV is reported
    lost by every other backend; MIL goes on reporting it."""
    frames, truth, _ = make_clip(n=75, hidden=[(40, 70)])
    results = _run(_target(name), frames, truth)
    ok_while_hidden = sum(r.ok for r in results[39:69])  # results[i] is frame i + 1
    if name in WITHOUT_LOSS_SIGNAL:
        assert ok_while_hidden == 30
    else:
        assert ok_while_hidden == 0


def test_unknown_backend_is_named():
    with pytest.raises(ValueError, match="'nope'"):
        make_matcher("nope")


def test_release_stops_every_fix_until_a_new_selection():
    frames, truth, _ = make_clip(n=40)
    target = _target()
    results = _run(target, frames[:10], truth[:10])
    assert all(r.ok for r in results)
    target.release()
    assert target.state is TargetState.RELEASED
    assert [target.update(frames[i], None).status for i in range(10, 15)] == ["released"] * 5
    target.acquire()
    assert target.update(frames[15], None).status == "awaiting_target"
    target.select(frames[16], _box(truth[16]), point=tuple(truth[16]))
    back = [target.update(frames[i], None) for i in range(17, 40)]
    assert all(r.ok for r in back)
    assert max(math.hypot(r.u - t[0], r.v - t[1]) for r, t in zip(back, truth[17:])) < 1.5


def test_a_proposed_candidate_becomes_the_target_only_after_confirming_frames():
    frames, truth, _ = make_clip(n=40)
    preds = _predictions(truth)
    p = TargetParams()
    target = _target()
    first = target.propose(frames[5], _box(truth[5]), tuple(truth[5]), 100.0, preds[5])
    assert first.status == "awaiting_target" and target.state is TargetState.CONFIRMING
    results = [target.update(frames[i], preds[i]) for i in range(6, 40)]
    n_waiting = p.confirm_frames - 1  # the proposal itself was the first match
    assert [r.status for r in results[: n_waiting - 1]] == ["awaiting_target"] * (n_waiting - 1)
    assert all(r.ok for r in results[n_waiting - 1 :]) and target.state is TargetState.TRACKING
    err = [
        math.hypot(r.u - t[0], r.v - t[1])
        for r, t in zip(results[n_waiting - 1 :], truth[5 + n_waiting :])
    ]
    assert np.mean(err) < 0.7


@pytest.mark.parametrize("why", ["moves_against_the_camera", "hidden"])
def test_a_proposed_candidate_that_does_not_confirm_is_dropped(why):
    hidden = [(7, 40)] if why == "hidden" else []
    frames, truth, _ = make_clip(n=20, hidden=hidden)
    preds = _predictions(make_clip(n=20)[1])
    if (
        why == "moves_against_the_camera"
    ):  # the prediction (the camera's motion) jumps 40 px the other way
        preds = [
            Prediction(q.u - 40.0 * (i > 5), q.v, q.width_px, q.height_px, q.sigma_px, q.px_per_m)
            for i, q in enumerate(preds)
        ]
    target = _target()
    target.propose(frames[5], _box(truth[5]), tuple(truth[5]), 100.0, preds[5])
    results = [target.update(frames[i], preds[i]) for i in range(6, 20)]
    assert not any(r.ok for r in results)
    assert {r.status for r in results} == {
        "awaiting_target"
    } and target.state is TargetState.AWAITING_TARGET


def _draw_rock(img, cx, cy):
    """A dark, vehicle-sized stone: an irregular blob with a lighter patch off its centre, nothing like the hull."""
    pts = [
        (cx + r * math.cos(a), cy + 0.8 * r * math.sin(a))
        for a, r in zip(np.linspace(0, 2 * math.pi, 9)[:-1], (19, 15, 18, 20, 14, 17, 21, 16))
    ]
    cv2.fillPoly(
        img, [np.round(np.array(pts) * 8).astype(np.int32)], (55, 60, 62), cv2.LINE_AA, shift=3
    )
    cv2.circle(
        img,
        (round((cx - 8) * 8), round((cy + 5) * 8)),
        6 * 8,
        (120, 125, 120),
        -1,
        cv2.LINE_AA,
        shift=3,
    )


def test_the_template_does_not_learn_its_way_onto_something_else():
    """The UUV turns slowly into a rock beside it (a cross-fade slow enough for the template to learn along), then
    the rock moves off: checked against the UUV's first appearance, the rock is never taken for it nor followed."""
    floor = _floor(5)[:H, :W]
    rng = np.random.default_rng(6)
    c = (W / 2, H / 2)
    fade, n = (10, 250), 300
    frames = []
    for i in range(n):
        a = np.clip((i - fade[0]) / (fade[1] - fade[0]), 0.0, 1.0)  # the rock's share
        uuv, rock = floor.copy(), floor.copy()
        _draw_target(uuv, *c, heading_deg=25)
        _draw_rock(rock, c[0] + 4 + max(0, i - fade[1]), c[1] + 3)
        img = (1 - a) * uuv.astype(float) + a * rock.astype(float)
        frames.append(np.clip(img + rng.normal(0, 3.0, img.shape), 0, 255).astype(np.uint8))
    matcher = TemplateMatcher()
    matcher.start(frames[0], _box(c), point=c)
    found = [matcher.follow(f, None) for f in frames[1:]]  # found[i] is frame i + 1
    assert all(m.found for m in found[: (fade[0] + fade[1]) // 2])  # the UUV while it shows
    assert all(math.hypot(m.u - c[0], m.v - c[1]) < 2.0 for m in found if m.found), (
        "followed the rock"
    )
    # (nearly) only the rock is left: the UUV is lost
    assert not any(m.found for m in found[fade[1] - 10 :])


@pytest.mark.parametrize("how", ["follow", "search"])
def test_a_wide_window_prefers_the_candidate_near_the_prediction(how):
    """Frames were skipped (or the UUV was lost): the window is wide and holds the UUV, a little blurred, near the
    prediction and a sharper copy of it 2.3 sigmas away. The copy matches better; the UUV is nearer: it wins."""
    floor = _floor(7)[:H, :W]
    c = (W / 2 - 20, H / 2)
    first = floor.copy()
    _draw_target(first, *c, heading_deg=25)
    matcher = TemplateMatcher()
    matcher.start(first, _box(c), point=c)
    sigma = 15.0
    uuv = (c[0] + 2.0, c[1] + 1.0)
    twin = (c[0] + 2.3 * sigma, c[1])
    img = floor.copy()
    _draw_target(img, *uuv, heading_deg=25)
    near = _box(uuv)
    x, y, w, h = near
    img[y : y + h, x : x + w] = cv2.GaussianBlur(img[y : y + h, x : x + w], (0, 0), 1.6)
    _draw_target(img, *twin, heading_deg=25)
    prediction = Prediction(c[0], c[1], LENGTH, BEAM, sigma_px=sigma, px_per_m=100.0)
    m = matcher.follow(img, prediction) if how == "follow" else matcher.search(img, prediction)
    assert m.found and math.hypot(m.u - uuv[0], m.v - uuv[1]) < 1.5, (
        m.u - c[0],
        m.v - c[1],
        m.score,
    )


def test_several_templates_at_once_score_as_opencv_does():
    """The drift check's one-product NCC (``_ncc_maps``) against ``cv2.matchTemplate`` template by template, on a
    textured image with a flat (uniform) corner, where OpenCV scores 0."""
    from localizer.tracking.template import _ncc_maps

    rng = np.random.default_rng(5)
    image = cv2.GaussianBlur(rng.normal(120.0, 25.0, (23, 23)).astype(np.float32), (0, 0), 1.0)
    image[:16, :16] = 90.0  # the places (0..1, 0..1) are flat
    templates = [
        cv2.GaussianBlur(rng.normal(120.0, 25.0, (15, 15)).astype(np.float32), (0, 0), 1.0)
        for _ in range(5)
    ]
    columns = np.stack([t.ravel().astype(np.float64) - t.mean() for t in templates], axis=1)
    columns /= np.linalg.norm(columns, axis=0)
    maps = _ncc_maps(image, columns, 15)
    assert maps.shape == (5, 9, 9)
    for t, got in zip(templates, maps, strict=True):
        want = cv2.matchTemplate(image, t, cv2.TM_CCOEFF_NORMED)
        np.testing.assert_allclose(got, want, atol=1e-4)
    # the flat places, and scores that vary elsewhere
    assert np.all(maps[:, :2, :2] == 0.0) and np.ptp(maps) > 0.5

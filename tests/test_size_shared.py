"""Several UUVs of one video sharing one estimate of the camera's height from their sizes
(:class:`groundstation.height_from_size.SharedEstimate`): one measuring schedule for all, turns that go past a UUV
whose outline cannot be measured or that is not tracked, a UUV whose heights disagree with the others' left out
with a warning, two that disagree with no third leaving the estimate unsure.

Synthetic measurements with known biases go through :meth:`HeightFromSize.take`; real Telemetry receives what
``auto`` hands over.
"""

import re

import numpy as np

from groundstation.height_from_size import HeightFromSize
from localizer.calibration import Calibration
from localizer.size_range import SizeHeight
from localizer.telemetry import Telemetry

T0 = 1000.0


def _sizes(cal_dict, n: int, mode: str = "check") -> list[HeightFromSize]:
    cal = Calibration.from_dict(cal_dict())
    sizes: list[HeightFromSize] = []
    for k in range(n):
        shared = sizes[0] if sizes else None
        sizes.append(HeightFromSize(cal, Telemetry(), mode, shared=shared, name=f"uuv{k + 1}"))
    return sizes


def _height(t: float, bias: float, rng, sigma: float = 0.05) -> SizeHeight:
    return SizeHeight(t, 10.0 - bias + rng.normal() * sigma, sigma, 0.04, 10.0, 0.3, 0.2)


def _run(
    sizes, seconds: float, result_of, asking=lambda k, t: True, later: bool = False
) -> list[tuple[float, int]]:
    """30 fps: every UUV asks (``asking``) in order; a UUV given the frame takes ``result_of(k, t)`` at once, or
    with ``later`` as ``skyfix process --beside`` takes them (:class:`~groundstation.offline.uuv_workers.SizeWorker`):
    in order, those of the UUVs sharing the asking one's estimate before it asks whenever its answer may depend on
    them (``asks_estimate``). The (time, UUV) of every frame given."""
    given, pending = [], []
    for f in range(round(seconds * 30)):
        t = T0 + f / 30.0
        for k, size in enumerate(sizes):
            if not asking(k, t):
                continue
            if later and size.asks_estimate(t):
                while any(sizes[j].shared is size.shared for j, _ in pending):
                    j, result = pending.pop(0)
                    sizes[j].take(result)
            if size.due(t):
                given.append((t, k))
                if later:
                    pending.append((k, result_of(k, t)))
                else:
                    size.take(result_of(k, t))
    for j, result in pending:  # the end of the pass: every result taken
        sizes[j].take(result)
    return given


def test_three_uuvs_take_turns_on_one_schedule(cal_dict):
    sizes = _sizes(cal_dict, 3)
    rng = np.random.default_rng(1)
    given = _run(sizes, 3.0, lambda k, t: "poor_fit")  # never sure: 5 frames a second for the three
    assert len(given) == 15
    assert [k for _, k in given[:3]] == [0, 1, 2]
    # measurements in a row without a height put a UUV's turns off: uuv1 never gives one, the others always do
    sizes = _sizes(cal_dict, 3)
    given = _run(sizes, 6.0, lambda k, t: "poor_fit" if k == 0 else _height(t, 0.0, rng))
    turns = [sum(k == i for _, k in given) for i in range(3)]
    assert turns[0] <= 0.6 * min(turns[1:]) and abs(turns[1] - turns[2]) <= 1, turns
    assert sizes[0].rejected["poor_fit"] == turns[0] and sizes[1].measured == turns[1]
    # a UUV not tracked (not asking) leaves its turns to the others within a fifth of a second
    sizes = _sizes(cal_dict, 3)
    given = _run(sizes, 3.0, lambda k, t: "poor_fit", asking=lambda k, t: k != 1 or t < T0 + 1.0)
    late = [k for t, k in given if t >= T0 + 1.2]
    assert 1 not in late and len(late) >= 8 and {0, 2} <= set(late)


def test_a_uuv_whose_heights_disagree_is_left_out(cal_dict):
    """uuv2's depth is wrong: its heights are 0.6 m off the others'. It is named, its heights leave the estimate
    and it goes on with one of its own; in ``auto`` no telemetry gets heights while they disagree, uuv1's and
    uuv3's get theirs alone after, uuv2's its own."""
    sizes = _sizes(cal_dict, 3, "auto")
    rng = np.random.default_rng(2)
    results = {}  # (UUV, time) -> its measurement: the same in both runs

    def result_of(k, t):
        return results.setdefault((k, t), _height(t, 0.8 if k == 1 else 0.2, rng))

    given = _run(sizes, 20.0, result_of)
    assert sizes[1].left_out and not sizes[0].left_out and not sizes[2].left_out
    e = sizes[0].estimate
    assert e.sure and abs(e.bias_m - 0.2) < 2 * e.sigma_m and abs(e.bias_m - 0.2) < 0.05
    assert sizes[2].estimate is e and abs(sizes[1].estimate.bias_m - 0.8) < 0.05
    # uuv1's warning, if any, is that it and uuv2 disagree while uuv3 could not yet tell which is right
    assert sizes[1].warnings and not sizes[2].warnings, [s.warnings for s in sizes]
    assert all("uuv1's and uuv2's heights disagree" in w for w in sizes[0].warnings)
    assert (
        re.search(r"uuv2.s heights are 0\.[56]\d m below", sizes[1].warnings[0])
        and "uuv1, uuv3" in sizes[1].warnings[0]
    )
    assert (
        "uuv2's own" in sizes[1].summary() and "one estimate for uuv1, uuv3" in sizes[0].summary()
    )
    for s, height in zip(sizes, (9.8, 9.2, 9.8)):
        values = s.tel.height_fixes["size"].values[:, 0]
        assert s.applied == len(values) > 10 and np.all(np.abs(values - height) < 0.3), values
    # the results taken later, as measured beside the pass: the same frames measured, the same heights handed over
    later = _sizes(cal_dict, 3, "auto")
    assert _run(later, 20.0, result_of, later=True) == given
    for a, b in zip(sizes, later, strict=True):
        assert a.summary() == b.summary() and a.warnings == b.warnings
        fixes, later_fixes = a.tel.height_fixes["size"], b.tel.height_fixes["size"]
        np.testing.assert_array_equal(fixes.times, later_fixes.times)
        np.testing.assert_array_equal(fixes.values, later_fixes.values)


def test_two_uuvs_that_disagree_leave_the_estimate_unsure(cal_dict):
    sizes = _sizes(cal_dict, 2, "auto")
    rng = np.random.default_rng(3)
    _run(sizes, 20.0, lambda k, t: _height(t, 0.8 if k == 1 else 0.0, rng))
    assert not sizes[0].estimate.sure and not any(s.left_out for s in sizes)
    assert all("size" not in s.tel.height_fixes for s in sizes)
    assert (
        len(sizes[0].warnings) == 1
        and "uuv1's and uuv2's heights disagree by 0.8" in (sizes[0].warnings[0])
    )

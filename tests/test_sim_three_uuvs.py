"""A third vehicle (``[third_uuv]``, as ``[second_uuv]``) in ``three_uuvs_crossing``, checked without the localizer:
its own records under ``uuvs/uuv3/`` (a straight line at its speed and depth, its own depth samples, its first box
around its own track pixel), and the scenario's refusals (bench/uuvs.py's three-UUV session is made this way)."""

from __future__ import annotations

import shutil
import tomllib
from pathlib import Path

import numpy as np
import pymap3d
import pytest

from groundstation.session.depth import read_depth
from groundstation.session.read import PRIMARY_UUV, load_session, uuv_ids
from localizer.calibration import ConfigError
from sim_fixtures.generate import generate
from sim_fixtures.scenario import scenario_from_dict

SCENARIO = (
    Path(__file__).resolve().parents[1] / "sim_fixtures" / "scenarios" / "three_uuvs_crossing.toml"
)
THIRD = tomllib.loads(SCENARIO.read_text())["third_uuv"]
IDS = (PRIMARY_UUV, "uuv2", "uuv3")


def scenario(**changes):
    data = tomllib.loads(SCENARIO.read_text())
    return scenario_from_dict({**data, **changes})


def local_ne(sc, truth) -> np.ndarray:
    """truth.csv's horizontal positions in the scenario's world frame (north, east), by pymap3d's NED call."""
    s = sc.site
    n, e, _ = pymap3d.geodetic2ned(
        truth["lat"], truth["lon"], s.surface_amsl_m, s.lat_deg, s.lon_deg, s.surface_amsl_m
    )
    return np.column_stack([n, e])


def test_a_third_uuv_has_records_of_its_own(tmp_path):
    """Without video (2 s from 9 s to 11 s around its pass): three UUVs; uuv3's truth a straight line at its speed and
    depth, |miss_m| from uuv1 at the pass, apart from uuv2's; its depth samples its own (not uuv2's)."""
    sc = scenario(duration_s=2.0, third_uuv={**THIRD, "pass_at_s": 1.0})
    generate(sc, tmp_path / "s", video=False)
    assert uuv_ids(tmp_path / "s") == IDS
    s1, s2, s3 = (load_session(tmp_path / "s", uuv=i) for i in IDS)
    ne1, ne2, ne3 = (local_ne(sc, s.truth) for s in (s1, s2, s3))
    t = s3.truth["t"]
    step = np.linalg.norm(np.diff(ne3, axis=0), axis=1) / np.diff(t)
    assert np.allclose(step, THIRD["speed_mps"], rtol=1e-3), step
    way = (ne3[-1] - ne3[0]) / np.linalg.norm(ne3[-1] - ne3[0])
    off_line = way[0] * (ne3[:, 1] - ne3[0, 1]) - way[1] * (ne3[:, 0] - ne3[0, 0])
    assert np.abs(off_line).max() < 1e-3
    assert np.all(np.abs(s3.truth["depth_m"] - THIRD["depth_m"]) < 1e-6)
    at_pass = int(np.argmin(np.abs(t - t[0] - 1.0)))
    assert abs(np.linalg.norm(ne3[at_pass] - ne1[at_pass]) - 1.0) < 0.02
    assert np.linalg.norm(ne3 - ne2, axis=1).min() > 0.5
    d2, d3 = (
        np.array([r.depth_m for r in read_depth(tmp_path / "s" / "uuvs" / i / "depth.jsonl", [])])
        for i in IDS[1:]
    )
    assert np.all(np.abs(d3 - THIRD["depth_m"]) < 0.05) and not np.allclose(d2, d3)


@pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="needs the ffmpeg CLI")
def test_each_first_box_holds_its_own_vehicle(tmp_path):
    """Rendered (0.5 s at 480x270): uuv2's and uuv3's first boxes each hold their own track pixel, not the other's
    (the third vehicle's box comes after the second's)."""
    sc = scenario(duration_s=0.5)
    generate(sc, tmp_path / "s")
    sessions = {i: load_session(tmp_path / "s", uuv=i) for i in IDS}
    for i, s in sessions.items():
        x, y, w, h = s.calibration.init_bbox
        row = int(np.flatnonzero(s.track["t"] == s.calibration.init_t)[0])
        for j, other in sessions.items():
            inside = x <= other.track["u"][row] <= x + w and y <= other.track["v"][row] <= y + h
            assert inside == (i == j), (i, j, (x, y, w, h))


def test_a_third_uuv_is_refused_where_it_cannot_be():
    base = {**THIRD}
    data = tomllib.loads(SCENARIO.read_text())
    for changes, key in (
        (
            {
                "third_uuv": base,
                "second_uuv": {**data["second_uuv"], "enabled": False, "role": "lookalike"},
            },
            "third_uuv.enabled",
        ),
        ({"third_uuv": {**base, "id": "uuv2"}}, "third_uuv.id"),
        ({"third_uuv": {**base, "enabled": False}}, "third_uuv.role"),
        ({"third_uuv": {**base, "miss_m": 0.0, "depth_m": 0.95}}, "third_uuv.miss_m"),
        ({"third_uuv": {**base, "depth_m": 3.9}}, "third_uuv.depth_m"),
    ):
        with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
            scenario(**changes)

"""The tracker through the renderer's own wind waves (issue 28): 5 m/s, the UUV ~20 px, a downlink without B-frames.

A 3 s cut of ``waves_5mps_oblique`` (640x360, camera 20 degrees off nadir, the UUV 2 m deep; every ray refracted
through its facet, caustics and glint, x264 at 4 Mbit/s without B-frames) with a wider field of view: the UUV spans
about 20 px. The tracker before this test located it on 1 of 90 frames (the selection's own; measured): the
wave-distorted UUV's score fell below its bars at once (a lens of water magnifies, shrinks and breaks it up) and
no re-acquisition reached its bar. Now 90 of 90 (92 % of them within the claim below), and with the UUV hidden for
the last 1.5 s: 45 of 45 visible frames, none of the 45 hidden ones (measured; the downlink is encoded on one x264
thread, so each run renders the same video).
"""

from __future__ import annotations

import math
import shutil
import tomllib
from pathlib import Path

import numpy as np
import pytest

from groundstation.offline.track import track_session
from groundstation.session.read import load_session, read_table
from sim_fixtures.generate import generate
from sim_fixtures.scenario import scenario_from_dict

pytestmark = pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="needs the ffmpeg CLI")

SCENARIO = (
    Path(__file__).resolve().parents[1] / "sim_fixtures" / "scenarios" / "waves_5mps_oblique.toml"
)


def _session(path: Path, occlusions) -> Path:
    data = tomllib.loads(SCENARIO.read_text())
    data.update(name="waves_track_test", duration_s=3.0, occlusions=occlusions)
    data["camera"] = dict(data["camera"], hfov_deg=36.0)  # the UUV ~20 px
    generate(scenario_from_dict(data), path)
    return path


def _tracked(path: Path, with_sigma: bool = False):
    """(ok, visible, pixel error (px), the UUV's size (px)) per frame, tracked as ``skyfix process`` does; with
    ``with_sigma`` the tracker's claimed 1-sigma of each of u and v (px) too."""
    tracked = track_session(load_session(path))
    truth = read_table(path / "track.csv", ("t", "u", "v"), allow_empty=("u", "v"))
    box = load_session(path).calibration.init_bbox
    ok = tracked.status == "ok"
    return (
        ok,
        np.isfinite(truth["u"]),
        np.hypot(tracked.u - truth["u"], tracked.v - truth["v"]),
        max(box[2:]) - 6,
    ) + ((tracked.sigma_px,) if with_sigma else ())


def test_the_uuv_is_located_through_rendered_waves(tmp_path):
    """Located, and the tracker's claim covers its error through the waves: within twice the claimed DRMS (√2·σ,
    h_acc's reading) on at least 90 % of the frames reported ok. Without the sigma's jitter term (the match's score
    and size alone claimed 0.5-0.8 px of this 20 px UUV) 82 % of them were (measured)."""
    ok, visible, err, size_px, sigma_px = _tracked(_session(tmp_path / "s", []), with_sigma=True)
    assert 17 <= size_px <= 23 and visible.all()
    assert ok.mean() >= 0.95, ok.astype(int)
    assert np.all(err[ok] < 3 * size_px)  # no wrong lock
    assert np.median(err[ok]) < 4.0
    assert np.mean(err[ok] <= 2.0 * math.sqrt(2.0) * sigma_px[ok]) >= 0.9


def test_a_uuv_hidden_under_waves_is_reported_lost(tmp_path):
    ok, visible, err, size_px = _tracked(_session(tmp_path / "s", [[1.5, 3.0]]))
    assert visible[:45].all() and not visible[46:].any()
    assert ok[visible].mean() >= 0.9, ok.astype(int)
    assert not ok[~visible].any(), ok.astype(int)  # gone: no frame passes for it
    assert all(math.isfinite(e) and e < 3 * size_px for e in err[ok])

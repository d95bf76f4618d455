"""Offline tracking forward and backward (groundstation.offline.track, ``both_ways``) on a short rendered occlusion.

``oblique_occl`` cut to 4 s (640x360, camera 55 degrees down, the UUV 2 m deep) with the UUV hidden from 1.5 to
2.5 s. The forward, causal pass reports the UUV lost for a few frames after it shows again (searched for, the
candidate confirmed by the frames after it; measured: 87 of 90 visible frames located); traced back from the
re-acquisition, those frames are located too (measured: 90 of 90), each at the simulator's exact pixel, and none
of the hidden frames is.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from groundstation.offline.track import Kept, track_session, track_sessions
from groundstation.session.read import load_session
from sim_fixtures.generate import generate
from sim_fixtures.scenario import load_scenario, with_overrides

pytestmark = pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="needs the ffmpeg CLI")

SCENARIO = Path(__file__).resolve().parents[1] / "sim_fixtures" / "scenarios" / "oblique_occl.toml"


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    sc = with_overrides(load_scenario(SCENARIO), duration_s=4.0, occlusions=[[1.5, 2.5]])
    return load_session(generate(sc, tmp_path_factory.mktemp("occl") / "s").session)


def test_a_reacquisition_is_traced_back_through_the_frames_the_causal_pass_missed(
    session, monkeypatch
):
    causal = track_session(session)
    both = track_session(session, both_ways=True)
    visible = np.isfinite(session.track["u"])
    assert 20 <= (~visible).sum() <= 40 and not causal.bridged.any()
    ok_causal, ok_both = causal.status == "ok", both.status == "ok"
    assert ok_both[visible].sum() > ok_causal[visible].sum()  # more visible frames located ...
    # ... the causal pass's own unchanged ...
    assert np.array_equal(ok_both & ~both.bridged, ok_causal)
    assert not ok_both[~visible].any() and not both.bridged[~visible].any()  # ... none hidden
    assert set(causal.status[~visible]) == set(both.status[~visible]) == {"lost"}
    err = np.hypot(both.u - session.track["u"], both.v - session.track["v"])
    assert np.all(err[both.bridged] < 3.0)  # at the UUV's own pixel (it spans ~26 px)
    assert np.all(np.isfinite(both.sigma_px[ok_both]))
    assert np.array_equal(np.isnan(both.u), ~ok_both)
    # two UUVs lost in the same frames (the same one, read twice) keep one copy of each frame between them, and
    # each is traced back as alone
    kept, real = [], Kept.__call__
    monkeypatch.setattr(Kept, "__call__", lambda self: kept.append(real(self)) or kept[-1])
    twice = track_sessions([session, load_session(session.path)], both_ways=True)
    assert len(kept) >= 2 * (~visible).sum() and len({id(k) for k in kept}) * 2 == len(kept)
    for tracked in twice:
        assert np.array_equal(tracked.status, both.status)
        assert np.array_equal(tracked.u, both.u, equal_nan=True)

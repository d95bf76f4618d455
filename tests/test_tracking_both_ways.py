"""Offline tracking forward and backward (groundstation.offline.track, ``both_ways``) on short rendered occlusions.

- ``oblique_occl`` cut to 4 s (640x360, camera 55 degrees down, the UUV 2 m deep) with the UUV hidden from 1.5 to
  2.5 s. The forward, causal pass reports the UUV lost for a few frames after it shows again (searched for, the
  candidate confirmed by the frames after it; measured: 87 of 90 visible frames located); traced back from the
  re-acquisition, those frames are located too (measured: 90 of 90), each at the simulator's exact pixel, and none
  of the hidden frames is.
- Through 8 m/s of wind (bench/tracker_waves.py's ``w8_15px_3.4m`` with seed 2, cut to 7.5 s: the UUV 3.4 m deep
  and about 14 px, hidden from 5.0 to 6.5 s): as the UUV shows again the search by colour restarts the track on a
  place of the seafloor 47 px from it, the colour confirms it (``COLOUR_CONFIRM_FAR_FRAMES``) and the forward pass
  reports the frame after before the colour refutes the restart (its frames of the vehicle's colour too few to prove
  it, ``COLOUR_PROVEN_FRAMES``) and the track goes back to the UUV's last sighting. The match stands out of the
  seafloor there: traced back from it, the pass reported 22 frames before it on that place, 17 of them while the
  UUV was hidden (measured; with two frames of confirmation, 3 reported causally and 14 traced back). The frame
  reported on the restart claims it: twice its DRMS covers the 48 px to the UUV (the restart's distance from where
  the UUV was sought is in its sigma until it is proven; 10 px were claimed without). The frames
  traced back from a restart by colour are bridged only once it is proven (tests/test_tracking_both_ways_sure.py:
  when, on a scripted forward pass).
"""

from __future__ import annotations

import shutil
import tomllib
from pathlib import Path

import numpy as np
import pytest

from groundstation.offline.track import Kept, track_session, track_sessions
from groundstation.session.read import load_session
from sim_fixtures.generate import generate
from sim_fixtures.scenario import load_scenario, scenario_from_dict, with_overrides

pytestmark = pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="needs the ffmpeg CLI")

SCENARIOS = Path(__file__).resolve().parents[1] / "sim_fixtures" / "scenarios"
SCENARIO = SCENARIOS / "oblique_occl.toml"


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


def test_frames_traced_back_from_a_restart_by_colour_wait_for_its_proof(tmp_path):
    # bench/tracker_waves.py's w8_15px_3.4m_s2, cut to 7.5 s
    data = tomllib.loads((SCENARIOS / "waves_8mps_oblique.toml").read_text())
    data.update(name="w8", seed=2, duration_s=7.5, occlusions=[[5.0, 6.5]])
    data["uuv"] = dict(data["uuv"], depth_m=3.4, depth_swing_m=0.2)
    data["camera"] = dict(data["camera"], hfov_deg=76.85)
    session = load_session(generate(scenario_from_dict(data), tmp_path / "w8").session)
    truth = session.track
    half_px = (max(session.calibration.init_bbox[2:]) - 6) / 2  # the box is padded by 3 px a side
    both = track_session(session, both_ways=True)  # the causal pass's pixels where not bridged
    ok, visible = both.status == "ok", np.isfinite(truth["u"])
    off = ok & (np.hypot(both.u - truth["u"], both.v - truth["v"]) > half_px)
    assert 40 <= (~visible).sum() <= 50
    # the restart on the seafloor is reported causally (as live) ...
    assert 1 <= (off & ~both.bridged).sum() <= 3
    # ... with a claim that covers it (twice its DRMS)
    err = np.hypot(both.u - truth["u"], both.v - truth["v"])
    assert np.all(err[off] <= 2.0 * np.sqrt(2.0) * both.sigma_px[off]), (
        err[off],
        both.sigma_px[off],
    )
    # ... and not traced back
    assert not ok[~visible].any(), np.flatnonzero(ok & ~visible)
    assert not (both.bridged & off).any(), np.flatnonzero(both.bridged & off)
    assert both.bridged.sum() >= 10  # the waves' losses elsewhere still traced back

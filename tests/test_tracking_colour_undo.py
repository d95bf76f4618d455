"""A restart by colour the colour then refutes is undone (localizer/tracking/session.py, COLOUR_PROVEN_S).

bench/tracker_waves.py's w2_15px_1.0m condition cut to 7.5 s: ``waves_2mps_nadir`` (2 m/s of wind, camera at
nadir, 640x360) with the UUV 1 m deep and the field of view widened so it spans about 15 px, hidden from 5.0 to
6.5 s. During the occlusion the search by colour restarts the track on a place of the seafloor 50 px from the
UUV's last sighting that shows the vehicle's colour for a few frames as the waves play; the colour check then
refutes it on nearly every frame. Before the undo the track stayed on that place: every one of the 30 frames after
the UUV came back (45 px away) was lost (measured). Now the restart is undone, the track goes back to its search
from the last sighting, and the UUV is found again (27 of 30, measured).
"""

from __future__ import annotations

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
    Path(__file__).resolve().parents[1] / "sim_fixtures" / "scenarios" / "waves_2mps_nadir.toml"
)
HIDDEN_S = (5.0, 6.5)


def test_a_restart_on_the_seafloor_during_an_occlusion_is_undone(tmp_path):
    data = tomllib.loads(SCENARIO.read_text())
    data.update(name="colour_undo_test", duration_s=7.5, occlusions=[list(HIDDEN_S)])
    data["uuv"] = dict(data["uuv"], depth_m=1.0, depth_swing_m=0.2)
    data["camera"] = dict(data["camera"], hfov_deg=61.17)  # the UUV ~15 px
    generate(scenario_from_dict(data), tmp_path / "s")
    tracked = track_session(load_session(tmp_path / "s"))
    truth = read_table(tmp_path / "s" / "track.csv", ("t", "u", "v"), allow_empty=("u", "v"))
    ok, visible = tracked.status == "ok", np.isfinite(truth["u"])
    err = np.hypot(tracked.u - truth["u"], tracked.v - truth["v"])
    near = err <= 7.5  # half the UUV's size: on the vehicle's image
    before, after = (
        truth["t"] - truth["t"][0] < HIDDEN_S[0],
        truth["t"] - truth["t"][0] > HIDDEN_S[1],
    )
    assert (ok & near)[before & visible].mean() >= 0.95
    back = visible & after
    assert back.sum() >= 25  # the UUV came back in view
    located = (ok & near)[back].mean()
    assert located >= 0.8, f"{located:.0%} of the {back.sum()} frames after the occlusion located"
    assert not (ok & visible & ~near).any(), err[ok & visible & ~near]

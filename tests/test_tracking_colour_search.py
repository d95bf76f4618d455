"""The search by colour through waves (localizer/tracking/session.py), on cuts of bench/tracker_waves.py's renders.

- A restart by colour the colour then refutes is undone (``COLOUR_PROVEN_FRAMES``): the w2_15px_1.0m condition,
  ``waves_2mps_nadir`` (2 m/s of wind, camera at nadir, 640x360) with the UUV 1 m deep, the field of view widened so
  it spans about 15 px, hidden from 5.0 to 6.5 s. During the occlusion the search by colour restarts the track on a
  place of the seafloor 50 px from the UUV's last sighting that shows the vehicle's colour for a few frames as the
  waves play; the colour check refutes it on nearly every frame after. Before the undo the track stayed on that
  place: every one of the 30 frames after the UUV came back (45 px away) was lost (measured). Now 27 of 30. A later
  restart by colour while the UUV was still hidden showed the colour on the two frames after it too, and two hidden
  frames (at 6.1 s) were reported on it; a restart away from where the UUV was sought now waits for four
  (``COLOUR_CONFIRM_FAR_FRAMES``), and no hidden frame is reported.
- A configured wind makes the sea rough for the search from the start (``COLOUR_SEARCH_WIND_MPS``): the
  w5_15px_2.0m condition with seed 2, ``waves_5mps_oblique`` with the UUV 2 m deep and about 16 px. The matcher
  lost it in its first frames, its reading of the sea stayed at three follows' (0.43), and the UUV, standing out in
  its colour at the prediction, was never sought by it: 1 of 90 frames located (measured). With the wind 80 of 90;
  the rest were frames the matcher held (its best place under its bars, not yet a loss) at the prediction, the
  vehicle's colour standing out there: those are fixes now (``HELD_COLOUR_REACH``), 87 of 90.
- The frame a restart by colour happens on is a fix when the restart is near where the UUV was sought: the
  w5_15px_2.0m condition with seed 1 (the UUV about 12 px), cut to 3 s. Tracking restarts by colour twice, each
  time within ``HELD_COLOUR_REACH`` of the prediction, on frames reported lost before: 58 of 90 frames located,
  60 now, the two restart frames 3.8 and 1.7 px from the UUV (measured).
- A frame the matcher holds counts for a restart's confirmation where the vehicle's colour stands out there as a
  restart needs: the w5_25px_3.4m condition with seed 1 (the UUV 3.4 m deep, about 26 px), cut to 3 s. As the waves
  lose the UUV, tracking restarts by colour on it; the waves then hold its matches under the bars for a few frames
  at a time, and the restarts waited through them for frames the matcher found it in: 32 of 90 frames located, 46 now,
  none off the UUV (measured).
- A held frame is a fix where the UUV was sought when the vehicle's colour stands out there as a restart needs and
  the matcher held a place further off: the w2_35px_3.4m condition with seed 1 (the UUV 3.4 m deep, about 36 px),
  cut to 4 s. In three frames the matcher held a place of the seafloor beside the UUV while its colour stood out at
  the prediction: 99 of 120 frames located, 102 now, none off the UUV (measured).
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

SCENARIOS = Path(__file__).resolve().parents[1] / "sim_fixtures" / "scenarios"


def _located(out: Path, base: str, depth_m: float, hfov_deg: float, **keys):
    """Render ``base`` with the UUV at ``depth_m`` and the field of view ``hfov_deg`` (other scenario ``keys``
    replaced) into ``out`` and track it as ``skyfix process`` does: (times from the start (s), visible, ok and
    within half the UUV's size of it, ok and further, ok while hidden) per frame."""
    data = tomllib.loads((SCENARIOS / f"{base}.toml").read_text())
    data.update(name=out.name, **keys)
    data["uuv"] = dict(data["uuv"], depth_m=depth_m, depth_swing_m=0.2)
    data["camera"] = dict(data["camera"], hfov_deg=hfov_deg)
    generate(scenario_from_dict(data), out)
    session = load_session(out)
    tracked = track_session(session)
    truth = read_table(out / "track.csv", ("t", "u", "v"), allow_empty=("u", "v"))
    half_px = (max(session.calibration.init_bbox[2:]) - 6) / 2  # the box is padded by 3 px a side
    ok, visible = tracked.status == "ok", np.isfinite(truth["u"])
    near = np.hypot(tracked.u - truth["u"], tracked.v - truth["v"]) <= half_px
    return truth["t"] - truth["t"][0], visible, ok & near, ok & visible & ~near, ok & ~visible


def test_a_restart_on_the_seafloor_during_an_occlusion_is_undone(tmp_path):
    hidden_s = (5.0, 6.5)
    t, visible, located, wrong, hidden_ok = _located(
        tmp_path / "undo",
        "waves_2mps_nadir",
        1.0,
        61.17,  # the UUV ~15 px
        duration_s=7.5,
        occlusions=[list(hidden_s)],
    )
    assert located[visible & (t < hidden_s[0])].mean() >= 0.95
    back = visible & (t > hidden_s[1])
    assert back.sum() >= 25  # the UUV came back in view
    share = located[back].mean()
    assert share >= 0.8, f"{share:.0%} of the {back.sum()} frames after the occlusion located"
    assert not wrong.any(), np.flatnonzero(wrong)
    assert not hidden_ok.any(), np.flatnonzero(hidden_ok)


def _located_5mps(out: Path, hfov_deg: float, seed: int, depth_m: float = 2.0) -> np.ndarray:
    """3 s of ``waves_5mps_oblique`` with the UUV ``depth_m`` deep, in view throughout: per frame, located (no frame
    may be reported further from the UUV than half its size)."""
    _, visible, located, wrong, _ = _located(
        out, "waves_5mps_oblique", depth_m, hfov_deg, duration_s=3.0, occlusions=[], seed=seed
    )
    assert visible.all()
    assert not wrong.any(), np.flatnonzero(wrong)
    return located


def test_a_configured_wind_lets_the_colour_find_a_uuv_lost_at_the_start(tmp_path):
    located = _located_5mps(tmp_path / "wind", 49.82, seed=2)  # the UUV ~16 px
    assert located.mean() >= 0.93, f"{located.sum()} of {len(located)} frames located"


def test_a_restart_by_colour_near_the_prediction_is_a_fix_on_its_own_frame(tmp_path):
    located = _located_5mps(tmp_path / "near", 64.03, seed=1)  # the UUV ~12 px
    assert located.sum() >= 60, f"{located.sum()} of {len(located)} frames located"


def test_frames_the_matcher_holds_confirm_a_restart_by_colour(tmp_path):
    located = _located_5mps(tmp_path / "held", 43.26, seed=1, depth_m=3.4)  # the UUV ~26 px
    assert located.sum() >= 42, f"{located.sum()} of {len(located)} frames located"


def test_a_held_frame_is_a_fix_where_the_uuv_was_sought_when_its_colour_stands_out_there(tmp_path):
    _, visible, located, wrong, _ = _located(
        tmp_path / "sought", "waves_2mps_nadir", 3.4, 32.16, duration_s=4.0, occlusions=[], seed=1
    )  # the UUV ~36 px
    assert visible.all()
    assert not wrong.any(), np.flatnonzero(wrong)
    assert located.sum() >= 101, f"{located.sum()} of {len(located)} frames located"

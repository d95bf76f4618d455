"""``skyfix process --pose-from-bottom auto`` on a short rendered session against the simulator's truth.

``bottom_follow`` (the UAV flies after a UUV over a textured floor; the gimbal's levelling error 0.2/-0.2°, the
compass's bias 2°) on plain GNSS (a 1.2 m walk + 3 cm white), 8 s at 640x360, pixels from track.csv: the camera's
attitude error the estimate finds is checked against ``truth_errors.csv`` (the simulator's own, reported − true), the
corrected track against ``truth.csv``, and what positions.csv, pose_from_bottom.json and the fix message say against
what was applied.
"""

from __future__ import annotations

import csv
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from groundstation.cli import main
from groundstation.messages import FixMessage
from groundstation.offline.bottom import NAME, bias_headings
from groundstation.offline.evaluate import error_ne_m, shape_m
from groundstation.session.positions import read_positions_csv
from groundstation.session.read import load_session
from localizer.bottom import in_bias_frame
from localizer.fix import POSE_COLUMNS
from localizer.pose import camera_pose
from sim_fixtures.generate import generate
from sim_fixtures.scenario import load_scenario, with_overrides

SCENARIO = Path(__file__).parents[1] / "sim_fixtures" / "scenarios" / "bottom_follow.toml"


@pytest.fixture(scope="module")
def processed(tmp_path_factory):
    """The session, and positions.csv's folder without and with the estimate."""
    root = tmp_path_factory.mktemp("bottom")
    sc = with_overrides(load_scenario(SCENARIO), duration_s=8.0, sensors={"gnss_mode": "plain"})
    session = root / "session"
    generate(sc, session, video=True)
    outs = {}
    for mode in ("off", "auto"):
        outs[mode] = root / mode
        args = ["process", str(session), "--use-track", "--quiet", "--out", str(outs[mode])]
        assert main([*args, "--pose-from-bottom", mode]) == 0
    return session, outs


def _errors(session: Path, out: Path):
    fixes = read_positions_csv(out / "positions.csv")
    truth = load_session(session, "uuv1").truth
    err = error_ne_m(fixes.t_unix, fixes.lat, fixes.lon, fixes.status == "ok", truth)
    return fixes, err


def _pose_columns(out: Path) -> dict[str, np.ndarray]:
    with open(out / "positions.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    return {
        c: np.array(
            [r[c] for r in rows] if c == "pose_source" else [float(r[c] or "nan") for r in rows]
        )
        for c in POSE_COLUMNS
    }


def test_the_biases_found_are_the_simulators(processed):
    session, outs = processed
    found = json.loads((outs["auto"] / NAME).read_text())
    assert found["applied"] == {"tilt": True, "heading": True, "walk": True}
    s = load_session(session, "uuv1")
    te = np.genfromtxt(session / "truth_errors.csv", delimiter=",", names=True)
    pose = camera_pose(s.calibration, s.telemetry, te["t"])
    ned = np.column_stack([te["cam_err_n_deg"], te["cam_err_e_deg"], te["cam_err_d_deg"]])
    fwd, right, heading = np.median(
        in_bias_frame(ned, bias_headings(s, pose, found["tilt_frame"])), axis=0
    )
    # within twice the claimed sigma, and the sigma itself small against the biases (0.2° tilt, 2° heading)
    assert abs(found["heading_deg"] - heading) < 2 * found["sigma_heading_deg"]
    assert found["sigma_heading_deg"] < 0.6
    for est, true in ((found["tilt_fwd_deg"], fwd), (found["tilt_right_deg"], right)):
        assert abs(est - true) < 2 * found["sigma_tilt_deg"]
    assert found["sigma_tilt_deg"] < 0.25
    assert abs(found["floor_depth_m"] - 4.0) < 3 * found["sigma_floor_depth_m"]


def test_a_plain_gnss_track_gets_its_shape_from_the_floor(processed):
    session, outs = processed
    _, err_off = _errors(session, outs["off"])
    fixes, err_on = _errors(session, outs["auto"])
    assert shape_m(err_on) < 0.4 * shape_m(err_off)  # measured 0.008 against 0.039 m
    e = np.hypot(*err_on.T)
    ok = np.isfinite(e)
    assert ok.sum() > 200
    # the constant offset stays the GNSS's (the floor cannot see it), the claim covers it
    assert np.mean(e[ok] <= 2 * fixes.h_acc_m[ok]) >= 0.9


def test_positions_and_the_fix_message_say_what_was_applied(processed):
    _, outs = processed
    found = json.loads((outs["auto"] / NAME).read_text())
    cols = _pose_columns(outs["auto"])
    assert set(cols["pose_source"]) == {"bottom"}
    # the heading taken off is the estimate's, its sigma the one in h_acc
    assert np.allclose(cols["cam_err_d_deg"], found["heading_deg"], atol=1e-3)
    assert np.allclose(cols["sigma_yaw_deg"], found["sigma_heading_deg"], atol=1e-3)
    assert np.allclose(cols["sigma_tilt_deg"], found["sigma_tilt_deg"], atol=1e-3)
    assert np.all(np.isfinite(cols["walk_n_m"])) and np.all(cols["sigma_walk_m"] > 0)
    # the walk is about the GNSS's mean: no constant shift
    assert abs(np.mean(cols["walk_n_m"])) < 0.05 and abs(np.mean(cols["walk_e_m"])) < 0.05
    with open(outs["off"] / "positions.csv", newline="") as f:
        assert not set(POSE_COLUMNS) & set(next(csv.reader(f)))

    fixes = read_positions_csv(outs["auto"] / "positions.csv")
    i = int(np.flatnonzero(fixes.status == "ok")[0])
    fix = dataclasses.replace(
        fixes[i],
        **{c: (str(v[i]) if c == "pose_source" else float(v[i])) for c, v in cols.items()},
    )
    message = FixMessage.model_validate(FixMessage.of(fix).to_json())
    assert message.pose_source == "bottom"
    assert message.cam_err_d_deg == pytest.approx(cols["cam_err_d_deg"][i])
    assert message.sigma_walk_m == pytest.approx(cols["sigma_walk_m"][i])
    assert message.to_fix().walk_e_m == pytest.approx(cols["walk_e_m"][i])
    told = FixMessage.of(fixes[i]).to_json()  # nothing estimated: null, as a live run's
    assert told["pose_source"] is None and told["cam_err_d_deg"] is None

"""The web page's map (groundstation/live/ui/topview.py) on bundled sessions' telemetry.

The camera's footprint, projected back into the image with the simulator's own projection (OpenCV's
projectPoints with the lens's distortion, not the localizer's ray code), lies on the image's outline, top edge
first; the track keeps ok fixes at most one per 0.1 s, in metres from the UAV's first position (pymap3d), each
sent once; the safety gates' track is placed the same way.
"""

from __future__ import annotations

import tomllib

import numpy as np
import pymap3d
import pytest
from live_helpers import ROOT

from groundstation.live.ui.topview import EDGE_SAMPLES, TopView
from groundstation.session.read import load_session
from localizer.fix import Fix
from localizer.pose import camera_pose
from sim_fixtures.generate import camera_of
from sim_fixtures.geometry import project
from sim_fixtures.scenario import scenario_from_dict

BUNDLED = ROOT / "sim_fixtures" / "bundled"


@pytest.mark.parametrize("name", ["nadir_hover", "oblique_2m", "vehicle_yaw"])
def test_the_footprint_is_the_images_outline_on_the_water(name):
    session = load_session(BUNDLED / name)
    sim_camera = camera_of(
        scenario_from_dict(tomllib.loads((BUNDLED / name / "scenario.toml").read_text()))
    )
    view = TopView(session.calibration, session.telemetry)
    t = float(session.frames["t"][100])
    view.on_fix(Fix(t, "lost"), None)  # the newest frame's time, no position
    snap = view.snapshot(t + 60.0)  # "now" is ignored once a frame was seen
    assert snap["pose"] == "ok" and snap["uav"] == [0.0, 0.0] and not snap["horizon"]
    pose = camera_pose(session.calibration, session.telemetry, t)
    assert snap["origin"] == {
        "lat": round(float(pose.lat_deg[0]), 8),
        "lon": round(float(pose.lon_deg[0]), 8),
    }
    footprint = np.array(snap["footprint"])
    assert footprint.shape == (4 * EDGE_SAMPLES, 2) and snap["top_edge"] == EDGE_SAMPLES
    camera_ned = np.array([*pose.cam_offset_ned_m[0, :2], 0.0])
    water = np.column_stack([footprint, np.full(len(footprint), pose.height_m[0])])
    u, v = project(sim_camera, pose.R_ned_from_cv[0], camera_ned, water)
    w, h = sim_camera.width, sim_camera.height
    off_border = np.minimum.reduce(
        [abs(u + 0.5), abs(u - (w - 0.5)), abs(v + 0.5), abs(v - (h - 0.5))]
    )
    assert off_border.max() < 0.05, (
        off_border.max()
    )  # footprint points are rounded to the millimetre
    # top edge
    assert np.allclose(v[:EDGE_SAMPLES], -0.5, atol=0.05) and np.all(np.diff(u[:EDGE_SAMPLES]) > 0)
    # then the right edge, clockwise
    assert np.allclose(u[EDGE_SAMPLES : 2 * EDGE_SAMPLES], w - 0.5, atol=0.05)


def test_the_track_keeps_ok_fixes_sent_once():
    session = load_session(BUNDLED / "nadir_hover")
    view = TopView(session.calibration, session.telemetry, min_dt_s=0.1)
    t0 = float(session.frames["t"][50])
    assert view.points_since(0) == []
    for i in range(12):  # a frame every 45 ms: every third is kept, and the lost one is not
        t = t0 + i * 0.045
        view.on_fix(
            Fix(t, "lost" if i == 3 else "ok", lat=63.44 + i * 1e-6, lon=10.4, h_acc_m=0.2), None
        )
    assert view.points_since(0) == []  # no origin before the map was drawn once
    snap = view.snapshot(0.0)
    lat0, lon0 = snap["origin"]["lat"], snap["origin"]["lon"]
    points = view.points_since(0)
    kept = [0, 4, 7, 10]  # ≥ 0.1 s apart, skipping the lost frame
    assert [p[4] for p in points] == [round(t0 + i * 0.045, 3) for i in kept]
    n, e, _ = pymap3d.geodetic2ned(63.44 + np.array(kept) * 1e-6, 10.4, 0.0, lat0, lon0, 0.0)
    assert np.allclose([p[1] for p in points], n, atol=1e-3) and np.allclose(
        [p[2] for p in points], e, atol=1e-3
    )
    assert all(p[3] == 0.2 for p in points)
    assert view.points_since(points[-1][0]) == []
    view.on_fix(Fix(t0 + 1.0, "ok", lat=63.44, lon=10.4, h_acc_m=0.3), None)
    assert [p[3] for p in view.points_since(points[-1][0])] == [0.3]


def test_the_gates_track_is_placed_like_the_fixes():
    session = load_session(BUNDLED / "nadir_hover")
    view = TopView(session.calibration, session.telemetry)
    gates = {
        "state": "acquiring",
        "reach_m": 1.5,
        "track": {
            "lat": 63.44001,
            "lon": 10.40002,
            "vn_mps": 0.1,
            "ve_mps": -0.2,
            "sigma_n_m": 0.3,
            "sigma_e_m": 0.2,
            "cov_ne_m2": 0.01,
        },
    }
    assert view.gate_view(None) is None
    assert view.gate_view(gates) == {
        "state": "acquiring",
        "reach_m": 1.5,
        "track": None,
    }  # no origin yet
    snap = view.snapshot(float(session.frames["t"][10]))
    shown = view.gate_view(gates)
    n, e, _ = pymap3d.geodetic2ned(
        63.44001, 10.40002, 0.0, snap["origin"]["lat"], snap["origin"]["lon"], 0.0
    )
    assert shown["track"]["n"] == pytest.approx(n, abs=1e-3) and shown["track"][
        "e"
    ] == pytest.approx(e, abs=1e-3)
    assert (shown["track"]["vn"], shown["track"]["sigma_e"], shown["track"]["cov_ne"]) == (
        0.1,
        0.2,
        0.01,
    )

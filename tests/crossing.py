"""The ``two_uuvs_crossing`` scenario as the tracking tests generate it: cut to 6 s, without TIMESYNC (the frames'
offset to the telemetry estimated from the video's motion), the camera fixed at -88° on a UAV wobbling 2° at 1.2 Hz.
"""

from pathlib import Path

from sim_fixtures.generate import generate
from sim_fixtures.scenario import load_scenario, with_overrides

SCENARIO = (
    Path(__file__).resolve().parents[1] / "sim_fixtures" / "scenarios" / "two_uuvs_crossing.toml"
)


def crossing_session(tmp_path_factory, **uav) -> Path:
    """The session generated into a new temporary folder; ``uav``: the UAV's scenario keys besides its wobble."""
    sc = with_overrides(
        load_scenario(SCENARIO),
        duration_s=6.0,
        mount={"attitude_source": "fixed", "fixed_rpy_deg": [0.0, -88.0, 0.0]},
        uav={"wobble_deg": 2.0, "wobble_hz": 1.2, **uav},
        telemetry={"timesync_hz": 0.0},
    )
    path = tmp_path_factory.mktemp("crossing") / "s"
    generate(sc, path)
    return path

"""The mosaic of the bottom growing live (groundstation/live/mosaic_live.py): ``skyfix run --live-mosaic
--floor-depth-m`` over the replay of a generated session (bottom_survey's drone without its attitude errors, 3 s at
640x360, a textured floor with a surveyed bullseye) serves the mosaic as the page's base map at /basemap/Z/X/Y
on 127.0.0.1; the bullseye found in those tiles lies where reference.toml says (pyproj's web Mercator, not the
localizer's geometry); the status (its schema's) counts the frames painted and skipped. A run asking for it without a floor
depth is refused in one line naming the key."""

import json
import math
from urllib.parse import parse_qs, urlsplit

import pytest
from jsonschema import Draft202012Validator
from live_helpers import ROOT, LiveRun, read_jsonl, skyfix, ui_url, wait_for
from test_mosaic import NO_POSE_ERRORS, marker_error_in_tiles
from test_ui_access import _get
from ui_browser import available, chromium

from groundstation.contracts import GROUNDSTATION
from sim_fixtures.generate import generate
from sim_fixtures.scenario import load_scenario, with_overrides


@pytest.fixture(scope="module")
def survey(tmp_path_factory):
    """bottom_survey without attitude errors, 3 s at 640x360, with its bullseye; and its scenario."""
    session = tmp_path_factory.mktemp("survey")
    sc = load_scenario(ROOT / "sim_fixtures" / "scenarios" / "bottom_survey.toml")
    sc = with_overrides(
        sc,
        duration_s=3.0,
        camera={"width": 640, "height": 360},
        marker={"enabled": True},
        sensors=NO_POSE_ERRORS,
    )
    generate(sc, session)
    return session, sc


def test_the_live_mosaic_serves_the_marker_where_it_was_surveyed(survey, tmp_path):
    import subprocess
    import tomllib

    session, sc = survey
    ref = tomllib.loads((session / "reference.toml").read_text())
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    with LiveRun(
        run_dir,
        session,
        "--live-mosaic",
        "--floor-depth-m",
        str(sc.site.floor_depth_m),
        "--live-mosaic-every-s",
        "0.2",
        video_latency_ms=0,
    ) as live:
        base = ui_url(run_dir / "run.log").rstrip("/")
        wait_for(lambda: live.replay.poll() is not None, 40, "the replay's end")

        def mosaic_status() -> dict:
            status, _, body = _get(f"{base}/api/status")
            assert status == 200
            return json.loads(body)["live_mosaic"]

        wait_for(lambda: mosaic_status()["painted"] >= 3, 20, "three frames painted")
        st = mosaic_status()
        lat = math.radians(ref["lat_deg"])
        z = math.ceil(math.log2(2 * math.pi * 6378137.0 * math.cos(lat) / 256 / st["gsd_m"]))

        def tile(z, x, y):
            status, _, body = _get(f"{base}/basemap/{z}/{x}/{y}?v={st['painted']}")
            assert status in (200, 404), status
            return body if status == 200 else None

        error_m, pixel_m = marker_error_in_tiles(tile, z, ref)
        live.finish()
    print(
        f"live mosaic: {st['painted']} frames painted, {st['skipped']} skipped, cells {st['gsd_m']} m; "
        f"marker in the zoom-{z} tiles {error_m:.3f} m (tile pixel {pixel_m:.3f} m)"
    )
    assert error_m <= 3 * st["gsd_m"] + pixel_m, (error_m, st)
    # its status section on Zenoh, as the status schema has it
    schema = Draft202012Validator(json.loads(GROUNDSTATION.path_of("status").read_text()))
    status = [
        json.loads(s["payload"]) for s in read_jsonl(live.sub_out) if s["key"] == "skyfix/status"
    ]
    assert status[-1]["live_mosaic"]["painted"] >= st["painted"]
    assert [e.message for m in status for e in schema.iter_errors(m)] == []

    refused = subprocess.run(
        skyfix("run", "--calibration", str(session / "session.toml"), "--live-mosaic", "--video", "none",
               "--gps-input", "none", "--no-ui"),
        capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert refused.returncode == 2
    assert "--live-mosaic = True: needs the floor's depth: --floor-depth-m" in refused.stderr
    assert len(refused.stderr.strip().splitlines()) == 1


@pytest.mark.skipif(available() is not None, reason=str(available()))
def test_the_page_fetches_the_mosaics_tiles_anew_as_it_grows(survey, tmp_path):
    """In Chromium: the page asks for the live mosaic's tiles with the version of each painted frame, loads them,
    and asks nothing of another machine."""
    session, sc = survey
    with LiveRun(
        tmp_path,
        session,
        "--live-mosaic",
        "--floor-depth-m",
        str(sc.site.floor_depth_m),
        "--live-mosaic-every-s",
        "0.2",
        video_latency_ms=0,
        replay_now=False,
    ) as live:
        url = ui_url(tmp_path / "run.log")
        with chromium(tmp_path, url.split("?")[0].rstrip("/")) as browser:
            page = browser.page
            page.goto(url)
            page.wait_for_selector("#conn.ok", timeout=20_000)
            live.start_replay()

            def versions() -> set[str]:
                page.evaluate("0")  # the browser's events (its requests) handed over
                return {
                    parse_qs(urlsplit(u).query).get("v", [""])[0]
                    for u in browser.requests
                    if "/basemap/" in u
                } - {""}

            wait_for(
                lambda: len(versions()) >= 2, 30, "tiles of two versions of the mosaic asked for"
            )
            wait_for(
                lambda: page.eval_on_selector("#map", "m => m.dataset.tiles") == "loaded",
                20,
                "the mosaic's tiles loaded",
            )
            assert not browser.errors, browser.errors
            assert browser.outside == []
            asked = sorted(versions(), key=int)
        live.finish(early=True)
    print(f"tile versions asked for: {asked}")


def test_the_mosaic_is_painted_in_a_nicer_process(tmp_path):
    """The painting and the tiles run in a process of their own 10 nice levels below the service, at least at nice 10
    (a thread of the service painting at a low priority held the interpreter's lock while it waited for a core beside
    busy programs), and a tile from it is byte for byte the same painter's in this process."""
    import itertools
    import multiprocessing
    import os

    from groundstation.live.mosaic_live import LiveMosaic, MosaicPainter
    from groundstation.map.tiles import tile_of
    from groundstation.session.read import load_session
    from groundstation.video.file import open_video
    from localizer.pose import uav_pose

    session = load_session(ROOT / "sim_fixtures" / "bundled" / "nadir_hover")
    cal, tel = session.calibration, session.telemetry
    with open_video(session.video_path) as video:
        frames = [
            (float(session.frames["t"][f.index]), f.image)
            for f in itertools.islice(video, 31)
            if f.index % 30 == 0
        ]
    poses = [uav_pose(cal, tel, t) for t, _ in frames]
    before = set(multiprocessing.active_children())
    live = LiveMosaic(cal, tel, 2.0, 1.0)
    try:
        for (_, image), pose in zip(frames, poses):
            live._paint_frame(image, pose)  # its EveryFrame thread's work
        children = [c for c in multiprocessing.active_children() if c not in before]
        assert len(children) == 1
        assert os.getpriority(os.PRIO_PROCESS, children[0].pid) == min(
            max(os.getpriority(os.PRIO_PROCESS, 0) + 10, 10), 19
        )
        z = live.info()["maxzoom"]
        xy = tile_of(float(poses[0].lat_deg[0]), float(poses[0].lon_deg[0]), z)
        served = live.tile(z, *xy)
    finally:
        live.close()
    in_process = MosaicPainter(cal, 2.0, tmp_path)
    for (_, image), pose in zip(frames, poses):
        in_process.paint_frame(image, pose)
    assert live.painted == 2 and live.grid == in_process.grid
    assert served is not None and served == in_process.tile(z, *xy)

"""The operator's web page in a real headless Chromium (Debian's, driven by Playwright) against ``skyfix replay`` →
``skyfix run`` on loopback, started without init_bbox (nadir_hover).

What an operator does, with the mouse: the page loads with nothing from outside (every request is to the
service; host names do not resolve); video frames arrive with the status word drawn on them; a box dragged on
open water is refused with the reason shown, and GPS_INPUT stays "no fix"; a box dragged around the UUV (its
true pixel from the simulator's track.csv at the exposure time of the frame on screen, through the replay's
printed time shift) selects it on that very frame, and ``ok`` fixes follow, near the truth; the map (track,
footprint, the last fix's lat/lon) and health (per-input rates, GPS_INPUT's fix_type, clocks, CPU) panels fill
in, with the safety gates tracking the UUV (header, health, the track on the map); a click on the UUV re-selects
it; "Release target" turns GPS_INPUT to "no fix" and the gates to acquiring. Screenshots of each step are kept (out/ui-screenshots/).

The header tells the truth at a glance: what GPS_INPUT sends now and why not a fix, within 2 s of every input
being cut, and a grey page with "no status since" once the service is gone.
"""

from __future__ import annotations

import re
import time
from urllib.parse import urlsplit

import pytest
from live_helpers import ROOT, LiveRun, stop, track_pixel, ui_url, wait_for
from ui_browser import available, chromium

SESSION = ROOT / "sim_fixtures" / "bundled" / "nadir_hover"
VIDEO_LATENCY_MS = 0  # the replay sends each frame at its exposure time (see test_live_e2e)
UUV_BOX = (33, 34)  # the vehicle's size in this session (pixels)
WATER_BOX = (
    40.0,
    290.0,
    33.0,
    34.0,
)  # open water, far from the UUV (which stays near the image centre)

pytestmark = pytest.mark.skipif(available() is not None, reason=str(available()))


def _dataset(page, key: str) -> str | None:
    return page.eval_on_selector("#video", f"c => c.dataset.{key}")


def _drag(page, box: tuple[float, float, float, float], camera_width: int) -> None:
    """Drag from the box's top-left corner to its bottom-right one (image pixels: x is the left edge of the box's
    first column)."""
    r = page.eval_on_selector(
        "#video", "c => { const r = c.getBoundingClientRect(); return [r.left, r.top, r.width]; }"
    )
    s = r[2] / camera_width
    x, y, w, h = box
    page.mouse.move(r[0] + x * s, r[1] + y * s)
    page.mouse.down()
    page.mouse.move(r[0] + (x + w) * s, r[1] + (y + h) * s, steps=4)
    page.mouse.up()


def _select_on_shown_frame(page, live: LiveRun, camera_width: int) -> dict:
    """Drag a box around the UUV on the frame the page shows; returns that frame's number and time."""
    end = time.time() + 10.0
    while time.time() < end:
        if (
            _dataset(page, "status") != "awaiting_target"
        ):  # a frame out of the decoder's buffer: its time is unknown
            time.sleep(0.03)
            continue
        frame, t = int(_dataset(page, "frame")), float(_dataset(page, "t"))
        u, v = track_pixel(SESSION, t - live.shift)
        w, h = UUV_BOX
        r = page.eval_on_selector(
            "#video",
            "c => { const r = c.getBoundingClientRect(); return [r.left, r.top, r.width]; }",
        )
        s = r[2] / camera_width
        x, y = u - (w - 1) / 2, v - (h - 1) / 2  # the box's first column and row
        page.mouse.move(r[0] + x * s, r[1] + y * s)
        page.mouse.down()  # the page holds the frame on screen from here on
        if (
            int(_dataset(page, "frame")) != frame
        ):  # a newer frame came in between: let go and try again
            page.keyboard.press("Escape")
            page.mouse.up()
            continue
        assert _dataset(page, "frozen") == "1"
        page.mouse.move(r[0] + (x + w) * s, r[1] + (y + h) * s, steps=4)
        page.mouse.up()
        return {"frame": frame, "t": t, "box": (x, y, w, h)}
    raise AssertionError("no frame with a known exposure time stayed on screen under the mouse")


def test_operator_selects_tracks_and_releases_in_the_browser(tmp_path):
    with LiveRun(
        tmp_path,
        SESSION,
        "--select-history-s",
        "2",
        video_latency_ms=VIDEO_LATENCY_MS,
        replay_now=False,
    ) as live:
        url = ui_url(tmp_path / "run.log")
        origin = f"{urlsplit(url).scheme}://{urlsplit(url).netloc}"
        assert urlsplit(url).hostname == "127.0.0.1" and "token" not in url  # localhost: no token
        with chromium(tmp_path, origin) as browser:
            page = browser.page
            page.goto(url)
            page.wait_for_selector("#conn.ok", timeout=20_000)
            browser.screenshot("1-before-video")
            live.start_replay()
            camera_width = 640

            # frames arrive, past the burst out of the decoder's buffer (no exposure time), awaiting a target
            wait_for(
                lambda: (
                    int(_dataset(page, "received") or 0) >= 3
                    and _dataset(page, "status") == "awaiting_target"
                ),
                25,
                "video frames awaiting a target",
            )

            # a box on open water: refused, the reason shown, nothing tracked
            _drag(page, WATER_BOX, camera_width)
            page.wait_for_selector("#cmd-result.bad", timeout=10_000)
            refusal = page.inner_text("#cmd-result")
            assert "no vehicle-sized object stands out of the water" in refusal, refusal
            t_water = time.time()
            wait_for(
                lambda: sum(g["t_recv"] > t_water for g in live.gps_input()) >= 3,
                15,
                "GPS_INPUT after the refusal",
            )
            browser.screenshot("2-box-on-water-refused")

            # a box around the UUV, on the frame on screen
            t_selecting = time.time()
            chosen = _select_on_shown_frame(page, live, camera_width)
            page.wait_for_selector("#cmd-result.ok", timeout=10_000)
            answer = page.inner_text("#cmd-result")
            assert re.fullmatch(
                rf"selected on frame {chosen['frame']} \(caught up \d+\): tracking", answer
            ), answer
            wait_for(
                lambda: (
                    _dataset(page, "status") == "ok"
                    and page.inner_text("#status-word") == "ok"
                    and "last fix_type 3 (fix)" in page.inner_text("#health")
                    and int(page.eval_on_selector("#map", "m => m.dataset.points")) >= 3
                ),
                10,
                "the page showing ok fixes: on the video, in the header, on the map and in GPS_INPUT's health",
            )
            browser.screenshot("3-tracking")
            fix_text = page.inner_text("#fix-text")
            assert re.match(r"UUV 63\.44\d{5}, 10\.\d{7} ± 0\.\d\d m", fix_text), fix_text
            health = page.inner_text("#health")
            rates = {
                m[1]: float(m[2])
                for m in re.finditer(
                    r"(ATTITUDE|GLOBAL_POSITION_INT)\s+[\d.]+ s\s+([\d.]+) Hz", health
                )
            }
            assert rates.get("ATTITUDE", 0) > 10 and rates.get("GLOBAL_POSITION_INT", 0) > 3, health
            assert "last fix_type 3 (fix)" in health and re.search(
                r"video\s+\S+\s+[\d.]+ s\s+[1-9][\d.]* fps", health
            )
            assert re.search(r"UAV link [\d.]+ ms \(timesync ± 0\.0 ms", health), health
            assert re.search(
                rf"video latency {VIDEO_LATENCY_MS} ms \(configured; image motion", health
            ), health
            assert re.search(r"CPU\s+\d+ % of one core", health), health
            # the camera's height from the UUV's size (--height-from-size check): the frames measured, or why not
            # (the measuring process may still be starting on a loaded machine: wait for its first answer)
            wait_for(
                lambda: (
                    (
                        m := re.search(
                            r"height from size.*· check · (\d+) measured, (\d+) without",
                            page.inner_text("#health"),
                        )
                    )
                    and int(m[1]) + int(m[2]) > 0
                ),
                30,
                "the height-from-size row with a frame measured or refused",
            )
            map_info = page.inner_text("#map-info")
            assert (
                re.search(r"camera \d+\.\d m above the water", map_info)
                and "no footprint" not in map_info
            )
            # the safety gates: tracking, in the header, the health table and on the map (the track's diamond)
            assert page.inner_text("#gate-state") == "gates tracking"
            gates = re.search(
                r"safety gates\s+ok\s+.*?tracking · (\d+) accepted · refused: .*unconfirmed (\d+).*"
                r"track [\d.]+ m/s, ± [\d.]+ m \(own [\d.]+ m\)",
                health,
            )
            assert gates and int(gates[1]) > 0 and int(gates[2]) >= 10, health
            assert page.eval_on_selector("#map", "m => m.dataset.gate") == "tracking"

            # the selection's valid GPS_INPUT before the click: a re-selection is a new lock, confirmed again
            wait_for(
                lambda: sum(g["fix_type"] == 3 for g in live.gps_input()) >= 10,
                20,
                "ten valid GPS_INPUT from the selection",
            )
            # a click on the UUV re-selects it there
            frame = int(_dataset(page, "frame"))
            u, v = track_pixel(SESSION, float(_dataset(page, "t")) - live.shift)
            r = page.eval_on_selector(
                "#video",
                "c => { const r = c.getBoundingClientRect(); return [r.left, r.top, r.width]; }",
            )
            page.mouse.click(
                r[0] + (u + 0.5) * r[2] / camera_width, r[1] + (v + 0.5) * r[2] / camera_width
            )
            wait_for(
                lambda: (
                    (
                        m := re.fullmatch(
                            r"selected on frame (\d+) \(caught up \d+\): tracking",
                            page.inner_text("#cmd-result"),
                        )
                    )
                    and int(m[1]) >= frame
                ),
                10,
                "the click's answer",
            )  # on that frame, or the next if it came in before the click
            wait_for(
                lambda: page.inner_text("#target-state") == "target tracking (click)",
                15,
                "the click's target",
            )

            # release: no fix until a new selection
            page.click("#release")
            wait_for(
                lambda: "release: released" in page.inner_text("#cmd-result"),
                10,
                "the release's answer",
            )
            t_released = time.time()
            wait_for(
                lambda: page.inner_text("#target-state") == "target released (click)",
                15,
                "the page showing the target released",
            )
            wait_for(
                lambda: (
                    (h := _header(page))["sending"] == "NO FIX"
                    and h["sending-why"] == "target released"
                ),
                10,
                lambda: f"the header saying no fix, the target released: {_header(page)}",
            )
            wait_for(
                lambda: (
                    sum(
                        g["fix_type"] == 1 and g["t_recv"] > t_released + 0.3
                        for g in live.gps_input()
                    )
                    >= 3
                ),
                10,
                "GPS_INPUT without a fix after the release",
            )
            wait_for(
                lambda: (
                    page.inner_text("#gate-state") == "gates acquiring"
                    and page.eval_on_selector("#map", "m => m.dataset.gate") == "acquiring"
                ),
                20,
                lambda: (
                    "the gates acquiring again after the release; the page shows "
                    f"{page.inner_text('#gate-state')!r}, the map "
                    f"{page.eval_on_selector('#map', 'm => m.dataset.gate')!r}"
                ),
            )
            browser.screenshot("4-released")
            assert not browser.errors, browser.errors
            assert browser.outside == [] and all(u.startswith(origin) for u in browser.requests), (
                browser.requests
            )
        live.finish()

    fixes = live.fixes()
    gps = live.gps_input()
    # nothing but "no fix" until the operator's selection (the box on water changed nothing)
    before = [g for g in gps if g["t_recv"] < t_selecting]
    assert any(g["t_recv"] > t_water for g in before) and {g["fix_type"] for g in before} == {1}
    assert all(
        f["status"] in ("awaiting_target", "buffered") for f in fixes if f["t_recv"] < t_selecting
    )
    # the selection re-initialised the tracker on the frame the operator saw: ok fixes from the frames after it,
    # near the truth
    ok = [f for f in fixes if f["status"] == "ok"]
    assert min(f["frame"] for f in ok) > chosen["frame"] and len(ok) >= 10
    err = live.fix_errors_m(ok)
    print(
        f"page: selected frame {chosen['frame']}; {len(ok)} ok fixes, MAE {err.mean():.4f} m, max {err.max():.4f} m"
    )
    assert err.mean() <= 0.1
    valid = [g for g in gps if g["fix_type"] == 3]
    assert len(valid) >= 10 and live.gps_errors_m(valid).mean() <= 0.1
    # after the release: at most the fix in flight, then no fix to the end
    after = [g for g in gps if g["t_recv"] > t_released]
    stop_at = next(i for i, g in enumerate(after) if g["fix_type"] != 3)
    assert stop_at <= 3 and len(after) - stop_at >= 5, [g["fix_type"] for g in after]
    assert all(g["fix_type"] == 1 and g["ignore_flags"] == 255 for g in after[stop_at:])
    released = [
        f["status"] for f in fixes if f["t_recv"] > t_released + 0.3
    ]  # frames after it, if any came
    assert set(released) <= {"released", "buffered"}, set(released)


def _header(page) -> dict:
    """The header's GPS_INPUT part: the big word and its class, the reason, the ages, the accuracy."""
    return page.evaluate("""() => Object.fromEntries(["sending", "sending-why", "sent-age", "autopilot", "hacc"]
        .map((id) => [id, document.getElementById(id).innerText])
        .concat([["class", document.getElementById("sending").className],
                 ["stale", document.body.classList.contains("stale")]]))""")


def _green_share(png: bytes) -> float:
    """The share of a screenshot's pixels that are green (the page's "ok" green, #0b6e0b, or any clearly green)."""
    import cv2
    import numpy as np

    bgr = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR).astype(int)
    b, g, r = bgr[..., 0], bgr[..., 1], bgr[..., 2]
    return float(((g > r + 40) & (g > b + 40)).mean())


def test_the_header_says_what_gps_input_sends_and_goes_grey_without_status(tmp_path):
    """The header says what GPS_INPUT sends now, and why not a fix; every input cut (the replay, which is also the
    UUV's autopilot, killed) turns it from a green "3D fix" to "NO FIX" with the reason within 2 s; the service
    stopped: the page goes grey with "no status since HH:MM:SS" and nothing green on it."""
    with LiveRun(tmp_path, SESSION, video_latency_ms=VIDEO_LATENCY_MS, replay_now=False) as live:
        url = ui_url(tmp_path / "run.log")
        with chromium(tmp_path, f"{urlsplit(url).scheme}://{urlsplit(url).netloc}") as browser:
            page = browser.page
            page.goto(url)
            page.wait_for_selector("#conn.ok", timeout=20_000)
            live.start_replay()

            # awaiting a target: no fix, and why; the replay's UUV endpoint answers as its autopilot does
            wait_for(
                lambda: (
                    (h := _header(page))["sending"] == "NO FIX"
                    and h["sending-why"] == "awaiting a target"
                    and h["autopilot"].startswith("autopilot heard ")
                    and "bad" in h["class"]
                ),
                25,
                lambda: f"the header saying no fix while awaiting a target: {_header(page)}",
            )
            wait_for(
                lambda: (
                    int(_dataset(page, "received") or 0) >= 3
                    and _dataset(page, "status") == "awaiting_target"
                ),
                25,
                "video frames awaiting a target",
            )
            _select_on_shown_frame(page, live, 640)
            wait_for(
                lambda: (h := _header(page))["sending"] == "3D fix" and "ok" in h["class"],
                15,
                lambda: f"the header saying 3D fix: {_header(page)}",
            )
            h = _header(page)
            assert re.fullmatch(r"accuracy ±0\.\d\d m", h["hacc"]) and re.fullmatch(
                r"sent \d\.\d s ago", h["sent-age"]
            ), h
            assert re.fullmatch(r"position \d\.\d s old", h["sending-why"]), h
            assert re.search(
                r"h_acc 0\.\d\d m", page.get_attribute("#hacc", "title")
            )  # the detail, on hover
            browser.screenshot("5-header-3d-fix")

            # every input cut: the header is not green within 2 s, and says why
            live.replay.kill()
            t_cut = time.monotonic()
            page.wait_for_function(
                """() => document.getElementById("sending").innerText === "NO FIX"
                && !document.getElementById("sending").classList.contains("ok")
                && document.getElementById("sending-why").innerText.startsWith("no new fix")""",
                timeout=2_000,
            )
            print(
                f"header: NO FIX {time.monotonic() - t_cut:.2f} s after the inputs were cut: {_header(page)}"
            )
            # then the autopilot (the replay) is not heard, and the tracker's and gates' words over the frozen
            # frame are no longer green either
            wait_for(
                lambda: (
                    _header(page)["autopilot"] == "autopilot NOT heard"
                    and page.eval_on_selector("#status-word", "e => e.className") == "word grey"
                    and page.eval_on_selector("#gate-state", "e => e.className") == "grey"
                ),
                15,
                lambda: f"the autopilot not heard, the tracker and gates grey: {_header(page)}",
            )
            browser.screenshot("6-inputs-cut")

            # the service stopped: grey, no status since the last one, nothing green
            stop(live.service)
            page.wait_for_function(
                r"""() => document.body.classList.contains("stale")
                && document.getElementById("sending").innerText === "NO STATUS"
                && /^no status since \d\d:\d\d:\d\d$/.test(document.getElementById("sending-why").innerText)""",
                timeout=20_000,
            )
            shot = browser.screenshot("7-no-status")
            assert _green_share(shot.read_bytes()) == 0.0
            assert not browser.errors, browser.errors

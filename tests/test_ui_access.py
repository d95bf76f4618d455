"""Who may use the web page: ``skyfix run`` with its page, and HTTP requests and a headless Chromium, all to
127.0.0.1 only.

- Bound beyond localhost (``--ui 0.0.0.0:0``), skyfix prints the page's URL with a token; every request without
  it gets 401, with a wrong one 403 (the page, its files, the commands, the WebSocket); with it (in the URL, then
  a cookie, or as a Bearer header) the page works in the browser, WebSocket included.
- On localhost an explicit ``--ui-token`` is enforced the same way.
- On localhost without a token: requests naming another host (DNS rebinding) and commands from another site's
  page (Origin) are refused; the page's own commands work, and bad ones get a one-line error.
"""

from __future__ import annotations

import json
import socket
import urllib.error
import urllib.request
from urllib.parse import urlsplit

import pytest
from live_helpers import ROOT, free_port, skyfix, start, stop, ui_url, wait_for
from ui_browser import available, chromium

CAL = ROOT / "sim_fixtures" / "bundled" / "nadir_hover" / "session.toml"


@pytest.fixture
def service(tmp_path):
    """``service(*ui_args) -> (base URL on 127.0.0.1, token or None)``: a skyfix run without inputs."""
    procs = []

    def run(*ui_args: str):
        log = tmp_path / f"run{len(procs)}.log"
        procs.append(
            start(
                skyfix(
                    "run",
                    "--calibration",
                    str(CAL),
                    "--mavlink",
                    f"udpin:127.0.0.1:{free_port()}",
                    "--zenoh-listen",
                    f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}",
                    "--video",
                    "none",
                    "--gps-input",
                    "none",
                    "--duration-s",
                    "120",
                    *ui_args,
                ),
                log,
            )
        )
        url = urlsplit(ui_url(log))
        token = url.query.removeprefix("token=") or None
        return f"http://127.0.0.1:{url.port}", token

    yield run
    for p in procs:
        stop(p)


def _get(
    url: str, headers: dict | None = None, data: bytes | None = None
) -> tuple[int, dict, bytes]:
    req = urllib.request.Request(
        url, data=data, headers=headers or {}, method="POST" if data is not None else "GET"
    )
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            return r.status, dict(r.headers), r.read()
    except urllib.error.HTTPError as e:
        return e.code, dict(e.headers), e.read()


def _error(body: bytes) -> str:
    return json.loads(body)["error"]


def test_beyond_localhost_every_request_needs_the_printed_token(service, tmp_path):
    base, token = service("--ui", "0.0.0.0:0")
    assert token and len(token) >= 16  # made up at start, printed in the URL
    for path in ("/", "/static/app.js", "/api/status", "/ws"):
        code, _, body = _get(base + path)
        assert code == 401 and "needs its token" in _error(body), (path, code, body)
        code, _, body = _get(f"{base}{path}?token=not-the-token")
        assert code == 403 and "wrong token" in _error(body), (path, code)
    code, _, body = _get(base + "/api/release", data=b"{}")
    assert code == 401
    code, headers, page = _get(f"{base}/?token={token}")
    assert (
        code == 200
        and b'<canvas id="video"' in page
        and "skyfix_token=" in headers.get("Set-Cookie", "")
    )
    assert "HttpOnly" in headers["Set-Cookie"] and "SameSite=Strict" in headers["Set-Cookie"]
    code, _, body = _get(base + "/api/status", headers={"Authorization": f"Bearer {token}"})
    status = json.loads(body)
    # the refused release changed nothing
    assert code == 200 and status["target"]["state"] == "awaiting_target"
    assert status["ui"]["token"] and status["ui"]["refused"] >= 9

    if available() is not None:
        pytest.skip(available())
    with chromium(tmp_path, base) as browser:
        page = browser.page
        page.goto(base + "/")  # without the token: refused, nothing of the page
        assert "needs its token" in page.inner_text("body")
        # the printed URL: the page, then its WebSocket by the cookie
        page.goto(f"{base}/?token={token}")
        page.wait_for_selector("#conn.ok", timeout=20_000)
        wait_for(
            lambda: page.eval_on_selector("#health tbody", "b => b.rows.length") > 3,
            10,
            "the health table",
        )
        assert "UAV MAVLink: nothing received" in page.inner_text("#problems")
        browser.screenshot("5-token-page-no-inputs")
        assert not browser.errors and not browser.outside


def test_an_explicit_token_is_enforced_on_localhost_too(service):
    base, token = service("--ui", "127.0.0.1:0", "--ui-token", "field-day-2026")
    assert token == "field-day-2026"
    assert _get(base + "/")[0] == 401 and _get(base + "/?token=field-day-2025")[0] == 403
    assert _get(base + "/?token=field-day-2026")[0] == 200


def test_localhost_refuses_other_hosts_and_other_sites(service):
    base, token = service("--ui", "127.0.0.1:0")
    assert token is None and _get(base + "/")[0] == 200  # no token on localhost
    host = urlsplit(base).netloc
    code, _, body = _get(base + "/", headers={"Host": f"attacker.example:{urlsplit(base).port}"})
    assert code == 403 and "not this machine's loopback address" in _error(body)
    code, _, body = _get(
        base + "/api/release", data=b"{}", headers={"Origin": "http://attacker.example"}
    )
    assert code == 403 and "another site" in _error(body)
    code, _, body = _get(base + "/api/explode", data=b"{}", headers={"Origin": f"http://{host}"})
    assert code == 404 and "unknown command 'explode'" in _error(body)
    code, _, body = _get(
        base + "/api/select", data=b'{"box": [1, 2]}', headers={"Content-Type": "application/json"}
    )
    assert code == 400 and _error(body) == "select: box = [1, 2]: expected 4 finite numbers"
    code, _, body = _get(base + "/api/select", data=b'{"box": [300, 160, 36, 36]}')
    assert code == 400 and _error(body) == "select: no frame received yet"
    code, _, body = _get(base + "/api/release", data=b"{}", headers={"Origin": f"http://{host}"})
    assert code == 200 and json.loads(body)["target"]["state"] == "released"
    code, _, body = _get(base + "/api/acquire", data=b"")
    assert code == 200 and json.loads(body)["target"]["state"] == "awaiting_target"

"""Debian's Chromium, headless, driven by Playwright (no browser download): for the web page's tests.

Chromium starts with the flags this machine's closed network needs and a fresh profile; host names do
not resolve (``--host-resolver-rules``), and every request the page makes is recorded (``requests``) and
anything not for the page's own server aborted, so a test can show the page needs nothing from outside.
Screenshots go to the test's tmp dir and are copied to ``out/ui-screenshots/``.
"""

from __future__ import annotations

import shutil
from contextlib import contextmanager
from pathlib import Path
from urllib.parse import urlsplit

from live_helpers import ROOT

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
FLAGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1",
]
SCREENSHOTS = ROOT / "out" / "ui-screenshots"


def available() -> str | None:
    """Why browser tests cannot run here, or None."""
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return "needs the playwright package (./dev setup installs it)"
    if not Path(CHROMIUM).exists():
        return "needs Debian's chromium (./dev setup installs it)"
    return None


class Browser:
    """One page in a fresh headless Chromium; ``requests``: every URL it asked for; ``errors``: the page's
    JavaScript errors."""

    def __init__(self, context, origin: str, tmp: Path):
        self.context = context
        self.origin = origin
        self.tmp = tmp
        self.requests: list[str] = []
        self.outside: list[str] = []
        self.errors: list[str] = []
        context.route("**/*", self._route)
        self.page = context.new_page()
        self.page.on("pageerror", lambda e: self.errors.append(str(e)))

    def _route(self, route) -> None:
        url = route.request.url
        self.requests.append(url)
        if f"{urlsplit(url).scheme}://{urlsplit(url).netloc}" == self.origin:
            route.continue_()
        else:
            self.outside.append(url)
            route.abort()

    def screenshot(self, name: str) -> Path:
        path = self.tmp / f"{name}.png"
        self.page.screenshot(path=str(path))
        SCREENSHOTS.mkdir(parents=True, exist_ok=True)
        shutil.copy(path, SCREENSHOTS / path.name)
        return path


@contextmanager
def chromium(tmp: Path, origin: str, viewport=(1400, 1400)):
    """A :class:`Browser` for pages of ``origin`` (``http://127.0.0.1:PORT``)."""
    from playwright.sync_api import sync_playwright

    profile = tmp / "chromium-profile"
    profile.mkdir()
    with sync_playwright() as p:
        context = p.chromium.launch_persistent_context(
            str(profile),
            executable_path=CHROMIUM,
            headless=True,
            args=FLAGS,
            viewport={"width": viewport[0], "height": viewport[1]},
        )
        try:
            yield Browser(context, origin, tmp)
        finally:
            context.close()

"""The web page's server: an aiohttp application on the service's own event loop.

Why aiohttp: it is asyncio itself (the server, its WebSocket and the service's workers
share one loop, with no second server loop or thread to hand data across), has
WebSocket and static files built in, and is a well-kept aio-libs project. (Starlette
needs uvicorn, which wants to own the process's signals and loop.)

Routes: ``/`` the page and ``/static/*`` its files (package data, nothing from the
internet); ``/ws`` the page's WebSocket; ``POST /api/select|release|acquire|confirm`` the
operator's commands (JSON as on Zenoh, :mod:`groundstation.live.control`; an error is HTTP
400 with ``{"error": "<one line>"}``); ``GET /api/status`` the status now;
``/basemap/{z}/{x}/{y}`` the base map's tiles (``--basemap``: a GeoTIFF, an MBTiles file or a folder of tiles,
:func:`groundstation.map.tiles.open_basemap`), read or rendered one at a time in a thread of their own at a lower
priority (the tracker goes first), the last :data:`TILE_CACHE` kept; 404 where the base map has none.

Several UUVs (``[[uuv]]``, one :class:`PageUuv` each): a command's JSON body names its UUV,
``"uuv": "<id>"`` (taken out before the command sees the rest); without it the command is
refused (400, naming the ids), and its answer says ``"uuv"``. With one UUV the body is the
command's alone, as on Zenoh (a ``"uuv"`` naming that UUV is allowed). ``/api/status`` is the
first UUV's status (the shared sections and its own) as with one, plus ``uuvs``: each UUV's own
sections by id (``target``, ``fix``, ``depth``, ``gps_input``, ``problems`` …; as in the final
status of a run of several).

The WebSocket sends, to each page: ``{"type": "hello", ...}`` once (the camera's size,
the run's settings, ``uuvs``: each UUV's ``id``, ``colour`` (:mod:`.palette`) and ``track``
so far; ``basemap``: the base map's ``info()`` and its tiles' ``url`` template, or null); ``{"type": "state", ...}`` once a second, and at once when what a UUV's GPS_INPUT sends changes
(the status as ``/api/status`` has it,
input rates measured here, the map's :meth:`TopView.snapshot` and ``uuvs``: per UUV its
``id``, the track points that page has not seen, its safety gates on the map
(:meth:`TopView.gate_view`) and its own rates); and the video packets of
:mod:`.feed` as binary messages. A page sends ``{"video": false}`` when hidden, and
``{"video": true}`` again. A page that reads slowly gets the newest of each, never a
backlog.

Access: bound to a loopback address (``127.0.0.1``, ``::1``, ``localhost``) the page
needs no token, and requests naming another host (DNS rebinding) are refused;
bound beyond (``0.0.0.0:8080``), or with ``--ui-token``, every request needs the token:
``?token=`` in the URL (skyfix prints the URL with it; the page then keeps it in a
cookie), or ``Authorization: Bearer``. Without it: 401; a wrong one: 403. Commands
and the WebSocket from another site's page (an ``Origin`` that is not this server)
are refused (403).
"""

from __future__ import annotations

import asyncio
import errno
import hmac
import json
import logging
import secrets
import socket
import time
from collections import OrderedDict, deque
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from urllib.parse import urlsplit

from aiohttp import WSMsgType, web

from groundstation.live.control import Control, ControlError, jsonable
from groundstation.live.ui import vendor
from groundstation.live.ui.bind import is_loopback, parse_bind
from groundstation.live.ui.feed import VideoFeed, lower_priority
from groundstation.live.ui.palette import colour
from groundstation.live.ui.topview import TopView
from groundstation.map.tiles import FORMATS, BaseMapError, open_basemap

log = logging.getLogger("skyfix.ui")

STATIC = resources.files("groundstation.live.ui") / "static"
COOKIE = "skyfix_token"
STATE_PERIOD_S = 1.0
CHANGE_POLL_S = 0.1  # how often the pusher asks whether what a UUV's GPS_INPUT sends changed (then it pushes at once)
WS_CLOSE_S = 0.5  # a stop waits this long for open pages to take the close
RATE_WINDOW_S = 3.0
COMMANDS = ("select", "release", "acquire", "confirm")
TILE_CACHE = 512  # base-map tiles kept in memory (PNG, a few kB to 100 kB each)
TILE_URL = "/basemap/{z}/{x}/{y}"
SECURITY_HEADERS = {
    "Content-Security-Policy": "default-src 'self'; img-src 'self' blob:; connect-src 'self'; frame-ancestors 'none'",
    "X-Frame-Options": "DENY",
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
    "Cache-Control": "no-store",
}


class UiError(OSError):
    """The page cannot be served (its port is taken, its address is not this machine's); one line naming --ui."""


class CounterRates:
    """Rates (per second) of growing counters (frames sent, bytes), over the last :data:`RATE_WINDOW_S`; a
    message kind's receive rate is :class:`~groundstation.live.sources.rates.RateMeter`'s."""

    def __init__(self, window_s: float = RATE_WINDOW_S):
        self.window_s = window_s
        self._samples: deque[tuple[float, dict]] = deque()

    def update(self, now: float, counts: dict[str, int | None]) -> dict[str, float | None]:
        self._samples.append((now, counts))
        while len(self._samples) > 2 and now - self._samples[1][0] >= self.window_s:
            self._samples.popleft()
        t0, first = self._samples[0]
        dt = now - t0
        return {
            k: (
                round((v - first[k]) / dt, 2)
                if dt > 0.2 and v is not None and first.get(k) is not None
                else None
            )
            for k, v in counts.items()
        }


@dataclass
class PageUuv:
    """One UUV on the page: its ``id``, its commands (``control``; the first UUV's status is the page's),
    with several, its own status sections (``own_status(now)``; default: its control's whole status), and
    ``sending()``: what its GPS_INPUT sends now (a value that changes when that does; None: no GPS_INPUT)."""

    id: str
    control: Control
    own_status: Callable[[float], dict] | None = None
    sending: Callable[[], object] | None = None
    rates: CounterRates = field(default_factory=CounterRates)


class Viewer:
    """One open page: the newest state and video packet not yet sent to it."""

    def __init__(self, uuvs: int = 1):
        self.video = True
        self.seq = [0] * uuvs  # per UUV, the last track point sent
        self.state: str | None = None
        self.packet: bytes | None = None
        self.ready = asyncio.Event()


def _counts(status: dict) -> dict[str, int | None]:
    def get(section: str, key: str):
        part = status.get(section)
        return part.get(key) if isinstance(part, dict) else None

    return {
        "video_frames": get("video", "frames"),
        "processed": get("pipeline", "processed"),
        "depth": get("depth", "received"),
        "gps_input": get("gps_input", "sent"),
        "uav": get("uav", "received"),
    }


class WebUi:
    """Worker serving the page (see the module doc); :meth:`start` binds (UiError), :meth:`run` serves.

    ``control``: the one UUV's commands, or each UUV's :class:`PageUuv` in the run's order (the topview's
    ``tracks`` in the same order). ``settings``: what the page shows about the run's configuration.
    ``basemap``: the map's base (a GeoTIFF, an MBTiles file or a folder of tiles), opened by :meth:`start`; or one
    the run makes (:class:`groundstation.live.mosaic_live.LiveMosaic`: its ``version`` in the tiles' cache key).
    """

    def __init__(
        self,
        bind: str,
        token: str | None,
        control: Control | Sequence[PageUuv],
        topview: TopView,
        feed: VideoFeed,
        camera_size: tuple[int, int],
        settings: dict,
        basemap=None,
    ):
        self.host, self.port = parse_bind(bind)
        self.bind = bind
        self.token = (
            token
            if token is not None
            else (None if is_loopback(self.host) else secrets.token_urlsafe(16))
        )
        self.uuvs = [PageUuv("uuv1", control)] if isinstance(control, Control) else list(control)
        self.several = len(self.uuvs) > 1
        self.control = self.uuvs[0].control
        self.topview = topview
        self.camera_size = camera_size
        self.settings = settings
        self.viewers: set[Viewer] = set()
        self.feed = feed  # a sink and frame listener of the pipeline: the page is where it delivers
        feed.deliver, feed.watching = self._deliver, self._watching
        self.rates = CounterRates()
        self.url: str | None = None
        self.refused = 0
        self._runner: web.AppRunner | None = None
        self._sockets: set[web.WebSocketResponse] = set()
        self.basemap_path = basemap
        self.basemap = None
        self._tiles: OrderedDict[tuple[int, int, int, int], bytes | None] = OrderedDict()
        self._tiler = ThreadPoolExecutor(
            1, thread_name_prefix="ui-tiles", initializer=lower_priority
        )

    # -- life ------------------------------------------------------------------------------------------
    async def start(self) -> None:
        """Open ``--basemap`` and listen on ``--ui``; :class:`UiError` naming the option when that cannot be done."""
        if self.basemap_path is not None and not isinstance(self.basemap_path, str):
            # one the run made: the live mosaic
            self.basemap, self.basemap_path = self.basemap_path, None
        if self.basemap_path is not None:
            try:
                self.basemap = await asyncio.get_running_loop().run_in_executor(
                    self._tiler, open_basemap, Path(self.basemap_path)
                )
            except BaseMapError as e:
                raise UiError(f"--basemap: {e}") from None
        if not vendor.is_present():
            log.warning(
                "web page: its map library, Leaflet %s, is not in %s: the page shows no map "
                "(./dev setup, or python -m groundstation.live.ui.vendor, fetches it)",
                vendor.VERSION,
                vendor.DEST,
            )
        app = web.Application(middlewares=[self._guard], client_max_size=64 * 1024)
        app.router.add_get("/", self._index)
        app.router.add_get("/ws", self._websocket)
        app.router.add_get("/favicon.ico", self._no_icon)
        app.router.add_get("/api/status", self._status)
        app.router.add_post("/api/{command}", self._command)
        app.router.add_get("/basemap/{z:\\d+}/{x:\\d+}/{y:\\d+}", self._tile)
        app.router.add_static("/static/", str(STATIC))
        app.on_response_prepare.append(self._headers)
        self._runner = web.AppRunner(app, access_log=None, handle_signals=False)
        await self._runner.setup()
        try:
            await web.TCPSite(self._runner, self.host, self.port, reuse_port=False).start()
        except OSError as e:
            await self._runner.cleanup()
            why = {
                errno.EADDRINUSE: f"port {self.port} is already in use (another skyfix run?); choose another "
                "with --ui HOST:PORT, or --no-ui",
                errno.EADDRNOTAVAIL: f"{self.host} is not an address of this machine",
            }.get(e.errno, e.strerror or str(e))
            raise UiError(f"--ui {self.bind}: {why}") from None
        port = self._runner.addresses[0][1]
        host = (
            socket.gethostname()
            if self.host in ("0.0.0.0", "::", "")
            else (f"[{self.host}]" if ":" in self.host else self.host)
        )
        self.url = f"http://{host}:{port}/"
        log.info("web page: %s%s", self.url, f"?token={self.token}" if self.token else "")

    async def run(self) -> None:
        try:
            async with asyncio.TaskGroup() as tg:
                tg.create_task(self.feed.run())
                tg.create_task(self._push_state())
        finally:
            closing = [asyncio.ensure_future(ws.close()) for ws in list(self._sockets)]
            if closing:  # together, and not waiting for a page that does not answer
                await asyncio.wait(closing, timeout=WS_CLOSE_S)
            if self._runner is not None:
                await self._runner.cleanup()
            if self.basemap is not None:
                self._tiler.submit(self.basemap.close)
            self._tiler.shutdown(wait=False, cancel_futures=True)

    def status(self) -> dict:
        return {
            "url": self.url,
            "token": self.token is not None,
            "viewers": len(self.viewers),
            "refused": self.refused,
            **self.feed.status(),
        }

    # -- pushing -----------------------------------------------------------------------------------------
    def _watching(self) -> bool:
        return any(v.video for v in self.viewers)

    def _deliver(self, packet: bytes) -> None:
        for v in self.viewers:
            if v.video:
                v.packet = packet
                v.ready.set()

    def status_now(self) -> dict:
        """The first UUV's status (the shared sections and its own) and, with several, ``uuvs``: each one's own."""
        first = self.control.status()
        if not self.several:
            return first
        t = first["t"]
        return first | {
            "uuvs": {
                u.id: jsonable(u.own_status(t)) if u.own_status else u.control.status()
                for u in self.uuvs
            }
        }

    def _own(self, status: dict, k: int) -> dict:
        return status["uuvs"][self.uuvs[k].id] if self.several else status

    def _sending(self) -> list:
        return [u.sending() if u.sending else None for u in self.uuvs]

    async def _push_state(self) -> None:
        """The state once a second, and at once when what a UUV's GPS_INPUT sends changes (a fix to no fix: the
        page's header says so within :data:`CHANGE_POLL_S`, not up to a second later)."""
        loop = asyncio.get_running_loop()
        pushed_at, sending = loop.time(), self._sending()
        while True:
            await asyncio.sleep(CHANGE_POLL_S)
            now_sending = self._sending()
            if loop.time() - pushed_at < STATE_PERIOD_S and now_sending == sending:
                continue
            pushed_at, sending = loop.time(), now_sending
            if not self.viewers:
                continue
            now = time.time()
            status = self.status_now()
            state = {
                "type": "state",
                "status": status,
                "rates": self.rates.update(now, _counts(status)),
                "map": self.topview.snapshot(now),
            }
            uuvs = []
            for k, u in enumerate(self.uuvs):
                own = self._own(status, k)
                uuvs.append(
                    {
                        "id": u.id,
                        "rates": u.rates.update(now, _counts(own))
                        if self.several
                        else state["rates"],
                        "gate": self.topview.gate_view((own.get("gps_input") or {}).get("gates")),
                    }
                )
            for v in self.viewers:
                for k, part in enumerate(uuvs):
                    track = self.topview.tracks[k].points_since(v.seq[k])
                    if track:
                        v.seq[k] = track[-1][0]
                    part["track"] = track
                v.state = json.dumps({**state, "uuvs": uuvs}, allow_nan=False)
                v.ready.set()

    # -- handlers ----------------------------------------------------------------------------------------
    @web.middleware
    async def _guard(self, request: web.Request, handler):
        given = request.query.get("token") or request.cookies.get(COOKIE)
        auth = request.headers.get("Authorization", "")
        if auth.startswith("Bearer "):
            given = auth[7:]
        if self.token is not None:
            if not given:
                return self._refuse(
                    401, "this page needs its token: open the URL skyfix run printed (…/?token=…)"
                )
            if not hmac.compare_digest(given.encode(), self.token.encode()):
                return self._refuse(403, "wrong token: open the URL skyfix run printed")
        elif not is_loopback(urlsplit(f"//{request.host}").hostname or ""):
            return self._refuse(
                403, f"host {request.host!r} is not this machine's loopback address"
            )
        origin = request.headers.get("Origin")
        if (
            (request.method != "GET" or request.path == "/ws")
            and origin is not None
            and urlsplit(origin).netloc != request.host
        ):
            return self._refuse(403, f"a request from another site ({origin}) is refused")
        response = await handler(request)
        if self.token is not None and request.query.get("token") == self.token:
            response.set_cookie(COOKIE, self.token, httponly=True, samesite="Strict")
        return response

    def _refuse(self, code: int, why: str) -> web.Response:
        self.refused += 1
        return web.json_response({"error": why}, status=code)

    @staticmethod
    async def _headers(request: web.Request, response: web.StreamResponse) -> None:
        response.headers.update(SECURITY_HEADERS)

    @staticmethod
    async def _no_icon(request: web.Request) -> web.Response:
        return web.Response(status=204)

    async def _index(self, request: web.Request) -> web.StreamResponse:
        return web.FileResponse(STATIC / "index.html")

    async def _tile(self, request: web.Request) -> web.Response:
        """A tile of the base map (PNG, JPEG or WebP as the base map has them); 404 where it has none."""
        z, x, y = (int(request.match_info[k]) for k in "zxy")
        if self.basemap is None or z > 30 or not (0 <= x < 2**z and 0 <= y < 2**z):
            return web.Response(status=404)
        key = (z, x, y, getattr(self.basemap, "version", 0))  # the live mosaic's grows
        if key in self._tiles:
            self._tiles.move_to_end(key)
        else:
            self._tiles[key] = await asyncio.get_running_loop().run_in_executor(
                self._tiler, self.basemap.tile, z, x, y
            )
            while len(self._tiles) > TILE_CACHE:
                self._tiles.popitem(last=False)
        data = self._tiles[key]
        if data is None:
            return web.Response(status=404)
        return web.Response(body=data, content_type=FORMATS[self.basemap.info()["format"]])

    async def _status(self, request: web.Request) -> web.Response:
        return web.json_response(self.status_now(), dumps=lambda o: json.dumps(o, allow_nan=False))

    def _addressed(self, command: str, payload: bytes) -> tuple[PageUuv, bytes]:
        """The UUV a command's body names (``"uuv"``) and the body without it; with one UUV, the body may name
        none. :class:`ControlError` for an unknown id, or none with several UUVs."""
        try:
            obj = json.loads(payload)
        except (ValueError, UnicodeDecodeError, RecursionError):
            obj = None
        ids = ", ".join(u.id for u in self.uuvs)
        if isinstance(obj, dict) and "uuv" in obj:
            name = obj.pop("uuv")
            uuv = next((u for u in self.uuvs if isinstance(name, str) and u.id == name), None)
            if uuv is None:
                raise ControlError(
                    f"{command}: uuv = {json.dumps(name)[:40]}: not a UUV of this run ({ids})"
                )
            return uuv, json.dumps(obj).encode()
        if self.several:
            raise ControlError(
                f"{command}: this run tracks several UUVs ({ids}): name one in the "
                f'JSON body, as {{"uuv": "{self.uuvs[0].id}"}}'
            )
        return self.uuvs[0], payload

    async def _command(self, request: web.Request) -> web.Response:
        command = request.match_info["command"]
        if command not in COMMANDS:
            return web.json_response(
                {"error": f"unknown command {command!r} (known: {', '.join(COMMANDS)})"}, status=404
            )
        try:
            uuv, payload = self._addressed(command, await request.read())
            result = await uuv.control.handle(command, payload)
        except ControlError as e:
            log.warning("page: command %s refused: %s", command, e)
            return web.json_response({"error": str(e)}, status=400)
        except Exception as e:  # a bug in one command must not stop the service
            log.exception("page: command %s failed", command)
            return web.json_response({"error": f"{command}: internal error: {e}"}, status=500)
        if self.several:
            result = {"uuv": uuv.id, **result}
        log.info(
            "page: %s%s done (latest frame %s)",
            command,
            f" {uuv.id}" if self.several else "",
            result.get("latest_frame"),
        )
        return web.json_response(result, dumps=lambda o: json.dumps(o, allow_nan=False))

    async def _websocket(self, request: web.Request) -> web.WebSocketResponse:
        # no permessage-deflate: the JPEGs do not compress, and zlib would cost the service CPU for every frame
        ws = web.WebSocketResponse(heartbeat=10.0, max_msg_size=4096, compress=False, timeout=2.0)
        await ws.prepare(request)
        viewer = Viewer(len(self.uuvs))
        uuvs = [
            {"id": u.id, "colour": colour(k), "track": self.topview.tracks[k].points_since(0)}
            for k, u in enumerate(self.uuvs)
        ]
        hello = {
            "type": "hello",
            "camera": {"width": self.camera_size[0], "height": self.camera_size[1]},
            "video": {
                "max_fps": round(1.0 / self.feed.min_interval_s, 2),
                "max_width": self.feed.max_width,
            },
            "settings": self.settings,
            "uuvs": uuvs,
            "basemap": None if self.basemap is None else {**self.basemap.info(), "url": TILE_URL},
        }
        for k, u in enumerate(uuvs):
            if u["track"]:
                viewer.seq[k] = u["track"][-1][0]
        self._sockets.add(ws)
        self.viewers.add(viewer)
        sender = asyncio.create_task(self._send(ws, viewer))
        try:
            await ws.send_str(json.dumps(hello, allow_nan=False))
            async for msg in ws:
                if msg.type == WSMsgType.TEXT:
                    self._from_page(viewer, msg.data)
        finally:
            self.viewers.discard(viewer)
            self._sockets.discard(ws)
            sender.cancel()
        return ws

    @staticmethod
    def _from_page(viewer: Viewer, text: str) -> None:
        try:
            message = json.loads(text)
        except ValueError:
            return
        if isinstance(message, dict) and isinstance(message.get("video"), bool):
            viewer.video = message["video"]

    @staticmethod
    async def _send(ws: web.WebSocketResponse, viewer: Viewer) -> None:
        while not ws.closed:
            await viewer.ready.wait()
            viewer.ready.clear()
            state, packet = viewer.state, viewer.packet
            viewer.state = viewer.packet = None
            try:
                if state is not None:
                    await ws.send_str(state)
                if packet is not None:
                    await ws.send_bytes(packet)
            except ConnectionError:
                return


def settings_of(cfg) -> dict:
    """What the page shows about a run's configuration (:class:`~groundstation.live.config.RunConfig`)."""
    return {
        "video_latency_ms": cfg.video_latency_ms,
        "gps_input_hz": cfg.gps_input_hz if cfg.gps_input else None,
        "fix_max_age_ms": cfg.fix_max_age_ms,
        "select_history_s": cfg.select_history_s,
        "tracker": cfg.tracker,
    }

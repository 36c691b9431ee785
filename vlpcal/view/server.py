"""The page's server (aiohttp: its own HTTP server, static files and streaming responses in
one well-kept package, on asyncio, so no separate ASGI server is needed).

It runs in a thread of its own beside the command. ``/`` the page, ``/static/…`` its script
and style (from the package: no build step, no outside URL), ``/scene`` the room (JSON),
``/report.png`` a calibrated deployment's report figure, ``/events`` the live stream
(server-sent events, :data:`TICK` apart when something changed; each camera's latest frame
in it, :data:`FRAME_HZ` a second at most), ``/frame/<id>`` a camera's latest JPEG. Bound to
loopback it is open; bound to any other interface every request needs the token printed at
start (``?token=`` once, then a cookie)."""

from __future__ import annotations

import asyncio
import base64
import hmac
import ipaddress
import json
import secrets
import socket
import threading
import time
from pathlib import Path

from aiohttp import web

from .hub import ViewHub
from .scene import Scene

#: s between two updates of a page (at most; none while nothing changed)
TICK = 0.1
#: a camera's frames sent to a page a second, at most: enough to aim a camera by, and cheap
#: beside the tracker (the rest are skipped; the page counts them)
FRAME_HZ = 10
#: the page's files
STATIC = Path(__file__).with_name("static")
#: what the page may load: its own server's files and frames, nothing outside
POLICY = ("default-src 'self'; img-src 'self' blob: data:; style-src 'self'; "
          "script-src 'self'; connect-src 'self'; frame-ancestors 'none'")
COOKIE = "vlpcal_view"
#: the names a page on this machine reaches a loopback-bound view by
LOOPBACK_NAMES = frozenset(("127.0.0.1", "localhost", "::1"))
#: s a connection may stay idle (a client that opens connections and sends nothing)
IDLE_SECONDS = 15.0


class ViewError(ValueError):
    """A bind address that cannot be served (one line)."""


def parse_bind(text: str, default_port: int = 8765) -> tuple[str, int]:
    """``HOST:PORT``, ``HOST``, ``:PORT`` or ``PORT`` → (host, port); the host defaults to
    127.0.0.1. IPv6 hosts in brackets (``[::1]:8765``)."""
    text = text.strip()
    host, port = "127.0.0.1", default_port
    if text.startswith("["):
        h, _, rest = text[1:].partition("]")
        host, port_text = h, rest.lstrip(":")
    elif text.count(":") == 1:
        host, port_text = text.split(":")
    elif text.isdigit():
        port_text = text
    else:
        host, port_text = text, ""
    host = host or "127.0.0.1"
    if port_text:
        if not port_text.isdigit() or not 0 <= int(port_text) <= 65535:
            raise ViewError(f"{text!r}: expected HOST:PORT with a port 0–65535")
        port = int(port_text)
    return host, port


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class ViewServer:
    """Serve ``scene`` and ``hub`` on ``host:port`` (port 0: any free one) in a thread. Off
    loopback, ``token`` (default: a new random one) is asked of every request."""

    def __init__(self, scene: Scene, hub: ViewHub | None, host: str = "127.0.0.1",
                 port: int = 8765, token: str | None = None, figure: bytes | None = None):
        self.scene, self.hub, self.host, self.figure = scene, hub, host, figure
        self.token = None if is_loopback(host) else (token or secrets.token_urlsafe(16))
        self.refused = 0  #: requests refused for want of the token
        self._scene_json = json.dumps(scene.doc, allow_nan=False).encode()
        self._loop = asyncio.new_event_loop()
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._runner: web.AppRunner | None = None
        self.port = port
        self._thread = threading.Thread(target=self._run, daemon=True, name="vlpcal-view")
        self._thread.start()
        self._ready.wait(10)
        if self._error is not None:
            raise ViewError(f"{host}:{port}: cannot serve the view there "
                            f"({getattr(self._error, 'strerror', None) or self._error})")

    @property
    def url(self) -> str:
        """The page's address; bound to every interface, this machine's on its network (the
        one a tablet on the site's network opens), else the bound host's."""
        host = self.host
        if host in ("0.0.0.0", "::", ""):
            host = _network_address() or "127.0.0.1"
        host = f"[{host}]" if ":" in host else host
        return f"http://{host}:{self.port}/" + (f"?token={self.token}" if self.token else "")

    def _run(self) -> None:
        asyncio.set_event_loop(self._loop)
        try:
            self._loop.run_until_complete(self._start())
        except BaseException as e:  # a port taken, a host not ours: said by the caller
            self._error = e
            self._ready.set()
            return
        self._ready.set()
        self._loop.run_forever()

    async def _start(self) -> None:
        app = web.Application(middlewares=[self._guard])
        app.router.add_get("/", self._page)
        app.router.add_get("/scene", self._scene)
        app.router.add_get("/events", self._events)
        app.router.add_get("/frame/{camera}", self._frame)
        app.router.add_get("/report.png", self._figure)
        app.router.add_static("/static/", STATIC, show_index=False)
        app.router.add_get("/favicon.ico", self._no_icon)
        self._runner = web.AppRunner(app, access_log=None, handle_signals=False,
                                     shutdown_timeout=0.5, keepalive_timeout=IDLE_SECONDS)
        await self._runner.setup()
        site = web.TCPSite(self._runner, self.host, self.port)
        await site.start()
        self.port = self._runner.addresses[0][1]

    def close(self) -> None:
        """Stop serving: a page still open is told the command ended (its last rows and this
        reach it first), then the server goes."""
        if self._runner is None or not self._loop.is_running():
            return
        if self.hub is not None:
            self.hub.say("the command has ended")
            self.hub.ended = True
            time.sleep(3 * TICK)
        done = asyncio.run_coroutine_threadsafe(self._runner.cleanup(), self._loop)
        try:
            done.result(3)
        except Exception:  # noqa: BLE001 — closing: a page that hangs on is let go
            pass
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(3)

    # -- handlers -------------------------------------------------------------------------------
    @property
    def _cookie(self) -> str:
        """The token's cookie, one per port (a cookie is the host's, whatever its port)."""
        return f"{COOKIE}_{self.port}"

    def _allowed(self, request) -> bool:
        """Whether a request may be served: off loopback, with the token; on loopback, named
        by a loopback host (a page of another site that a DNS rebinding points at 127.0.0.1
        names its own host, and is refused)."""
        if self.token is None:
            named = (request.host or "").lower()
            if named.startswith("["):  # [::1]:8765
                named = named[1:].split("]", 1)[0]
            elif named.count(":") == 1:  # host:port
                named = named.split(":", 1)[0]
            return named in LOOPBACK_NAMES or named == self.host.lower()
        given = request.query.get("token") or request.cookies.get(self._cookie) or ""
        return hmac.compare_digest(given.encode("utf-8", "replace"),
                                   self.token.encode("utf-8"))

    @web.middleware
    async def _guard(self, request, handler):
        if not self._allowed(request):
            self.refused += 1
            return web.Response(status=403, text="this view asks for the token its command "
                                "printed when it started (…/?token=…), at the address it "
                                "printed\n")
        given = request.query.get("token") if self.token is not None else None
        response = await handler(request)
        response.headers["Content-Security-Policy"] = POLICY
        response.headers["X-Content-Type-Options"] = "nosniff"
        response.headers["Cache-Control"] = "no-store"
        if given:
            response.set_cookie(self._cookie, self.token, httponly=True, samesite="Strict")
        return response

    async def _page(self, request):
        return web.FileResponse(STATIC / "index.html")

    async def _no_icon(self, request):
        return web.Response(status=204)

    async def _scene(self, request):
        return web.Response(body=self._scene_json, content_type="application/json")

    async def _figure(self, request):
        if self.figure is None:
            raise web.HTTPNotFound()
        return web.Response(body=self.figure, content_type="image/png")

    async def _frame(self, request):
        if self.hub is None:
            raise web.HTTPNotFound()
        seq, t, uv, jpeg = self.hub.latest_frame(request.match_info["camera"])
        if jpeg is None:
            raise web.HTTPNotFound()
        # the frame with its own spots and time: the page draws them together
        return web.Response(body=jpeg, content_type="image/jpeg",
                            headers={"X-Frame-Seq": str(seq), "X-Frame-Time": repr(t),
                                     "X-Frame-Spots": json.dumps(uv)})

    async def _events(self, request):
        response = web.StreamResponse(headers={"Content-Type": "text/event-stream"})
        await response.prepare(request)
        after, seen = (self.hub.start() if self.hub else 0), {}
        hello = {"source": self.hub.source if self.hub else "", "live": self.hub is not None,
                 "tracking": bool(self.hub and self.hub.tracking)}
        await response.write(_event("hello", hello))
        if self.hub is None:
            return response
        status, sent = None, {}  # camera → when its last frame went to this page
        survey_seen = 0
        try:
            while True:
                cams, rows, missed = self.hub.since(after, seen)
                if rows:
                    after = rows[-1]["n"]
                now = time.monotonic()
                for cid, cam in cams.items():  # a frame with its own spots and time
                    if cam["frame"] and now - sent.get(cid, -1e9) >= 1 / FRAME_HZ:
                        seq, t, uv, jpeg = self.hub.latest_frame(cid)
                        if jpeg is not None:
                            cam["jpeg"] = base64.b64encode(jpeg).decode()
                            cam["jpeg_seq"], cam["jpeg_t"], cam["jpeg_uv"] = seq, t, uv
                            sent[cid] = now
                said = self.hub.status
                survey = None
                if self.hub.survey_version != survey_seen:
                    survey_seen, survey = self.hub.survey_version, self.hub.survey
                ended = self.hub.ended
                if cams or rows or missed or said != status or survey is not None or ended:
                    status = said
                    update = {"cameras": cams, "rows": rows, "missed": missed,
                              "status": said, "ended": ended}
                    if survey is not None:
                        update["survey"] = survey
                    await response.write(_event("update", update))
                if ended:
                    break
                await asyncio.sleep(TICK)
        except (ConnectionResetError, asyncio.CancelledError):
            pass
        return response


def _network_address() -> str | None:
    """This machine's address on its network: the one its route out would use (a UDP socket
    aimed at a private address sends nothing); None without a network."""

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.connect(("10.255.255.255", 1))
            return s.getsockname()[0]
        except OSError:
            return None


def _event(kind: str, data) -> bytes:
    return f"event: {kind}\ndata: {json.dumps(data, allow_nan=False)}\n\n".encode()

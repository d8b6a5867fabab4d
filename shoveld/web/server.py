"""The web server of the cab and office pages: static files and a WebSocket of snapshots.

aiohttp serves both: a small, well-kept asyncio server with WebSockets built in, so
one process holds the Zenoh subscriber and pushes every change to the pages without
a framework or a build step. The pages and their script are files of this package,
served from it (no CDN: the cab has no internet).

Zenoh calls back on its own threads; they only mark the state changed, and one
asyncio task sends the newest snapshot to every page (at most ``MAX_RATE_HZ`` times a
second, and once a second anyway so ages and "silent" marks move on).
"""

from __future__ import annotations

import asyncio
import json
import logging
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from aiohttp import WSMsgType, web

from shoveld.web.state import ScreenState

STATIC = Path(__file__).parent / "static"
SENDER: web.AppKey[asyncio.Task[None]] = web.AppKey("sender", asyncio.Task)
MAX_RATE_HZ = 20.0
log = logging.getLogger("shoveld.web")


@dataclass
class ZenohSource:
    """Where the screen's messages come from."""

    connect: list[str]
    mode: str = "client"
    shovel: str = "*"
    prefix: str = "shovel"
    tls: Any = None
    retry_s: float = 2.0
    check_s: float = 1.0
    """How often the open session is asked whether it still reaches anything."""


def bridge(state: ScreenState, src: ZenohSource, stop: threading.Event) -> None:
    """Open the Zenoh subscriber, retrying until it opens; says on the page what it waits
    for. Runs on its own thread until ``stop``."""
    from shoveld.cli.cab import TOPICS, CabClient, watch_link

    client = None
    where = ", ".join(src.connect)
    while not stop.is_set():
        try:
            client = CabClient(state, src.connect, src.mode, src.shovel, src.prefix, src.tls,
                               topics=TOPICS | {"joints"})
            break
        except Exception as e:  # noqa: BLE001 - zenoh.ZError: no router yet
            state.set_link("connecting", f"waiting for Zenoh at {where} ({type(e).__name__})")
            stop.wait(src.retry_s)
    if client is None:
        return
    state.set_link("up", where)
    try:
        watch_link(state, client, where, stop, src.check_s)
    finally:
        client.close()


class ScreenServer:
    """The aiohttp application for one screen state."""

    def __init__(self, state: ScreenState) -> None:
        self.state = state
        self.clients: set[web.WebSocketResponse] = set()
        self._dirty: asyncio.Event | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        state.on_change = self._on_change
        app = web.Application()
        app.router.add_get("/", self._page("cab.html"))
        app.router.add_get("/office", self._page("office.html"))
        app.router.add_get("/ws", self._ws)
        app.router.add_get("/api/state", self._api)
        app.router.add_static("/static/", STATIC, follow_symlinks=False)
        app.on_startup.append(self._start)
        app.on_shutdown.append(self._close_clients)
        self.app = app

    def _page(self, name: str) -> Any:
        async def handler(_: web.Request) -> web.FileResponse:
            return web.FileResponse(STATIC / name, headers={"Cache-Control": "no-cache"})
        return handler

    def _on_change(self) -> None:
        """From any thread: ask the sender to push a fresh snapshot."""
        loop, dirty = self._loop, self._dirty
        if loop is not None and dirty is not None and not loop.is_closed():
            loop.call_soon_threadsafe(dirty.set)

    async def _start(self, app: web.Application) -> None:
        self._loop = asyncio.get_running_loop()
        self._dirty = asyncio.Event()
        app[SENDER] = asyncio.create_task(self._sender())

    async def _close_clients(self, app: web.Application) -> None:
        app[SENDER].cancel()
        for ws in list(self.clients):
            await ws.close()

    async def _sender(self) -> None:
        assert self._dirty is not None
        while True:
            try:
                await asyncio.wait_for(self._dirty.wait(), timeout=1.0)
            except TimeoutError:
                pass
            self._dirty.clear()
            if self.clients:
                text = json.dumps(self.state.snapshot())
                for ws in list(self.clients):
                    try:
                        await ws.send_str(text)
                    except (ConnectionError, RuntimeError):
                        self.clients.discard(ws)
            await asyncio.sleep(1.0 / MAX_RATE_HZ)

    async def _ws(self, request: web.Request) -> web.WebSocketResponse:
        ws = web.WebSocketResponse(heartbeat=10.0)
        await ws.prepare(request)
        # Catch up at once: a page opened (or reconnected) mid-truck sees it whole.
        await ws.send_str(json.dumps(self.state.snapshot()))
        self.clients.add(ws)
        try:
            async for msg in ws:
                if msg.type == WSMsgType.ERROR:
                    break
        finally:
            self.clients.discard(ws)
        return ws

    async def _api(self, _: web.Request) -> web.Response:
        return web.json_response(self.state.snapshot())


def parse_listen(text: str) -> tuple[str, int]:
    """``HOST:PORT`` (``[::1]:8080`` for IPv6) -> (host, port); ValueError says why."""
    host, sep, port = text.rpartition(":")
    if not sep or not host:
        raise ValueError(f"--listen {text!r}: expected HOST:PORT, e.g. 127.0.0.1:8080")
    try:
        p = int(port)
    except ValueError:
        raise ValueError(f"--listen {text!r}: port {port!r} is not a number") from None
    if not 0 <= p <= 65535:
        raise ValueError(f"--listen {text!r}: port {p} is out of range 0-65535")
    return host.strip("[]"), p


async def serve(state: ScreenState, host: str, port: int, started: Any = None,
                stop: asyncio.Event | None = None) -> None:
    """Serve until ``stop`` is set (or forever); ``started(url)`` is called once bound."""
    server = ScreenServer(state)
    runner = web.AppRunner(server.app, access_log=None)
    await runner.setup()
    site = web.TCPSite(runner, host, port)
    await site.start()
    addresses = runner.addresses  # (host, port, ...) of each bound socket
    bound = int(addresses[0][1]) if addresses else port
    shown = f"[{host}]" if ":" in host else host
    if started is not None:
        started(f"http://{shown}:{bound}/")
    try:
        await (stop.wait() if stop is not None else asyncio.Event().wait())
    finally:
        await runner.cleanup()


def run_screen(src: ZenohSource, host: str, port: int, page: str = "",
               duration: float | None = None) -> None:
    """``shoveld cab --web`` and ``shoveld office --web``: the bridge thread and the
    server, until Ctrl-C or ``duration``."""
    state = ScreenState()
    stop = threading.Event()
    t = threading.Thread(target=bridge, args=(state, src, stop), name="zenoh-bridge",
                         daemon=True)
    t.start()

    def started(url: str) -> None:
        print(f"serving the {'office' if page == 'office' else 'cab'} page at {url}{page}",
              flush=True)

    async def main() -> None:
        done = asyncio.Event()
        if duration is not None:
            asyncio.get_running_loop().call_later(duration, done.set)
        await serve(state, host, port, started, done)

    try:
        asyncio.run(main())
    except KeyboardInterrupt:
        pass
    finally:
        stop.set()
        t.join(timeout=5.0)


class ThreadedScreen:
    """The page server on a thread of its own (the demo, the tests, the latency bench):
    ``url`` once started; :meth:`close` stops it."""

    def __init__(self, state: ScreenState, host: str = "127.0.0.1", port: int = 0) -> None:
        self.state = state
        self.url = ""
        self._ready = threading.Event()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, args=(host, port),
                                        name="screen-server", daemon=True)
        self._thread.start()
        self._ready.wait(10.0)
        if self._error is not None:
            raise self._error
        if not self.url:
            raise RuntimeError("the page server did not start within 10 s")

    def _run(self, host: str, port: int) -> None:
        async def main() -> None:
            self._loop = asyncio.get_running_loop()
            self._stop = asyncio.Event()

            def started(url: str) -> None:
                self.url = url
                self._ready.set()
            await serve(self.state, host, port, started, self._stop)

        try:
            asyncio.run(main())
        except BaseException as e:  # noqa: BLE001 - reported to the starting thread
            self._error = e
            self._ready.set()

    def close(self) -> None:
        if self._loop is not None and self._stop is not None and not self._loop.is_closed():
            self._loop.call_soon_threadsafe(self._stop.set)
        self._thread.join(timeout=5.0)

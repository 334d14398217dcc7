"""The console server: one NiceGUI app serving every student's page, one zenoh session per logged-in page.

NiceGUI (FastAPI + Vue/Quasar, its assets in its wheel: nothing is fetched from another host) was
built for robot operator UIs: pages are Python, their events (clicks, keys, clicks on an image)
come back as Python callbacks, so the page uses the same user API as a script and adds nothing
on the wire.
"""

from __future__ import annotations

import logging
import socket
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from robots.kinds import facts
from user_peer.console.doors import Doors
from user_peer.console.feed import Decoded
from user_peer.console.health import PERIOD_S, Health
from user_peer.console.login import Logins
from user_peer.console.pictures import ROUTE, Pictures
from user_peer.console.teacher import ROUTE as TEACHER
from user_peer.console.ticker import OnePerTurn, Ticker

if TYPE_CHECKING:
    from user_peer.world import World

__all__ = [
    "Console",
    "serve",
    "page_urls",
    "RECONNECT_S",
    "PRUNE_S",
    "PING_INTERVAL_S",
    "PING_TIMEOUT_S",
    "HISTORY_MESSAGES",
    "REFRESH_VIEW_S",
]

REFRESH_VIEW_S = 0.2
"""How often every page redraws (the console's one clock, :mod:`.ticker`): the view may be 0.5 s behind."""

RECONNECT_S = 30.0
"""How long a page whose connection dropped may come back as it was (NiceGUI's reconnect timeout): a busy
server, a starved browser or a flaky Wi-Fi must not log a student out. After it the page is gone and her grace
begins. Nothing drives meanwhile: the dropped connection lets go of her keys at once. 10 s was too short for a class on one loaded 2-core box: with 20 pages at
load 25-38 pages came back after more than 10 s and NiceGUI had forgotten them (back at the login)."""

PRUNE_S = 180.0
"""How long a page the server served may take to connect its websocket before NiceGUI forgets it (NiceGUI's own
default is 60 s). On a loaded 2-core box pages took 66-137 s to load their scripts; NiceGUI had pruned them, so
their first connection failed ('implicit handshake failed') and they reloaded to the login, starting over. A page
that never connects costs the server its elements (about 80 KiB) that long, so an address keeps only its newest few
such pages, and loads are limited per address (:mod:`.doors`): a flood of loads is forgotten within a second."""

PING_INTERVAL_S, PING_TIMEOUT_S = 8.0, 12.0
"""The websocket's heartbeat: a ping every 8 s, answered within 12 s (NiceGUI derives 24 s and 12 s from the 30 s
reconnect window; it was 8 s and 4 s with 10 s). A starved page's late answer is forgiven for longer, and a page
whose network died silently, with a key down, is still let go of within 20 s (a closed tab: at once)."""

HISTORY_MESSAGES = 20_000
"""Messages NiceGUI keeps for each page to send again when its connection comes back (its own default is 1,000, and
it also forgets any older than the ping's and the reconnect window's 50 s). A page whose outbox had lost one of the
messages it missed is reloaded by NiceGUI ("outbox rewind failed"): a page that redraws its views every 0.2 s met
1,000 within seconds, so a dropped connection of 10-20 s (a starved browser, a busy server: CI's whole runs) came back
as a reloaded page, and a click under way was lost with it. The age limit keeps the memory to 50 s of a page's
updates."""

log = logging.getLogger("robofabric.console")


@dataclass
class Console:
    """What every page shares: where the world is, the class's base zenoh config, the logged-in worlds."""

    world: str
    connect: tuple[str, ...]
    base_file: str | None = None
    grace: float = 10.0
    rerun_url: str | None = None
    join_timeout: float = 10.0
    instructors: tuple[str, ...] = ()  # the logins that may open the teacher's page (user_peer/console/teacher.py)
    view3d: bool = True  # each page has the 3D view (console --no-3d: the top-down map alone)
    view_fps: int = 10  # frames a second each page's 3D view draws in its browser (console --view-fps)
    logins_required: bool | None = (
        None  # whether the router refuses a session without a login (.world_kind); None: not known yet
    )
    logins: Logins = field(init=False)
    health: Health = field(init=False, default_factory=Health)
    pictures: Pictures = field(init=False, default_factory=Pictures)
    ticker: Ticker = field(init=False, default_factory=lambda: Ticker(REFRESH_VIEW_S))
    decoded: Decoded = field(init=False, default_factory=Decoded)  # every page's poses, decoded once
    doors: Doors = field(init=False, default_factory=Doors)  # page loads, websockets, whose socket speaks for a page
    builds: OnePerTurn = field(init=False, default_factory=OnePerTurn)  # the pages' builds, one per turn of the loop

    def __post_init__(self) -> None:
        self.logins = Logins(self._open, grace=self.grace, on_leave=stop_robots)

    def _open(self, config: Any, name: str) -> Any:
        from user_peer.console.follow import streams
        from user_peer.world import World

        w = World(config, name, join_timeout=self.join_timeout, followed=streams)
        try:
            w.info()
        except BaseException:
            w.close()
            raise
        return w


def stop_robots(world: World) -> None:
    """Her page went away: every robot she owns stops where it is (a base brakes, an arm holds)."""
    for rid in world.robots():
        r = world.robot(rid)
        if r.is_owner:
            try:
                if facts(r.kind).base:
                    r.twist(0.0, 0.0)
                r.stop(confirm=False)
            except Exception as exc:
                log.info("console: could not stop %s for %s: %s", rid, world.user, exc)


def page_urls(host: str, port: int, scheme: str = "http") -> list[str]:
    """The URLs to open: every interface's IPv4 address when listening on all of them."""
    if host not in ("0.0.0.0", "", "::"):
        return [f"{scheme}://{host}:{port}/"]
    import ifaddr

    addrs = sorted(
        {ip.ip for a in ifaddr.get_adapters() for ip in a.ips if isinstance(ip.ip, str)},
        key=lambda a: (a.startswith("127."), a),
    )
    return [f"{scheme}://{a}:{port}/" for a in addrs] or [f"{scheme}://{socket.gethostname()}:{port}/"]


def _routes(console: Console) -> None:
    """The student's page (``/``), the teacher's (:data:`~.teacher.ROUTE`) and the view's pictures."""
    from fastapi import Response
    from nicegui import app, ui

    from user_peer.console.page import ConsolePage
    from user_peer.console.teacher_page import TeacherPage

    @ui.page("/")
    def index(client: Any) -> None:
        ConsolePage(console, client).show()

    @ui.page(TEACHER)
    def teacher(client: Any) -> None:
        TeacherPage(console, client).show()

    @app.get(ROUTE + "/{token}.png")
    def picture(token: str) -> Response:
        png = console.pictures.get(token)
        if png is None:
            return Response(status_code=404)
        return Response(png, media_type="image/png", headers={"Cache-Control": "private, max-age=3600"})


async def _probe(console: Console) -> None:
    """Whether the world asks for logins (the login card's caption: .world_kind), asked until a router answers."""
    import asyncio

    from user_peer.console.workers import LOGINS, off_loop

    from user_peer.console.world_kind import probe_logins

    while console.logins_required is None:
        console.logins_required = await off_loop(
            LOGINS, probe_logins, console.world, console.connect, console.base_file
        )
        if console.logins_required is None:
            await asyncio.sleep(5.0)


def serve(console: Console, host: str, port: int, tls: tuple[str, str] | None = None) -> None:
    """Serve the console until Ctrl-C (or SIGTERM); every logged-in world is closed on the way out.
    ``tls``: (certificate, key) PEM files to serve HTTPS (a password never crosses the LAN in clear)."""
    import os

    # NiceGUI serves its own test harness's port when it sees pytest's variable, which a console started by
    # a test inherits: this process is a real server either way
    os.environ.pop("PYTEST_CURRENT_TEST", None)
    import asyncio

    from nicegui import Client, app, background_tasks, core, ui

    console.doors.install(app, core.sio, Client, exempt=(ROUTE,), max_age=PRUNE_S)  # before ui.run starts the app

    _routes(console)

    async def report() -> None:
        while True:
            await asyncio.sleep(PERIOD_S)
            pages = sum(1 for c in Client.instances.values() if c.has_socket_connection)
            print(console.health.line(console.health.take(pages)), flush=True)
            if console.doors.any():
                print(console.doors.line(), flush=True)

    async def announce() -> None:
        """The URLs, once the port takes connections (the startup handlers run before uvicorn listens)."""
        probe = "127.0.0.1" if host in ("0.0.0.0", "") else "::1" if host == "::" else host
        while True:
            try:
                _, writer = await asyncio.open_connection(probe, port)
            except OSError:
                await asyncio.sleep(0.05)
                continue
            writer.close()
            break
        for url in page_urls(host, port, "https" if tls else "http"):
            print(f"console: open {url}", flush=True)
        if console.instructors:
            print(f"console: the teacher's page is {TEACHER} ({', '.join(console.instructors)})", flush=True)

    def started() -> None:
        # after NiceGUI's startup set them from the reconnect window
        core.sio.eio.ping_interval, core.sio.eio.ping_timeout = PING_INTERVAL_S, PING_TIMEOUT_S
        background_tasks.create(announce(), name="console announce")
        background_tasks.create(_probe(console), name="console asks whether the world asks for logins")
        background_tasks.create(console.health.probe(), name="console health probe")
        background_tasks.create(report(), name="console health report")
        background_tasks.create(console.ticker.run(), name="console redraw clock")
        background_tasks.create(
            console.doors.forget_waiting(Client.instances), name="console forgets pages that do not connect"
        )

    def dropped() -> None:
        console.health.dropped += 1

    app.on_startup(started)
    app.on_disconnect(dropped)
    app.on_shutdown(console.logins.close)
    try:
        ui.run(
            host=host,
            port=port,
            title=f"robofabric console · {console.world}",
            reload=False,
            show=False,
            show_welcome_message=False,
            reconnect_timeout=RECONNECT_S,
            message_history_length=HISTORY_MESSAGES,
            favicon="🤖",
            uvicorn_logging_level="warning",
            # no per-message deflate: it cost the server (and every browser) a compression of each update, to
            # save bytes a class LAN does not miss
            ws_per_message_deflate=False,
            # no Tailwind: its runtime compiles CSS in every page as it loads and watches every change of the
            # page for new classes; the page uses Quasar's own classes
            tailwind=False,
            **({"ssl_certfile": tls[0], "ssl_keyfile": tls[1]} if tls else {}),
        )
    except KeyboardInterrupt:  # uvicorn shuts down, then raises the Ctrl-C it caught again: we are done
        pass
    finally:
        console.logins.close()  # idempotent: the shutdown handler closed them already unless startup failed
    print("console: stopped", flush=True)

"""The console's doors: who may load a page or open a websocket, what a page that never connects costs, whose socket
may speak for a page.

A page load makes a NiceGUI ``Client`` (its elements, about 80 KiB) that waits for its websocket; 1,500 loads that
never connected grew the console by 200 MB, kept for the 180 s window and never given back to the system. So:

- **page loads** (every request that makes a ``Client``: the page, and NiceGUI's own 404 page) are a token bucket
  per address (:data:`LOADS_BURST` at once, :data:`LOADS_PER_S` a second after); the excess is answered 429 at
  once, before anything is made; while :data:`WAITING_MAX` served pages wait for their websocket, 503;
- **pages that never connect**: an address keeps its :data:`WAITING_PER_ADDRESS` newest; the older ones are
  forgotten within a second (:data:`PRUNE_EVERY_S`), and any after ``PRUNE_S`` (a slow browser on a loaded
  machine keeps its page while it loads);
- **websockets**: at most :data:`SOCKETS_PER_ADDRESS` open per address, a bucket for new ones;
- **a page's socket speaks for that page only**: NiceGUI (3.18) hands an ``event`` (a click, a key) to the
  client the message *names*, whatever socket sent it, so any socket that knew a page's ids could click its
  buttons; here an event, an ack, a log line or a JavaScript answer is taken only from a socket whose handshake
  joined that client (NiceGUI puts it in the client's room) and dropped, and counted, otherwise.

The decisions are :mod:`.limits` (pure); this module applies them.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Any, Callable

from user_peer.console.limits import Buckets, Waiting, address_key, pages_to_forget

__all__ = [
    "Doors",
    "DoorsMiddleware",
    "guard_socket_events",
    "LOADS_BURST",
    "LOADS_PER_S",
    "WAITING_PER_ADDRESS",
    "WAITING_MAX",
    "SOCKETS_PER_ADDRESS",
    "PRUNE_EVERY_S",
]

log = logging.getLogger("robofabric.console")

LOADS_BURST, LOADS_PER_S = 40, 1.0
"""Page loads per address: 40 at once (a student's tabs and reloads; a few pages side by side from one machine),
then one a second."""

WAITING_PER_ADDRESS = 32
"""Served pages an address may hold at one moment that have not connected yet; the older ones are forgotten. A
class of 32 behind one NAT address, every page loaded when the teacher says go, is all waiting at once while
the server is slow to take their websockets; below the class, its first students' pages would be forgotten
(docs/security.md). Still below :data:`LOADS_BURST`, so a flood's burst is cut to it."""

WAITING_MAX = 400
"""Served pages waiting for their websocket, from every address together (about 32 MB), before a load gets 503."""

SOCKETS_PER_ADDRESS, SOCKETS_BURST, SOCKETS_PER_S = 40, 40, 2.0
"""Websockets per address: 40 open at once, 40 new at once, then 2 a second (a dropped page reconnects)."""

PRUNE_EVERY_S = 1.0
"""How often the waiting pages are looked at."""

SOCKET_PATH = "/_nicegui_ws"
ASSET_PREFIXES = ("/_nicegui/", SOCKET_PATH, "/favicon.ico")
"""Requests that make no page: NiceGUI's assets (static, cached), the websocket (limited on its own)."""

GUARDED_EVENTS = ("event", "javascript_response", "ack", "log")
"""The socket.io messages NiceGUI routes by the client id they name."""


@dataclass
class Doors:
    """The console's limits and what they refused (the console's health report prints them)."""

    clock: Callable[[], float] = time.monotonic
    loads: Buckets = field(default_factory=lambda: Buckets(LOADS_PER_S, LOADS_BURST))
    connects: Buckets = field(default_factory=lambda: Buckets(SOCKETS_PER_S, SOCKETS_BURST))
    open_sockets: dict[str, int] = field(default_factory=dict)
    waiting: int = 0  # served pages not connected, at the last look
    refused_loads: int = 0
    refused_sockets: int = 0
    forgotten: int = 0  # served pages forgotten before they connected
    foreign: int = 0  # socket messages naming a page their socket does not belong to
    max_age: float = 180.0  # how long a served page may take to connect (the console's PRUNE_S, set by install)

    def admit_load(self, host: str) -> tuple[int, float] | None:
        """None when a page load from ``host`` may go on, else (HTTP status, seconds to wait)."""
        wait = self.loads.take(address_key(host), self.clock())
        if wait > 0:
            self.refused_loads += 1
            return 429, wait
        if self.waiting >= WAITING_MAX:
            self.refused_loads += 1
            return 503, 5.0
        return None

    def socket_opened(self, host: str) -> bool:
        """Whether a websocket from ``host`` may open (counted open when it may: :meth:`socket_closed` after)."""
        key = address_key(host)
        if self.open_sockets.get(key, 0) >= SOCKETS_PER_ADDRESS or self.connects.take(key, self.clock()) > 0:
            self.refused_sockets += 1
            return False
        self.open_sockets[key] = self.open_sockets.get(key, 0) + 1
        return True

    def socket_closed(self, host: str) -> None:
        key = address_key(host)
        n = self.open_sockets.get(key, 0) - 1
        if n > 0:
            self.open_sockets[key] = n
        else:
            self.open_sockets.pop(key, None)

    def prune(self, clients: dict[str, Any], now: float, max_age: float) -> None:
        """Forget the served pages that should not wait any longer (``clients``: NiceGUI's ``Client.instances``,
        ``now`` in its clock, ``time.time()``)."""
        waiting = [Waiting(c.id, address_key(_ip(c)), c.created) for c in list(clients.values()) if _waits(c)]
        self.waiting = len(waiting)
        for cid in pages_to_forget(waiting, now, per_address=WAITING_PER_ADDRESS, max_age=max_age):
            c = clients.get(cid)
            if c is not None and _waits(c):
                try:
                    c.delete()
                except (
                    Exception
                ):  # NiceGUI's delete raises when its table lost the client (its #1826): forgotten anyway
                    log.debug("console: forgetting page %s", cid, exc_info=True)
                self.forgotten += 1
                self.waiting -= 1

    def install(self, app: Any, sio: Any, client_cls: Any, *, exempt: tuple[str, ...] = (), max_age: float) -> None:
        """Put the doors in front of NiceGUI's ``app`` (before it starts) and guard its socket.io server ``sio``;
        ``client_cls``: NiceGUI's ``Client``; ``exempt``: path prefixes that make no page; ``max_age``: how long a
        served page may take to connect."""
        import functools

        self.max_age = max_age
        # NiceGUI's app calls Client.prune_instances() every 10 s with its 60 s default and offers no setting: the
        # threshold is its keyword argument, bound here before ui.run starts the app (which looks the method up then)
        client_cls.prune_instances = functools.partial(client_cls.prune_instances, client_age_threshold=max_age)
        app.add_middleware(DoorsMiddleware, doors=self, exempt=exempt)
        guard_socket_events(sio, client_cls.instances, self)

    async def forget_waiting(self, clients: dict[str, Any]) -> None:
        """Forever: served pages that will not connect are forgotten within a second (a line when any was)."""
        import asyncio

        while True:
            await asyncio.sleep(PRUNE_EVERY_S)
            before = self.forgotten
            self.prune(clients, time.time(), self.max_age)
            if self.forgotten != before:  # at most once a second, and only while pages are forgotten
                print(self.line(), flush=True)

    def any(self) -> bool:
        """Whether there is anything to report."""
        return bool(self.waiting or self.forgotten or self.refused_loads or self.refused_sockets or self.foreign)

    def line(self) -> str:
        return (
            f"console: doors: {self.waiting} pages waiting to connect · {self.forgotten} forgotten · refused "
            f"{self.refused_loads} page loads, {self.refused_sockets} websockets · {self.foreign} foreign socket messages"
        )


def _waits(c: Any) -> bool:
    """A served page that never connected (one that did and dropped is NiceGUI's reconnect window's)."""
    return not c.has_socket_connection and not c._delete_tasks and not c.is_deleted  # noqa: SLF001


def _ip(c: Any) -> str:
    try:
        return c.ip
    except RuntimeError:  # a client without a request
        return ""


class DoorsMiddleware:
    """ASGI middleware in front of NiceGUI: page loads and websockets per address (:class:`Doors`)."""

    def __init__(self, app: Any, doors: Doors, exempt: tuple[str, ...] = ()) -> None:
        self.app, self.doors, self.exempt = app, doors, ASSET_PREFIXES + exempt

    async def __call__(self, scope: dict, receive: Any, send: Any) -> None:
        host = (scope.get("client") or ("", 0))[0] or ""
        path = scope.get("path", "")
        if scope["type"] == "http" and not path.startswith(self.exempt):
            refused = self.doors.admit_load(host)
            if refused is not None:
                await _refuse(send, *refused)
                return
        elif scope["type"] == "websocket" and path.startswith(SOCKET_PATH):
            if not self.doors.socket_opened(host):
                await send({"type": "websocket.close", "code": 1008})
                return
            try:
                await self.app(scope, receive, send)
            finally:
                self.doors.socket_closed(host)
            return
        await self.app(scope, receive, send)


async def _refuse(send: Any, status: int, wait: float) -> None:
    body = (
        b"too many page loads from your address: try again shortly\n"
        if status == 429
        else b"the console is busy: try again shortly\n"
    )
    await send(
        {
            "type": "http.response.start",
            "status": status,
            "headers": [
                (b"content-type", b"text/plain; charset=utf-8"),
                (b"retry-after", str(max(1, round(wait))).encode()),
                (b"content-length", str(len(body)).encode()),
            ],
        }
    )
    await send({"type": "http.response.body", "body": body})


def guard_socket_events(sio: Any, clients: dict[str, Any], doors: Doors) -> None:
    """Take NiceGUI's messages that name a client only from a socket that joined that client (its handshake put
    it in the client's room); any other is dropped and counted in ``doors.foreign``."""
    handlers = sio.handlers["/"]
    for name in GUARDED_EVENTS:
        inner = handlers.get(name)
        if inner is None:
            raise RuntimeError(
                f"NiceGUI has no socket.io handler {name!r}: the console's guard of its events needs updating"
            )

        def guarded(sid: str, msg: Any, *rest: Any, _inner: Callable = inner, _name: str = name) -> Any:
            cid = msg.get("client_id") if isinstance(msg, dict) else None
            if not isinstance(cid, str) or cid not in clients or cid not in sio.rooms(sid):
                doors.foreign += 1
                log.debug(
                    "console: a socket sent %r for a page it does not belong to: dropped", _name
                )  # counted, not logged: a flood
                return None
            return _inner(sid, msg, *rest)

        handlers[name] = guarded

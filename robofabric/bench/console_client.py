"""A student's console page without a browser: NiceGUI's own socket protocol, as the page's JavaScript speaks it.

``bench console --clients N`` needs a class of pages on one box, and 20 real Chromium pages do not fit on two
cores (their drawing, not the console's serving, takes the box). What the server feels of a page is its
socket: the page's first request, the socket.io connection with the page's client id, the element tree the
server sends as ``update`` messages, the events the page sends back (a field's ``update:value``, a button's
``click``, the console's own ``rf_key`` on element 0), the answers to ``run_javascript`` and the ``ack`` of
every message it got. :class:`EmulatedPage` does exactly that, so the server does for it what it does for a
browser's page: builds her page, owns her robot, drives her base and pushes every update.

The element tree is kept as the page keeps it (``update`` replaces or deletes elements by id) and looked up
the way a person reads a page: a button by its label, a field by its label, a line by its text. A 3D view
(``ui.scene``) says ``init`` once it arrives, as three.js's component does when it is mounted: the server then
sends it every object and, from then on, every move, as it does to a browser (:func:`scenes_to_start`).

Each student comes from an address of her own, as a class's machines do: ``127.0.0.2``, ``127.0.0.3``.. (all of
127/8 is this machine's loopback on Linux), her page's load and its websocket both, through one HTTP session of
hers; the console's per-address limits (:mod:`user_peer.console.doors`) then see 32 students, not one address
loading 32 pages. ``--one-address`` puts the whole class on ``127.0.0.1``, as a class behind one NAT looks.

Run as a program (``python -m robofabric.bench.console_client URL --first K --count N``), it puts N students
(``c{K}``..) on their bases (``base{K}``..), each holding ← with speed 2 and letting go now and then as a
student steering does (the first ``--arms`` of them also own ``arm0``.. and apply IK), until SIGTERM or
``--seconds``; then it prints one JSON line of what happened.
"""

from __future__ import annotations

import ast
import asyncio
import contextlib
import json
import re
import signal
import sys
import time
import uuid
from dataclasses import dataclass, field
from typing import Any

__all__ = ["EmulatedPage", "PageGone", "parse_page", "scenes_to_start", "ClientReport", "student_address", "main"]

_ELEMENTS = re.compile(r"parseElements\(String\.raw`(.*?)`\)", re.S)
_QUERY = re.compile(r"query: (\{.*?\}),\s*\n")
_UNESCAPE = (("&#36;", "$"), ("&#96;", "`"), ("&gt;", ">"), ("&lt;", "<"), ("&amp;", "&"))  # nicegui.js's parseElements


RECONNECT_TRIES, RECONNECT_WAIT_S = 10, 30.0
"""A dropped socket's tries to reconnect (1 s apart, then up to 5 s), and how long an action waits for it."""

JOIN_WAIT_S = 120.0
"""How long a student waits for each step of her join (her page, its answer to Log in, her request's): a person
waits that long for a console a whole class is joining at once."""


def student_address(k: int) -> str:
    """The loopback address the ``k``-th student (from 0) comes from: ``127.0.0.2``.. (``127.0.0.1`` is the
    console's own and the pages'); at most 253 students, the addresses of 127.0.0.0/24 past .1."""
    if not 0 <= k <= 252:
        raise ValueError(f"student {k}: one loopback address each, 127.0.0.2 to 127.0.0.254 (at most 253 students)")
    return f"127.0.0.{2 + k}"


class PageGone(RuntimeError):
    """The server dropped the page, or an element a student needs is not on it within the time allowed."""


def parse_page(html: str) -> tuple[dict[str, dict[str, Any]], dict[str, Any]]:
    """(elements by id, the socket's query) from a NiceGUI page's HTML: the two things its script starts from.
    The query is written as a Python literal (``True``), which is why it is read with ``ast.literal_eval``."""
    m, q = _ELEMENTS.search(html), _QUERY.search(html)
    if m is None or q is None:
        raise PageGone("not a NiceGUI page: no element tree or socket query in it")
    raw = m.group(1)
    for a, b in _UNESCAPE:
        raw = raw.replace(a, b)
    return {str(k): v for k, v in json.loads(raw).items()}, dict(ast.literal_eval(q.group(1)))


def scenes_to_start(update: dict[str, Any], started: set[str]) -> list[str]:
    """The elements of an ``update`` that wait for an ``init`` from the page (a 3D view: NiceGUI sends its objects
    and their moves only once the browser's scene said it is there) and have not had it yet."""
    return [
        str(eid)
        for eid, el in update.items()
        if el is not None and str(eid) not in started and any(e.get("type") == "init" for e in (el.get("events") or []))
    ]


def _label(el: dict[str, Any]) -> str:
    props = el.get("props") or {}
    return str(props.get("label") or props.get("aria-label") or el.get("text") or "")


def _names(el: dict[str, Any]) -> tuple[str, ...]:
    """Every name a person (or a screen reader) has for an element: its label, its aria-label, its text."""
    props = el.get("props") or {}
    return tuple(str(n) for n in (props.get("label"), props.get("aria-label"), el.get("text")) if n)


@dataclass
class EmulatedPage:
    """One page: ``open`` it, then act on it by labels as a student would."""

    url: str
    elements: dict[str, dict[str, Any]] = field(default_factory=dict)
    sent: int = 0
    updates: int = 0
    js_answered: int = 0
    _query: dict[str, Any] = field(default_factory=dict)
    _next_id: int = 0
    _sio: Any = None
    _changed: asyncio.Event | None = None
    _acker: asyncio.Task | None = None
    _opened: float = 0.0
    _final: bool = False  # the socket closed for good: her own close, or no reconnection within its tries
    scenes: set[str] = field(default_factory=set)  # the 3D views told ``init`` (scenes_to_start)
    dropped_after: float | None = None  # seconds from the socket's connect to its first drop
    drops: int = 0  # times the socket dropped (each then reconnected, as a browser's page does, or was final)

    async def _on_disconnect(self, reason: Any = None) -> None:
        self.drops += 1
        if self.dropped_after is None:
            self.dropped_after = time.monotonic() - self._opened
        if self._changed is not None:
            self._changed.set()

    async def _on_final(self, *_: Any) -> None:
        self._final = True
        if self._changed is not None:
            self._changed.set()

    async def open(self, http: Any, timeout: float = 60.0) -> None:
        """Ask for the page and connect its socket (the implicit handshake of a page's first connection), both
        through ``http`` (an ``aiohttp.ClientSession``): the socket comes from the address the page was loaded from."""
        import socketio

        async with http.get(self.url, timeout=timeout) as r:
            if r.status != 200:
                raise PageGone(f"{self.url} answered {r.status}")
            self.elements, self._query = parse_page(await r.text())
        self._next_id = int(self._query.get("next_message_id", 0))
        self._changed = asyncio.Event()
        # a dropped socket reconnects to the same page, as NiceGUI's page script does (a server that stalled past
        # its ping timeout drops it), asking for the messages from the last one it has (the page keeps the others
        # for its reconnect window); the URL is read again at each try for that
        sio = socketio.AsyncClient(
            reconnection=True,
            reconnection_attempts=RECONNECT_TRIES,
            reconnection_delay=1.0,
            reconnection_delay_max=5.0,
            http_session=http,
        )
        for name in ("update", "run_javascript", "load_js_components", "notify", "open", "download"):
            sio.on(name, self._handler(name))
        sio.on("disconnect", self._on_disconnect)
        sio.on("__disconnect_final", self._on_final)
        query = {
            **self._query,
            "document_id": str(uuid.uuid4()),
            "tab_id": str(uuid.uuid4()),
            "implicit_handshake": "true",
        }
        base = self.url.rstrip("/")

        def url() -> str:
            return f"{base}/?" + "&".join(
                f"{k}={v}" for k, v in {**query, "next_message_id": str(self._next_id)}.items()
            )

        await sio.connect(url, socketio_path="/_nicegui_ws/socket.io", transports=["websocket"], wait_timeout=timeout)
        self._sio = sio
        self._opened = time.monotonic()
        self._acker = asyncio.create_task(self._ack_every(3.0))

    def _handler(self, name: str) -> Any:
        async def on(msg: Any = None) -> None:
            if isinstance(msg, dict) and "_id" in msg:
                mid = msg.pop("_id")
                if mid < self._next_id:
                    return  # already had it (a resend after a reconnect)
                self._next_id = mid + 1
            if name == "update" and isinstance(msg, dict):
                self.updates += 1
                for eid, el in msg.items():
                    if el is None:
                        self.elements.pop(str(eid), None)
                    else:
                        self.elements[str(eid)] = el
                for eid in scenes_to_start(msg, self.scenes):  # a 3D view, mounted: it says so, as three.js does
                    self.scenes.add(eid)
                    with contextlib.suppress(PageGone):
                        await self._fire(eid, "init", [])
            elif name == "run_javascript" and isinstance(msg, dict) and msg.get("request_id") is not None:
                # a page without a browser has no storage and no DOM: every answer is null, as a fresh tab's
                await self._emit("javascript_response", {"request_id": msg["request_id"], "result": None})
                self.js_answered += 1
            if self._changed is not None:
                self._changed.set()

        return on

    async def _emit(self, event: str, data: dict[str, Any]) -> None:
        deadline = time.monotonic() + RECONNECT_WAIT_S
        while self._sio is not None and not self._sio.connected and not self._final and time.monotonic() < deadline:
            await asyncio.sleep(0.1)  # reconnecting: what she does waits for it, as a page's clicks do
        if self._sio is None or not self._sio.connected:
            raise PageGone("the page's socket is closed")
        await self._sio.emit(event, {**data, "client_id": self._query["client_id"]})
        self.sent += 1

    async def _ack_every(self, period: float) -> None:
        while self.connected:
            await asyncio.sleep(period)
            try:
                await self._emit("ack", {"next_message_id": self._next_id})
            except Exception:
                return

    @property
    def connected(self) -> bool:
        """Whether the page is still there: its socket open, or reconnecting."""
        return self._sio is not None and not self._final

    def find(self, label: str, *, tag: str | None = None, exact: bool = True) -> str | None:
        """The id of the element a person would call ``label`` (its label, aria-label or text)."""
        for eid, el in self.elements.items():
            if tag is not None and el.get("tag") != tag:
                continue
            if any(n == label if exact else label in n for n in _names(el)):
                return eid
        return None

    def text(self) -> str:
        """Every label and text on the page, a line each: what a person could read."""
        return "\n".join(t for t in map(_label, self.elements.values()) if t)

    async def _until(self, check: Any, timeout: float) -> Any:
        """``check()``'s first truthy value, looked at after each message from the server, within ``timeout``
        (None if it never held, or the socket closed)."""
        assert self._changed is not None
        deadline = time.monotonic() + timeout
        while not (got := check()):
            left = deadline - time.monotonic()
            if left <= 0 or not self.connected:
                return None
            self._changed.clear()
            try:
                await asyncio.wait_for(self._changed.wait(), timeout=min(left, 0.5))
            except TimeoutError:
                pass
        return got

    async def wait_for(self, label: str, *, tag: str | None = None, exact: bool = True, timeout: float = 30.0) -> str:
        """Wait until an element called ``label`` is on the page; its id."""
        eid = await self._until(lambda: self.find(label, tag=tag, exact=exact), timeout)
        if eid is None:
            said = [t for t in self.text().splitlines() if ":" in t][-3:]  # the page's last words, to say why
            gone = (
                f"; its socket dropped {self.drops} time(s), first {self.dropped_after:.1f} s after it opened"
                + ("" if self.connected else ", and did not come back")
                if self.dropped_after is not None
                else ""
            )
            raise PageGone(
                f"no {label!r} on the page within {timeout:g} s (the page says: {' | '.join(said)[-400:]}{gone}; "
                f"{self.updates} updates, {self.js_answered} JavaScript calls answered, next message {self._next_id})"
            )
        return str(eid)

    async def wait_text(self, pred: Any, timeout: float) -> bool:
        """Wait until ``pred(self.text())`` holds; whether it did within ``timeout``."""
        return bool(await self._until(lambda: pred(self.text()), timeout))

    async def _fire(self, eid: str, kind: str, args: list[Any]) -> None:
        el = self.elements.get(eid) or {}
        listener = next((e["listener_id"] for e in el.get("events", []) if e.get("type") == kind), None)
        if listener is None:
            raise PageGone(f"{_label(el) or eid!r} takes no {kind!r}")
        await self._emit("event", {"id": int(eid), "listener_id": listener, "args": [json.dumps(a) for a in args]})

    async def fill(self, label: str, value: str, timeout: float = 30.0) -> None:
        await self._fire(await self.wait_for(label, timeout=timeout), "update:value", [value])

    async def click(self, label: str, timeout: float = 30.0) -> None:
        await self._fire(await self.wait_for(label, tag="q-btn", timeout=timeout), "click", [])

    async def type_number(self, label: str, value: float, timeout: float = 30.0) -> None:
        """A number typed into a Quasar field (its ``update:modelValue``, as the field sends it)."""
        await self._fire(await self.wait_for(label, timeout=timeout), "update:modelValue", [value])

    async def drop(self, view: str, name: str, xyz: tuple[float, float, float], timeout: float = 30.0) -> None:
        """A 3D object called ``name`` dragged in the view ``view`` and dropped at ``xyz`` (ui.scene's ``dragend``)."""
        x, y, z = xyz
        await self._fire(
            await self.wait_for(view, exact=False, timeout=timeout),
            "dragend",
            [{"type": "dragend", "object_id": "", "object_name": name, "x": x, "y": y, "z": z}],
        )

    async def key(self, key: str, down: bool) -> None:
        """The page's key line (the console's ``rf_key`` on element 0, as its KEYS_JS sends it)."""
        await self._fire("0", "rf_key", [{"key": key, "down": down, "t": int(time.time() * 1000)}])

    async def close(self) -> None:
        self.drops -= 1 if self._sio is not None and self._sio.connected else 0  # her own close is no drop
        self._final = True
        if self._acker is not None:
            self._acker.cancel()
        if self._sio is not None:
            await self._sio.disconnect()


@dataclass
class ClientReport:
    """What the emulated class did: how many got in, how long that took, and what went wrong on the way."""

    clients: int = 0
    joined: int = 0
    owners: list[str] = field(default_factory=list)
    join_s: list[float] = field(default_factory=list)
    keys: int = 0
    arms: list[str] = field(default_factory=list)
    ik_applied: int = 0
    ik_unsolved: int = 0
    back_at_login: int = 0
    disconnected: int = 0
    drops: int = 0  # sockets of joined pages that dropped (each reconnected, or counted in ``disconnected``)
    refused: int = 0
    errors: list[str] = field(default_factory=list)


REFUSED = ("NotOwner", "Rejected", "Timeout", "Unreachable", "Error")


async def _student(
    url: str,
    i: int,
    http: Any,
    report: ClientReport,
    stop: asyncio.Event,
    period: float,
    arm: str | None = None,
    target: tuple[float, float, float] | None = None,
) -> EmulatedPage | None:
    """Student ``c{i}`` logs in, selects and requests ``base{i}``, then steers: ← held, let go every ``period``.
    With an ``arm``, she requests it too, sets its IK target's height and drops the target at ``target`` in the
    3D view, and every fourth turn nudges the target 1 cm and applies IK, as the paper's Test A does by hand."""
    page = EmulatedPage(url)
    t0 = time.monotonic()

    async def join() -> None:
        await page.open(http, timeout=JOIN_WAIT_S)
        await page.fill("Name", f"c{i}", timeout=JOIN_WAIT_S)
        await page.click("Log in", timeout=JOIN_WAIT_S)
        await page.click(f"base{i}", timeout=JOIN_WAIT_S)
        await page.click("Request", timeout=JOIN_WAIT_S)
        await page.wait_for(f"request base{i}: you own it", exact=False, timeout=JOIN_WAIT_S)
        await page.key("2", True)  # speed 2, as the pages drive
        await page.key("2", False)
        if arm is not None:
            await page.click(arm, timeout=JOIN_WAIT_S)
            await page.click("Request", timeout=JOIN_WAIT_S)
            await page.wait_for(f"request {arm}: you own it", exact=False, timeout=JOIN_WAIT_S)
            if target is not None:
                await page.type_number("IK target height z (m)", target[2])
                await page.drop("drag the orange sphere", "ik-target", target)

    joining, stopping = asyncio.create_task(join()), asyncio.create_task(stop.wait())
    await asyncio.wait({joining, stopping}, return_when=asyncio.FIRST_COMPLETED)
    stopping.cancel()
    if not joining.done():
        joining.cancel()
        with contextlib.suppress(BaseException):
            await joining
    why = "stopped first" if joining.cancelled() else joining.exception()
    if why is not None:
        report.errors.append(f"c{i}: did not join: {why}")
        await page.close()
        return None
    report.joined += 1
    report.owners.append(f"c{i}")
    if arm is not None:
        report.arms.append(arm)
    report.join_s.append(time.monotonic() - t0)
    down, turns = False, 0
    while not stop.is_set() and page.connected:
        down = not down
        turns += 1
        try:
            await page.key("ArrowLeft", down)
            report.keys += 1
            if arm is not None and turns % 8 == 0:  # every fourth press: the target 1 cm out or back, then IK
                await page.click("x plus" if turns % 16 else "x minus", timeout=5)
                # as a person does: see the line say it is solving, then read the answer before applying it
                await page.wait_text(lambda t: "IK: solving..." in t, 2.0)
                await page.wait_text(lambda t: "IK: solving..." not in t, 10.0)
                if "IK: [" in page.text():
                    await page.click("Apply IK", timeout=5)
                    report.ik_applied += 1
                else:
                    report.ik_unsolved += 1
        except PageGone:
            break
        try:
            await asyncio.wait_for(stop.wait(), timeout=period * (1.0 if down else 0.25))
        except TimeoutError:
            pass
    if page.connected:
        try:
            await page.key("ArrowLeft", False)
        except PageGone:
            pass
    return page


async def run_class(
    url: str,
    first: int,
    count: int,
    seconds: float,
    period: float = 1.0,
    started: Any = None,
    arms: int = 0,
    targets: list[tuple[float, float, float]] | None = None,
    one_address: bool = False,
) -> ClientReport:
    """``count`` students at once on the console at ``url``; until ``seconds`` pass (or SIGTERM/SIGINT). The
    first ``arms`` of them also own ``arm0``.. and apply IK now and then, from ``targets[k]`` (world frame). Each
    comes from her own loopback address (:func:`student_address`), or all from 127.0.0.1 with ``one_address``."""
    import aiohttp

    report = ClientReport(clients=count)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        try:
            loop.add_signal_handler(sig, stop.set)
        except (NotImplementedError, RuntimeError):
            pass
    # one session (connection pool, cookie jar) a student, bound to her address: her page and its socket share it
    sessions = [
        aiohttp.ClientSession(
            connector=None if one_address else aiohttp.TCPConnector(local_addr=(student_address(k), 0))
        )
        for k in range(count)
    ]
    try:
        aims = list(targets or [])
        tasks = [
            asyncio.create_task(
                _student(
                    url,
                    first + k,
                    sessions[k],
                    report,
                    stop,
                    period,
                    f"arm{k}" if k < arms else None,
                    aims[k] if k < min(arms, len(aims)) else None,
                )
            )
            for k in range(count)
        ]

        async def said_joined() -> None:
            while report.joined + len(report.errors) < count:
                await asyncio.sleep(0.05)
            if started is not None:
                started(report)

        watcher = asyncio.create_task(said_joined())
        try:
            await asyncio.wait_for(stop.wait(), timeout=seconds)
        except TimeoutError:
            pass
        stop.set()
        pages = [p for p in await asyncio.gather(*tasks) if p is not None]
        watcher.cancel()
        for k, p in enumerate(pages):
            report.drops += p.drops
            words = p.text()
            if not p.connected:
                report.disconnected += 1
            elif p.find("Log in", tag="q-btn") is not None:
                report.back_at_login += 1
            elif any(w in words for w in REFUSED):
                report.refused += 1
                if len(report.errors) < 5:  # what the page said: a refusal, or a word of one in other text
                    said = next(ln for ln in words.splitlines() if any(w in ln for w in REFUSED))
                    report.errors.append(f"a page of the class refused ({k}): {said[:200]}")
            await p.close()
    finally:
        for http in sessions:
            await http.close()
    return report


def main(argv: list[str] | None = None) -> int:
    import argparse

    ap = argparse.ArgumentParser(prog="python -m robofabric.bench.console_client", description=__doc__.split("\n\n")[0])
    ap.add_argument("url")
    ap.add_argument("--first", type=int, default=0, help="the first student's number (c{first} drives base{first})")
    ap.add_argument("--count", type=int, default=1, help="how many students")
    ap.add_argument("--seconds", type=float, default=60.0, help="how long they drive at most (SIGTERM ends sooner)")
    ap.add_argument("--period", type=float, default=1.0, help="how long ← is held before it is let go (s)")
    ap.add_argument("--arms", type=int, default=0, help="the first ARMS students also own arm0.. and apply IK")
    ap.add_argument("--targets", default="", help="each arm's first IK target in the world frame: x,y,z;x,y,z;...")
    ap.add_argument(
        "--one-address",
        action="store_true",
        help="every student from 127.0.0.1 (a class behind one NAT), not each from her own 127.0.0.N",
    )
    a = ap.parse_args(argv)
    targets = [tuple(float(v) for v in t.split(",")) for t in a.targets.split(";") if t.strip()]

    def joined(r: ClientReport) -> None:
        print(f"clients: {r.joined} of {r.clients} joined", flush=True)

    report = asyncio.run(
        run_class(
            a.url,
            a.first,
            a.count,
            a.seconds,
            a.period,
            started=joined,
            arms=a.arms,
            targets=targets,
            one_address=a.one_address,
        )
    )  # type: ignore[arg-type]
    print(json.dumps(report.__dict__), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

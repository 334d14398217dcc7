"""Logins: one zenoh session per logged-in student, in her own name and with her own password.

The console holds no credential of its own. A page's login builds a client config from the class's
router endpoint plus the typed name and password (the ``transport/auth/usrpwd`` of her ``NAME.json5``,
written by ``robofabric secure init``), so the router checks her exactly as it checks her scripts; a
wrong password or unknown name is the router's refusal, shown on the page. In an open world (a router
without logins) she leaves the password empty and picks a name.

Her pages (two tabs, a reload) share her session: the router knows one session per login. When her
last page goes away its world is not closed at once: her robots are stopped, and the world is
closed (her robots released to the next in the queue) after ``grace`` seconds, unless she logs in
again with the same name and password within it and gets the same world back.

A reload keeps her session: a login hands her tab a :class:`Ticket` (a random token the tab keeps in its
``sessionStorage``, the server only its SHA-256), and the reloaded tab presents it to get her world back
without her password, with what the tab's event log held and the robot she had selected. A ticket is good
while her world is held (her pages, then the grace) and ends when she logs out (:meth:`Logins.logout`: her
robots stop and her session closes at once, in every tab of hers).
"""

from __future__ import annotations

import hashlib
import hmac
import math
import json
import logging
import secrets
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Callable

from fabric import keys
from fabric.config import ConfigError, FabricConfig
from user_peer.console.limits import LoginThrottle
from user_peer.errors import FabricUserError

__all__ = ["LoginError", "Logins", "Ticket", "login_config", "LOG_LINES"]

LOG_LINES = 200
"""The event log lines a tab keeps (its ``ui.log``'s) and gets back after a reload."""

log = logging.getLogger("robofabric.console")


class LoginError(FabricUserError):
    """A login the page refuses or the router refused; ``reason`` is what the page shows."""


def login_config(
    world: str, connect: tuple[str, ...], name: str, password: str, *, base_file: str | None = None
) -> FabricConfig:
    """The client config of one page's session: the router's endpoints, the console's base zenoh config file
    if any (e.g. TLS settings), and the student's usrpwd login when she typed a password."""
    try:
        keys.validate_id(name, what="name")
    except ValueError as exc:
        raise LoginError(str(exc)) from None
    extra: tuple[tuple[str, str], ...] = ()
    if password:
        extra = (
            ("transport/auth/usrpwd/user", json.dumps(name)),
            ("transport/auth/usrpwd/password", json.dumps(password)),
        )
    try:
        return FabricConfig(world=world, profile="client", connect=connect, config_file=base_file, extra=extra)
    except ConfigError as exc:
        raise LoginError(str(exc)) from None


@dataclass(eq=False)
class Ticket:
    """What one tab of hers keeps across a reload: her name, its event log's lines (text, classes), the events
    and owners it had seen (so nothing is logged twice or lost), the robot she had selected."""

    name: str
    lines: deque = field(default_factory=lambda: deque(maxlen=LOG_LINES))
    events_seen: int = 0
    owners: dict[str, str] = field(default_factory=dict)
    selected: str | None = None
    holder: object = None  # the page that writes to it now (the one before a reload lingers a while)


def _digest(token: str) -> str:
    return hashlib.sha256(token.encode()).hexdigest()


@dataclass
class _Held:
    world: object  # user_peer.World
    password: str
    pages: int = 1
    closer: threading.Timer | None = None
    tickets: dict[str, Ticket] = field(default_factory=dict)  # by the SHA-256 of their tokens


class Logins:
    """The worlds of the logged-in pages, by user. Thread-safe: logins run off the page's event loop.

    ``open_world(config, name)`` opens a world (``user_peer.api.World``); ``on_leave(world)`` stops what
    her page was driving when the page goes. Failed logins are throttled per name and per address with a
    growing delay (:class:`~.limits.LoginThrottle`, ``clock`` its time): a guess waits its turn without
    reaching the router."""

    def __init__(
        self,
        open_world: Callable[[FabricConfig, str], object],
        *,
        grace: float,
        on_leave: Callable[[object], None],
        throttle: LoginThrottle | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._open = open_world
        self.grace = grace
        self._on_leave = on_leave
        self._held: dict[str, _Held] = {}
        self._lock = threading.Lock()
        self.throttle = throttle or LoginThrottle()
        self._clock = clock
        self.refused = 0  # logins refused (wrong password, unknown name, bad name, nobody there)
        self.throttled = 0  # logins not tried: too many failures of that name or from that address

    def login(self, config: FabricConfig, name: str, password: str, address: str = ""):
        """Her world: a new session, or the one she already has (another tab of hers, or the page she left
        within the grace), for the same password only: the router knows one session per login, so her
        pages share it. :class:`LoginError` if the router refuses her, or if ``name`` or ``address`` (the
        page's) failed too often lately (then nothing is tried)."""
        with self._lock:
            wait = self.throttle.wait(name, address, self._clock())
            if wait > 0:
                self.throttled += 1
                raise LoginError(
                    f"Too many failed logins for {name} or from this address: try again in {math.ceil(wait)} s"
                )
            try:
                held = self._shared(name, password)
            except LoginError:
                self.throttle.failed(name, address, self._clock())
                raise
            if held is not None:
                self.throttle.succeeded(name, address)
                return held
        try:
            world = self._open(config, name)
        except FabricUserError as exc:
            with self._lock:
                self.refused += 1
                if _is_refusal(exc.reason):  # the router's no, not a router that is not there
                    self.throttle.failed(name, address, self._clock())
            raise LoginError(_refusal(name, password, exc.reason)) from None
        with self._lock:
            self.throttle.succeeded(name, address)
            held = self._shared(name, password)  # two of her pages logged in at once: the first session serves both
            if held is None:
                self._held[name] = _Held(world, password)
        if held is not None:
            _close(world)
            return held
        log.info("console: %s logged in", name)
        return world

    def _shared(self, name: str, password: str):
        """Her open world for another page of hers (the lock held); None when she has none."""
        held = self._held.get(name)
        if held is None:
            return None
        if not hmac.compare_digest(held.password.encode(), password.encode()):
            self.refused += 1
            # the router's own words for a wrong password: a guesser learns nothing about who is logged in
            raise LoginError(_refusal(name, password, "authentication failed"))
        if held.closer is not None:
            held.closer.cancel()
            held.closer = None
            log.info("console: %s is back within the grace", name)
        held.pages += 1
        return held.world

    def ticket(self, name: str) -> tuple[str, Ticket]:
        """A new tab's ticket (its token, and what it keeps) for her held world: a reload of that tab presents the
        token to :meth:`resume`."""
        token = secrets.token_urlsafe(32)
        t = Ticket(name)
        with self._lock:
            held = self._held.get(name)
            if held is None:
                raise LoginError(f"{name} is not logged in")
            held.tickets[_digest(token)] = t
        return token, t

    def resume(self, token: str):
        """Her world and the tab's :class:`Ticket` for a token a reloaded tab presents, counted as one more
        page of hers (and back within the grace); None when the token is unknown, or her session ended."""
        d = _digest(token or "")
        with self._lock:
            for name, held in self._held.items():
                t = held.tickets.get(d)
                if t is not None:
                    if held.closer is not None:
                        held.closer.cancel()
                        held.closer = None
                        log.info("console: %s is back within the grace (a reload)", name)
                    held.pages += 1
                    return held.world, t
        return None

    def logout(self, name: str, world: object) -> None:
        """She logged out: her tickets end, her robots stop and her session closes now (every tab of hers)."""
        with self._lock:
            held = self._held.get(name)
            if held is None or held.world is not world:
                return
            del self._held[name]
            if held.closer is not None:
                held.closer.cancel()
        try:
            self._on_leave(world)
        except Exception:
            log.exception("console: stopping %s's robots failed", name)
        log.info("console: %s logged out", name)
        _close(world)

    def leave(self, name: str, world: object | None = None) -> None:
        """Her page went away: stop her robots now, close her world after the grace. ``world``: the page's, when
        it had one (a page of a session she logged out of, then logged in anew, leaves nothing of the new one)."""
        with self._lock:
            held = self._held.get(name)
            if held is None or (world is not None and held.world is not world):
                return
            held.pages -= 1
            if held.pages > 0:
                return
            held.closer = threading.Timer(self.grace, self._expire, args=(name, held))
            held.closer.daemon = True
            held.closer.start()
        try:
            self._on_leave(held.world)
        except Exception:
            log.exception("console: stopping %s's robots failed", name)

    def _expire(self, name: str, held: _Held) -> None:
        with self._lock:
            if self._held.get(name) is not held or held.closer is None:
                return  # she came back
            del self._held[name]
        log.info("console: %s's page left %.0f s ago: her world closes", name, self.grace)
        _close(held.world)

    def users(self) -> list[str]:
        with self._lock:
            return sorted(self._held)

    def pages(self) -> dict[str, int]:
        """Each logged-in user's open pages on this console (0 while her grace runs)."""
        with self._lock:
            return {name: max(0, h.pages) if h.closer is None else 0 for name, h in self._held.items()}

    def close(self) -> None:
        """Close every world (the console stops)."""
        with self._lock:
            held, self._held = list(self._held.values()), {}
        for h in held:
            if h.closer is not None:
                h.closer.cancel()
            _close(h.world)


def _close(world: object) -> None:
    try:
        world.close()  # type: ignore[attr-defined]
    except Exception:
        log.exception("console: closing a world failed")


def _refusal(name: str, password: str, reason: str) -> str:
    """The page's words for a session that did not open."""
    if _is_refusal(reason):
        if password:
            return f"Login failed for {name}: wrong password or unknown name (the router refused this login)"
        return f"Login failed for {name}: this world needs a password (the router refused a login without one)"
    return f"Could not join: {reason}"


def _is_refusal(reason: str) -> bool:
    """Whether the router refused the login (a wrong password or name), not that it could not be reached."""
    return "authentication failed" in reason or "refused" in reason

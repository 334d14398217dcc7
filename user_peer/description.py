"""The world's description (robots, types, limits, sensors) as a user peer asks for it and keeps it.

It is the union of every live sim's part (a world served by several sims). A sim may start after the user, so
the first look waits for one to serve it; while a live sim describes no robot (a standby, which may take a
shard over without any token changing, or a sim still starting) it is asked again at most every
:data:`REDESCRIBE_S` seconds.
"""

from __future__ import annotations

import time
from typing import Callable

from fabric import keys
from fabric.interfaces import ServiceError, WorldInfo
from fabric.session import Fabric
from user_peer import services
from user_peer.errors import Timeout, Unreachable

__all__ = ["REDESCRIBE_S", "WorldDescription"]

REDESCRIBE_S = 1.0
"""How often :meth:`WorldDescription.get` asks again while a live sim describes no robot of the world (a standby)."""


class WorldDescription:
    """``current``: the description in use, None until asked or after :meth:`forget`; ``known``: the last one
    seen (which robots a departed sim served). ``live_sims()``: the ids of the sims alive now."""

    def __init__(
        self, fabric: Fabric, world: str, *, live_sims: Callable[[], list[str]], timeout: float, join_timeout: float
    ) -> None:
        self.fabric = fabric
        self.world = world
        self.timeout = timeout
        self.join_timeout = join_timeout
        self.current: WorldInfo | None = None
        self.known: WorldInfo | None = None
        self._live_sims = live_sims
        self._asked_at = 0.0  # when it was asked for (monotonic)

    def forget(self) -> None:
        """Ask again next time (a sim came or went: a shard's robots join or leave the world)."""
        self.current = None

    def get(self, *, refresh: bool = False, timeout: float | None = None) -> WorldInfo:
        """The description; the first call waits up to ``timeout`` (default ``join_timeout``) for a sim to serve it."""
        if self.current is None or refresh:
            self.current = self.fetch(self.join_timeout if timeout is None else timeout)
        elif time.monotonic() - self._asked_at > REDESCRIBE_S and set(self._live_sims()) - {
            r.sim for r in self.current.robots
        }:
            self._asked_at = time.monotonic()
            try:
                self.current = self.fetch(min(1.0, self.timeout))
            except (Timeout, Unreachable):
                pass  # keep what we had: the world's own trouble is reported by its tokens
        return self.current

    def fetch(self, wait: float) -> WorldInfo:
        """The description, asked again until a sim serves it or ``wait`` s pass. :class:`Timeout` names the
        sims alive and the last answer; a sim that refuses to describe its world is :class:`Unreachable` at once."""
        key = keys.srv(self.world, "world")
        t0 = time.monotonic()
        deadline = t0 + wait
        last = ""
        while True:
            left = deadline - time.monotonic()
            try:
                # at most a few seconds per try: a query sent before any sim existed is never answered later
                info = services.world_info(self.fabric, timeout=max(0.05, min(left, 2.0)))
                self.known = info
                self._asked_at = time.monotonic()
                return info
            except ServiceError as exc:
                if not exc.reason.startswith("no reply"):
                    raise Unreachable(
                        f"the sim of world {self.world!r} refused its description: {exc.reason}"
                    ) from None
                last = exc.reason
            left = deadline - time.monotonic()
            if left <= 0:
                break
            time.sleep(min(0.2, left))  # no queryable yet: zenoh answers at once, so pace the retries
        sims = sorted(pid for _, pid in self.fabric.live_peers("sim", timeout=0.5))
        seen = f"sim peers alive: {', '.join(sims)}" if sims else "no sim peer alive in this world"
        raise Timeout(
            f"no world description for {self.world!r} after {time.monotonic() - t0:.1f} s of waiting: "
            f"nobody served {key} ({seen}; last answer: {last}). Is a sim peer running on world {self.world!r}?"
        )

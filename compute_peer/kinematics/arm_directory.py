"""The arms one kinematics service serves, and how it learns them from the sims' world description.

One Pinocchio model per robot type, each arm placed at its base pose (:class:`PlacedArm`). Arms are given
(worlds without a sim to ask) or learnt from ``srv/world`` (:mod:`compute_peer.world_lookup`): in the
background when a sim comes or goes or joints of an unknown arm arrive, at most once a second; and before a
request for an arm not known yet is refused, waiting up to its timeout for a lookup. Once the world has
answered with the sims there are now, an unknown id is refused at once, so a flood of made-up ids never
stalls the service. Lookups never run on a Zenoh callback thread.

A lookup the sims did not answer in time (a starved world) is tried again later, each time waiting longer for the
answer, until one comes: nothing else sets one off while the same sims stay (a compute peer started beside two
starved sims, in a whole `make test` at load 30, knew no arm 90 s on).
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass
from typing import Callable

from fabric import keys
from fabric.interfaces import NoReply, ServiceError
from fabric.limits import quote
from fabric.rate import Clock
from fabric.session import Fabric
from robots.kinds import facts

from ..world_lookup import BackgroundLookup, described_robots
from .arm import PlacedArm
from .model import ArmModel

log = logging.getLogger("robofabric.kinematics")

DISCOVERY_INTERVAL = 1.0  # s between two srv/world lookups set off by streams
REQUEST_DISCOVERY_INTERVAL = 0.2  # s: a request for an unknown arm may look again this soon (a sim that just came)
LOOKUP_TIMEOUT_S = 2.0  # s a lookup waits for the sims' answers
# s: a lookup that went unanswered is tried again after 1, 2, 4, 8, 8, ... s, each waiting that much longer
RETRY_MAX_S = 8.0


@dataclass(frozen=True, slots=True)
class ArmPlacement:
    """What the service needs of one arm: its robot type and base pose (x, y, z, yaw) in the world."""

    type: str
    pose: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)


class ArmDirectory:
    """Robot id -> placed arm; ``discover``: learn them from ``srv/world``. Failed lookups count in
    ``counters["discovery_failed"]`` (the service's counters). Background lookups only once started."""

    def __init__(self, fabric: Fabric, *, discover: bool, clock: Clock, counters: dict[str, int]) -> None:
        self.fabric = fabric
        self.discovering = bool(discover)
        self.counters = counters
        self._lock = threading.RLock()
        self._models: dict[str, ArmModel] = {}
        self._arms: dict[str, PlacedArm] = {}
        self._not_arms: set[str] = set()  # the world's other robots (bases): their joints are not an IK's seed
        self._lookup = BackgroundLookup(
            self.discover,
            name="kinematics-discovery",
            clock=clock,
            on_error=lambda exc: self._failed(f"{type(exc).__name__}: {exc}"),
        )
        self._last_error = ""
        self._sims_changed = 0  # bumped when a sim peer comes or goes: the world's arms may have changed
        self._answered_at = -1  # the value of _sims_changed when srv/world last answered
        self._started = False
        self._closed = False
        self._retry_s = DISCOVERY_INTERVAL  # the wait before the next retry of an unanswered lookup
        self._retry: threading.Timer | None = None
        # called with the arms' names after each lookup the sims answered, outside the lock (the service hears
        # those arms' joints alone from then on); in the thread that looked up, which may be zenoh's
        self.on_answered: Callable[[list[str]], None] | None = None

    def add(self, robot: str, placement: ArmPlacement) -> PlacedArm:
        """Serve ``robot`` (an arm of type ``placement.type`` at ``placement.pose``)."""
        keys.validate_id(robot, what="robot id")
        with self._lock:
            model = self._models.get(placement.type)
            if model is None:
                model = self._models[placement.type] = ArmModel(placement.type)
            arm = self._arms[robot] = PlacedArm(model, placement.pose)
        return arm

    @property
    def names(self) -> list[str]:
        with self._lock:
            return sorted(self._arms)

    def get(self, robot: str) -> PlacedArm | None:
        """The arm ``robot`` if known now (no lookup)."""
        with self._lock:
            return self._arms.get(robot)

    @property
    def answered(self) -> bool:
        """Whether the sims there are now have answered ``srv/world`` (before that, no id is known to be unknown)."""
        with self._lock:
            return self._answered_at == self._sims_changed

    def not_an_arm(self, robot: str) -> bool:
        """Whether a sim described ``robot`` as a robot of another kind (a base publishes joints too: its wheels)."""
        with self._lock:
            return robot in self._not_arms and robot not in self._arms

    def find(self, robot: str) -> PlacedArm:
        """The arm ``robot``, looked up first when unknown; :class:`ServiceError` naming the known ones otherwise."""
        arm = self.get(robot)
        if arm is None and self.discovering:
            self._look_now()
            arm = self.get(robot)
        if arm is None:
            raise ServiceError(
                f"unknown arm {quote(robot, 64)}: this compute peer serves {', '.join(self.names) or 'no arms yet'}"
            )
        return arm

    def discover(self, timeout: float = 2.0) -> int:
        """Learn the arms of the world from the sim peers' ``srv/world``; returns how many are known."""
        with self._lock:
            generation = self._sims_changed
        try:
            described = described_robots(self.fabric, None, timeout=timeout)
        except NoReply as exc:
            # no sim yet: normal when the compute starts first (`robofabric up`); its token brings a lookup
            nobody = "nobody serves it" in str(exc)
            self._failed(str(exc), quiet=nobody)
            if not nobody:
                self._retry_later()
            return len(self.names)
        except ServiceError as exc:
            self._failed(str(exc))
            self._retry_later()
            return len(self.names)
        with self._lock:
            self._answered_at = generation
            self._retry_s = DISCOVERY_INTERVAL
            self._not_arms |= {r.id for r in described if not facts(r.kind).chain}  # a sim late to answer loses none
        for r in described:
            if not facts(r.kind).chain or self.get(r.id) is not None:
                continue
            try:
                self.add(r.id, ArmPlacement(r.type, tuple(float(v) for v in r.pose)))
                log.info("serving kinematics for %s (%s)", r.id, r.type)
            except Exception as exc:  # a robot type this installation has no model for
                log.warning("cannot serve kinematics for %s (%s): %s", r.id, r.type, exc)
        names = self.names
        if self.on_answered is not None:
            self.on_answered(names)
        return len(names)

    def _failed(self, why: str, *, quiet: bool = False) -> None:
        self.counters["discovery_failed"] = self.counters.get("discovery_failed", 0) + 1
        # said once per distinct reason; "nobody serves it" (no sim yet) is normal at a start: not a warning
        if why != self._last_error:
            self._last_error = why
            log.log(logging.INFO if quiet else logging.WARNING, "looking the world's arms up: %s", why)

    def _retry_later(self) -> None:
        """Look the world up again after a wait that doubles each time (see the module), with as much longer to
        answer; one retry pending at a time."""
        with self._lock:
            if self._closed or (self._retry is not None and self._retry.is_alive()):
                return
            delay = self._retry_s
            self._retry_s = min(2 * delay, RETRY_MAX_S)
            self._retry = threading.Timer(delay, self._retry_now, args=(LOOKUP_TIMEOUT_S + delay,))
            self._retry.name, self._retry.daemon = "kinematics-discovery-retry", True
            self._retry.start()

    def _retry_now(self, timeout: float) -> None:
        if self._started and not self._closed:
            self._lookup.start(0.0, timeout=timeout)

    def sim_seen(self, kind: str, peer: str, alive: bool) -> None:
        """A sim came or went (the peers watch's callback): look the world up again now (its description may
        name other arms)."""
        with self._lock:
            self._sims_changed += 1
        self._lookup.again_now()
        self.look_soon()

    def start(self) -> None:
        """Background lookups may run from now on; the first one starts now."""
        with self._lock:
            self._started = True
        if self.discovering:
            self.look_soon()

    def look_soon(self) -> None:
        """Look the world up in a thread (never inside a Zenoh callback), at most once a second; not before
        ``start()``, which looks it up itself (a sim's token seen while declaring only marks the world changed)."""
        if self._started:
            self._lookup.start(DISCOVERY_INTERVAL)

    def _look_now(self, timeout: float = 2.0) -> None:
        """Look the world up before answering a request for an arm not known yet (a sim that just came,
        or joints that have not arrived): the request waits up to ``timeout`` rather than failing.

        Runs in the query's own handler thread; joins a lookup already under way."""
        deadline = time.monotonic() + timeout
        while True:
            with self._lock:
                if self._answered_at == self._sims_changed or self._closed:
                    return
            wait = self._lookup.until_allowed(REQUEST_DISCOVERY_INTERVAL)
            if self._lookup.claim(REQUEST_DISCOVERY_INTERVAL):
                self._lookup.run(max(0.1, deadline - time.monotonic()))
                return
            left = deadline - time.monotonic()
            if left <= 0:
                return
            if self._lookup.running:
                self._lookup.wait(left)
                return
            time.sleep(min(max(wait, 0.01), left))

    def close(self) -> None:
        """No more lookups; a request waiting for one returns."""
        with self._lock:
            self._closed = True
            retry = self._retry
        if retry is not None:
            retry.cancel()
        self._lookup.close()


__all__ = [
    "ArmDirectory",
    "ArmPlacement",
    "DISCOVERY_INTERVAL",
    "LOOKUP_TIMEOUT_S",
    "REQUEST_DISCOVERY_INTERVAL",
    "RETRY_MAX_S",
]

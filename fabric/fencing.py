"""Fencing by term: which state a consumer may believe.

A world's authority (the sim peer that owns the robots and the ownership records) stamps its
term on every message it writes (:attr:`fabric.interfaces.Header.term`).
A standby that takes the world over raises the term; a primary that comes back from a freeze still
stamps the old one until it notices and steps down. Consumers keep the highest term they have seen
per world and ignore authority state stamped with a lower one, so for them there is never more than
one authority, whatever the wire carries for a moment.

Terms are scoped by authority object, not by world (docs/sim.md, "Several sims, one world"): several sims
may serve one world, each the authority of its own robots with terms of its own (a shard's standby takes
over with its shard's term + 1, and the other shards' terms do not move). A fence keeps the highest term
per *scope*: the robot a stream or a record is about (``robot/{id}/...``, ``own/{id}``), or the robots a
``srv/world`` / ``srv/state`` answer describes (:func:`authority_scopes`).

Only authority keys are fenced (:func:`is_authority_key`): robot state streams the sim writes, the
ownership records and the world description. Everything users, compute peers and tools write carries
term 0 and is never compared. Pure: no zenoh, no clock.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

from fabric import keys, streams

__all__ = [
    "AUTHORITY_STREAMS",
    "Fence",
    "FenceVerdict",
    "SimFence",
    "MAX_DEPARTED_SIMS",
    "MAX_SCOPES",
    "WORLD_SCOPE",
    "authority_scopes",
    "fenced_scopes",
    "is_authority_event",
    "is_authority_key",
]

AUTHORITY_STREAMS = frozenset(s.name for s in streams.STREAMS if s.fenced)
"""Robot streams only a sim authority writes (:attr:`fabric.streams.RobotStream.fenced`; paths and IK results come
from compute peers)."""

MAX_DEPARTED_SIMS = 256
"""Ids of sims whose token went, kept so their late samples cannot re-raise a reset fence (bounded:
anyone may declare a token)."""

MAX_SCOPES = 4096
"""Scopes a fence keeps (robots and objects of a world; bounded: a made-up id must not grow it)."""

WORLD_SCOPE = ""
"""The scope of authority state that names no robot (a ``srv/world`` answer without robots)."""


def _parsed(key: str) -> keys.ParsedKey | None:
    try:
        return keys.parse(key)
    except ValueError:
        return None


def _is_authority(p: keys.ParsedKey) -> bool:
    if p.category == "robot":
        return p.leaf in AUTHORITY_STREAMS
    if p.category == "own":  # own/{obj}: the record (own/{obj}/by/{user} is a user's request)
        return True
    if p.category == "srv":
        return p.subject in ("world", "state")
    return False


def _scopes(p: keys.ParsedKey | None, msg: object) -> tuple[str, ...]:
    if p is None:
        return (WORLD_SCOPE,)
    if p.category in ("robot", "own") and p.subject:
        return (p.subject,)
    if msg is not None and not hasattr(msg, "robots"):
        return ()  # an answer that is no world state (a sim saying which shard it is): nothing to fence
    robots = getattr(msg, "robots", None)
    if robots:
        ids = tuple(dict.fromkeys(str(getattr(r, "id", "")) for r in robots))
        return ids if all(ids) else (WORLD_SCOPE,)
    return (WORLD_SCOPE,)


def is_authority_key(key: str) -> bool:
    """Whether ``key`` carries state only the world's sim authority writes."""
    p = _parsed(key)
    return p is not None and _is_authority(p)


def authority_scopes(key: str, msg: object = None) -> tuple[str, ...]:
    """The authority objects whose terms fence ``key``'s message: the robot or object it is about, or, for
    ``srv/world`` and ``srv/state``, the robots ``msg`` describes (``(WORLD_SCOPE,)`` when it names none; ``()``,
    nothing to fence, for an answer that is no world state)."""
    return _scopes(_parsed(key), msg)


def fenced_scopes(key: str, msg: object = None) -> tuple[str, ...] | None:
    """:func:`authority_scopes` for an authority key, None for any other: the key parsed once, as every
    subscriber does for every message it fences."""
    p = _parsed(key)
    return _scopes(p, msg) if p is not None and _is_authority(p) else None


NOT_SIM_EVENTS = frozenset({keys.DECODE, "compute"})
"""Event chunks others than sims write: decode reports (every login, ``event/decode/by/{login}``) and the
compute peers' (``event/compute/**``). A class's router lets only sims write the rest of ``event/**``."""


def is_authority_event(key: str) -> bool:
    """Whether an event on ``key`` can only have come from a sim (docs/security.md): a client acts on such an
    event alone (and only when its source is the object's authority); what any login may write is display-only."""
    try:
        p = keys.parse(key)
    except ValueError:
        return False
    return p.category == "event" and p.subject not in NOT_SIM_EVENTS


@dataclass(frozen=True, slots=True)
class FenceVerdict:
    """``accept``: believe the message; ``raised``: it carried a higher term than any before."""

    accept: bool
    raised: bool = False


class Fence:
    """The highest term seen; thread-safe. ``check(term)`` says whether to believe a message."""

    def __init__(self, term: int = 0) -> None:
        self._term = int(term)
        self._lock = threading.Lock()
        self.stale = 0

    @property
    def term(self) -> int:
        return self._term

    def check(self, term: int) -> FenceVerdict:
        """Accept ``term`` if it is at least the highest seen (raising that mark); count and refuse it otherwise."""
        with self._lock:
            if term < self._term:
                self.stale += 1
                return FenceVerdict(False)
            raised = term > self._term
            self._term = term
            return FenceVerdict(True, raised)

    def reset(self) -> None:
        """Forget the highest term: the world's last sim left, and a sim started afresh begins at term 1."""
        with self._lock:
            self._term = 0

    def raise_to(self, term: int) -> None:
        """Never go below ``term`` from now on (an authority taking over fences its own past)."""
        with self._lock:
            self._term = max(self._term, int(term))


class SimFence:
    """One world's fences, one per authority scope (:func:`authority_scopes`), and the sim peers it follows
    (their liveliness tokens); thread-safe.

    A scope's fence resets when the sim whose term it holds leaves (its shard may restart from scratch, term
    1, while other sims serve the world), and every fence resets when the world's last sim leaves; a departed
    sim's late samples, in flight when it left, are refused so that they cannot raise a fence again over
    the new sim. Sessions and the recorder's sink keep one per world they fence."""

    def __init__(self) -> None:
        self.fences: dict[str, Fence] = {}
        self._holder: dict[str, str] = {}  # scope -> the sim whose term its fence holds
        self.sims: set[str] = set()
        self.resets = 0
        self.stale = 0
        self._departed: set[str] = set()
        self._lock = threading.Lock()

    def term(self, scope: str = WORLD_SCOPE) -> int:
        """The highest term believed in ``scope`` (0: none yet, or reset)."""
        with self._lock:
            f = self.fences.get(scope)
        return f.term if f is not None else 0

    def _fence(self, scope: str) -> Fence | None:
        f = self.fences.get(scope)
        if f is None and len(self.fences) < MAX_SCOPES:
            f = self.fences[scope] = Fence()
        return f

    def believe(self, term: int, source: str, scopes: tuple[str, ...] = (WORLD_SCOPE,)) -> bool:
        """Whether authority state stamped ``term`` by ``source`` about ``scopes`` may be believed: not from a
        departed sim, and ``term`` at least the highest heard in every one of them (each raised to it)."""
        with self._lock:
            if term and source in self._departed:
                self.stale += 1
                return False
            fences = [(s, self._fence(s)) for s in scopes]
            if any(f is not None and term < f.term for _, f in fences):
                self.stale += 1
                return False
            for s, f in fences:
                if f is not None and f.check(term).accept and term:
                    self._holder[s] = source
        return True

    def raise_to(self, term: int, scopes: tuple[str, ...]) -> None:
        """Never believe less than ``term`` in ``scopes`` from now on (an authority taking over fences its own past)."""
        with self._lock:
            for s in scopes:
                f = self._fence(s)
                if f is not None:
                    f.raise_to(term)

    def sim_seen(self, peer_id: str) -> None:
        """A sim peer of the world is alive (its token appeared)."""
        with self._lock:
            self.sims.add(peer_id)
            self._departed.discard(peer_id)

    def sim_left(self, peer_id: str) -> bool:
        """A sim peer is gone: the scopes whose term it held reset; True when it was the last one and every
        fence was reset."""
        with self._lock:
            self.sims.discard(peer_id)
            if len(self._departed) < MAX_DEPARTED_SIMS:
                self._departed.add(peer_id)
            last = not self.sims
            held = list(self.fences) if last else [s for s, h in self._holder.items() if h == peer_id]
            for s in held:
                self._holder.pop(s, None)
                f = self.fences.get(s)
                if f is not None:
                    f.reset()
            if last:
                self.resets += 1
        return last

"""Who is live, and who subscribes to and serves what: liveliness tokens, and what each peer tells of itself.

A peer says it is alive with a token ``rf/W/peer/KIND/ID``. A token is declared by whoever holds a
login, so its key may be anything the router lets through (``peer/viewer/with space``): every
reader here takes tokens as they come, keeps those that name a peer, and returns the others as
``bad`` (their keys, to be shown quoted and skipped), never raising on them.

Subscribers and queryables are not visible to a client: each peer tells its own on its token's key
(:mod:`fabric.declared`). A world where nobody tells (a class world's student may not ask, peers older than this)
leaves ``available`` False: the caller says so instead of showing "no subscriber".
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field
from typing import Any

from fabric import keys, streams

__all__ = [
    "Peer",
    "Declarations",
    "live_tokens",
    "read_declarations",
    "SERVICE_TYPES",
    "service_types",
    "quoted",
    "STREAM_TYPES",
    "key_type",
]

# The request and reply types of each service (``-`` for a query without a payload).
SERVICE_TYPES: dict[str, tuple[str, str]] = {
    "world": ("-", "WorldInfo"),
    "state": ("-", "WorldState"),
    "ik": ("IKRequest", "IKReply"),
    "fk": ("FKRequest", "FKReply"),
    "jacobian": ("JacobianRequest", "JacobianReply"),
    "plan": ("PlanRequest", "PlanReply"),
    "map": ("MapRequest", "MapReply"),
    "own": ("OwnRequest", "OwnershipRecord"),
}


STREAM_TYPES: dict[str, str] = {s.name: s.message for s in streams.STREAMS}
"""The message type each robot stream ``rf/W/robot/ID/{stream}`` carries (:data:`fabric.streams.STREAMS`)."""


def key_type(key: str) -> str | None:
    """The message type ``key`` is declared to carry (a command key: its body's type), or None when any may.

    ``pub`` refuses another type before it sends: a Twist on a JointState key only made the sim and the
    compute log decode errors."""
    from fabric.interfaces import COMMAND_BODIES

    try:
        p = keys.parse(key)
    except ValueError:
        return None
    if p.category == "cmd":
        body = COMMAND_BODIES.get(p.leaf)
        return body.__name__ if body is not None else None
    if p.category == "robot":
        return STREAM_TYPES.get(p.leaf)
    if p.category == "object" and p.leaf == "pose":
        return "Pose"
    if p.category == "map":
        return "OccupancyGrid"
    return None


def quoted(text: str, limit: int = 120) -> str:
    """A key from the network as it may be shown: repr-quoted (no control characters reach the terminal), clipped."""
    r = ascii(text)
    return r if len(r) <= limit else r[: limit - 3] + "..."


def service_types(key: str) -> tuple[str, str]:
    """(request type, reply type) of the service on ``key`` (``rf/W/srv/NAME/...`` or ``rf/W/own/OBJ[/by/USER]``)."""
    parts = key.split("/")
    if len(parts) >= 4 and parts[2] == "srv":
        return SERVICE_TYPES.get(parts[3], ("?", "?"))
    if len(parts) >= 4 and parts[2] == "own":
        return ("-", "OwnershipRecord") if len(parts) == 4 else SERVICE_TYPES["own"]
    return ("?", "?")


@dataclass(frozen=True, slots=True)
class Peer:
    kind: str
    id: str


def _peer_of(token_key: str, world: str) -> Peer | None:
    """The peer a token names, or None when its key is not ``rf/W/peer/KIND/ID`` with valid parts."""
    try:
        p = keys.parse(token_key)
    except ValueError:
        return None
    if p.world != world or p.category != "peer" or not p.subject or not p.leaf:
        return None
    return Peer(p.subject, p.leaf)


def live_tokens(fab: Any, *, timeout: float = 1.0) -> tuple[list[Peer], list[str]]:
    """(peers, bad token keys) of ``fab``'s world from its liveliness tokens; malformed tokens go to ``bad``."""
    peers: set[Peer] = set()
    bad: set[str] = set()
    for k in fab.live_tokens(keys.peers_all(fab.world), timeout=timeout):
        p = _peer_of(k, fab.world)
        if p is None:
            bad.add(k)
        else:
            peers.add(p)
    return sorted(peers, key=lambda p: (p.kind, p.id)), sorted(bad)


@dataclass
class Declarations:
    """What the peers of a world told of themselves: per key expression, the ids of the peers declaring it."""

    available: bool = False
    """Whether any peer told (a class world's student may not ask; peers older than this answer nothing)."""
    subscribers: dict[str, list[str]] = field(default_factory=dict)
    queryables: dict[str, list[str]] = field(default_factory=dict)
    told: dict[str, Peer] = field(default_factory=dict)  # peer id -> the peer, for each peer that told
    bad_tokens: list[str] = field(default_factory=list)  # keys of answers that name no peer, or another one

    def of_peer(self, peer_id: str) -> tuple[list[str], list[str]] | None:
        """(subscribed key expressions, served key expressions) of one peer; None when it did not tell."""
        if peer_id not in self.told:
            return None
        subs = sorted(k for k, who in self.subscribers.items() if peer_id in who)
        served = sorted(k for k, who in self.queryables.items() if peer_id in who)
        return subs, served

    def matching(self, table: dict[str, list[str]], key: str) -> list[str]:
        """The peers whose declared expressions (in ``table``) intersect ``key`` (a key or an expression)."""
        import zenoh

        try:
            ke = zenoh.KeyExpr(key)
        except Exception:
            return []
        out: set[str] = set()
        for expr, who in table.items():
            try:
                if ke.intersects(zenoh.KeyExpr(expr)):
                    out.update(who)
            except Exception:
                continue
        return sorted(out)


def read_declarations(session: Any, world: str, *, timeout: float = 1.0) -> Declarations:
    """The subscribers and queryables of ``world``'s peers, as each peer tells them on its token's key
    (:mod:`fabric.declared`; not the router's admin space, which can stop the router for good).

    ``session`` is a raw zenoh session (a Fabric's ``session``, or shell completion's bare one); this session's own
    peer is not asked (its declarations are the reader's, not the world's)."""
    import zenoh

    from fabric.declared import decode_told

    subs: dict[str, set[str]] = defaultdict(set)
    served: dict[str, set[str]] = defaultdict(set)
    out = Declarations()
    bad: set[str] = set()
    try:
        replies = session.get(
            keys.peers_all(world),
            timeout=timeout,
            target=zenoh.QueryTarget.ALL,
            consolidation=zenoh.ConsolidationMode.NONE,
            allowed_destination=zenoh.Locality.REMOTE,
        )
        for rep in replies:
            if rep.ok is None:
                continue
            k = str(rep.ok.key_expr)
            p = _peer_of(k, world)
            told = decode_told(rep.ok.payload.to_bytes())
            if p is None or told is None or (told.kind, told.id) != (p.kind, p.id):
                bad.add(k)  # any login may answer on a key it may declare a token on: taken as it comes, never raised
                continue
            out.told[p.id] = p
            for e in told.subscribers:
                subs[e].add(p.id)
            for e in told.queryables:
                served[e].add(p.id)
    except Exception:  # a closing session
        pass
    out.available = bool(out.told)
    out.bad_tokens = sorted(bad)
    out.subscribers = {k: sorted(v) for k, v in sorted(subs.items())}
    out.queryables = {k: sorted(v) for k, v in sorted(served.items())}
    return out

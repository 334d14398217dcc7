"""Who is live, and who subscribes to and serves what: liveliness tokens and the router's admin space.

A peer says it is alive with a token ``rf/W/peer/KIND/ID``. A token is declared by whoever holds a
login, so its key may be anything the router lets through (``peer/viewer/with space``): every
reader here takes tokens as they come, keeps those that name a peer, and returns the others as
``bad`` (their keys, to be shown quoted and skipped), never raising on them.

Subscribers and queryables are not visible to a client; the router knows them. A router started by
robofabric answers read-only queries on its admin space (:mod:`fabric.config`):
``@/ROUTER/router/{subscriber,queryable,token}/KEY`` each with the zenoh ids of the clients that
declared it. A token ties a zenoh id to a peer id, so declarations are named by peer. A router
that does not answer (a stock zenohd, an ACL that hides ``@/**``) leaves ``available`` False: the
caller says so instead of showing "no subscriber".
"""

from __future__ import annotations

import json
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
    """What the routers of a world know: per key, the peers (``kind/id``, or a zenoh id) declaring it."""

    available: bool = False
    subscribers: dict[str, list[str]] = field(default_factory=dict)
    queryables: dict[str, list[str]] = field(default_factory=dict)
    peers: dict[str, Peer] = field(default_factory=dict)  # zenoh id -> the peer its token names
    bad_tokens: list[str] = field(default_factory=list)

    def name(self, zid: str) -> str:
        p = self.peers.get(zid)
        return p.id if p is not None else f"zid:{zid[:8]}"

    def of_peer(self, peer_id: str) -> tuple[list[str], list[str]]:
        """(subscribed key expressions, served key expressions) of one peer."""
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
    """The subscribers, queryables and tokens on ``world``'s keys, from every reachable router's admin space.

    ``session`` is a raw zenoh session (a Fabric's ``session``, or shell completion's bare one): the admin space
    (``@/...``) and the zenoh ids it answers with are zenoh's own, below anything the Fabric encodes."""
    root = keys.world_root(world)
    try:
        own = str(session.info.zid())  # this reader's own declarations are not the world's
    except Exception:
        own = ""
    raw: dict[str, dict[str, set[str]]] = {"subscriber": defaultdict(set), "queryable": defaultdict(set)}
    tokens: list[tuple[str, set[str]]] = []
    answered = False
    for what in ("subscriber", "queryable", "token"):
        try:
            import zenoh

            replies = session.get(
                f"@/*/router/{what}/{root}/**",
                timeout=timeout,
                target=zenoh.QueryTarget.ALL,
                consolidation=zenoh.ConsolidationMode.NONE,
            )
            for rep in replies:
                if rep.ok is None:
                    continue
                answered = True
                k = str(rep.ok.key_expr)
                marker = f"/router/{what}/"
                if marker not in k:
                    continue
                expr = k.split(marker, 1)[1]
                zids = _zids(rep.ok.payload.to_bytes()) - {own}
                if what == "token":
                    tokens.append((expr, zids))
                else:
                    raw[what][expr] |= zids
        except Exception:
            continue
    out = Declarations(available=answered)
    bad: set[str] = set()
    for expr, zids in tokens:
        if not expr.startswith(f"{root}/peer/"):
            continue
        p = _peer_of(expr, world)
        if p is None:
            bad.add(expr)
            continue
        for z in zids:
            out.peers[z] = p
    out.bad_tokens = sorted(bad)
    out.subscribers = {k: sorted({out.name(z) for z in v}) for k, v in sorted(raw["subscriber"].items()) if v}
    out.queryables = {k: sorted({out.name(z) for z in v}) for k, v in sorted(raw["queryable"].items()) if v}
    return out


def _zids(payload: bytes) -> set[str]:
    """The client and peer zenoh ids of an admin-space declaration entry (routers relay, they do not declare)."""
    try:
        doc = json.loads(payload)
    except ValueError:
        return set()
    if not isinstance(doc, dict):
        return set()
    out: set[str] = set()
    for field_name in ("clients", "peers"):
        v = doc.get(field_name)
        if isinstance(v, list):
            out.update(str(z) for z in v if isinstance(z, str))
    return out

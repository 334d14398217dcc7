"""Key expressions of a robofabric world.

Every key in the fabric is built here and nowhere else, so that the layout in
docs/design.md has one source of truth and a malformed id is refused before it ever
reaches the wire. Parsing is the inverse: tools such as ``echo`` and the
recorder use :func:`parse` to learn what a key holds.
"""

from __future__ import annotations

from dataclasses import dataclass

from fabric import streams

PREFIX = "rf"

ROBOT_STREAMS = streams.NAMES
"""Every robot stream's name (``robot/{id}/{name}``), from the one table, :data:`fabric.streams.STREAMS`."""
LATCHED_STREAMS = frozenset(s.name for s in streams.STREAMS if s.latched)
"""The robot streams whose latest a late joiner gets at once (:func:`is_latched`): a planned path."""
COMMANDS = ("joints", "trajectory", "twist", "path", "stop", "reset")
SERVICES = ("ik", "fk", "jacobian", "plan", "map", "world", "state", "move")
PEER_KINDS = ("sim", "compute", "user", "viewer", "recorder", "router", "tool")

_FORBIDDEN = set("/*$#? \t\n\r")

#: The chunk before the writer's user id in every key a user writes (commands, ownership requests,
#: scene-object poses): ``.../cmd/joints/by/alice``. Not ``@alice``: zenoh treats a chunk starting
#: with ``@`` as verbatim, which no wildcard matches, so ``rf/demo/**`` (record, echo) would miss it.
BY = "by"


def validate_id(value: str, *, what: str = "id") -> str:
    """Return ``value`` if it can be one chunk of a key, else raise ``ValueError`` naming it."""
    if not isinstance(value, str):
        raise ValueError(f"{what} must be a string, got {type(value).__name__}: {value!r}")
    if not value:
        raise ValueError(f"{what} must not be empty")
    bad = sorted(set(value) & _FORBIDDEN)
    if bad:
        raise ValueError(f"{what} {value!r} contains forbidden character(s) {''.join(bad)!r}")
    if value in (".", ".."):
        raise ValueError(f"{what} {value!r} is not allowed")
    return value


def _choice(value: str, allowed: tuple[str, ...], what: str) -> str:
    if value not in allowed:
        raise ValueError(f"unknown {what} {value!r}; expected one of {', '.join(allowed)}")
    return value


def world_root(world: str) -> str:
    return f"{PREFIX}/{validate_id(world, what='world')}"


def in_world(expr: str, world: str) -> str:
    """A key expression a person typed, full (``rf/demo/robot/**``) or world-relative (``robot/*/pose``,
    ``/robot/*/pose``), as the full key expression; ``ValueError`` naming ``expr`` when zenoh refuses it."""
    import zenoh  # here, not at the top: the key layout itself needs no session library

    full = expr if expr.startswith(PREFIX + "/") else f"{world_root(world)}/{expr.lstrip('/')}"
    try:
        zenoh.KeyExpr(full)
    except Exception as exc:  # zenoh raises its own ZError, not a ValueError
        raise ValueError(f"{expr!r} is not a valid key expression: {exc}") from None
    return full


def world_all(world: str) -> str:
    """Every key of one world: what ``record`` takes by default."""
    return f"{world_root(world)}/**"


def robot_stream(world: str, robot: str, stream: str) -> str:
    return f"{world_root(world)}/robot/{validate_id(robot, what='robot id')}/{_choice(stream, ROBOT_STREAMS, 'stream')}"


def robot_joints(world: str, robot: str) -> str:
    return robot_stream(world, robot, "joints")


def robot_pose(world: str, robot: str) -> str:
    return robot_stream(world, robot, "pose")


def robot_scan(world: str, robot: str) -> str:
    return robot_stream(world, robot, "scan")


def robot_path(world: str, robot: str) -> str:
    return robot_stream(world, robot, "path")


def robot_stream_all(world: str, stream: str) -> str:
    """One stream of every robot: ``rf/{world}/robot/*/{stream}``."""
    return f"{world_root(world)}/robot/*/{_choice(stream, ROBOT_STREAMS, 'stream')}"


def _by(user: str) -> str:
    return f"{BY}/{validate_id(user, what='user id')}"


def robot_cmd(world: str, robot: str, command: str, user: str) -> str:
    """Where ``user`` commands ``robot``: ``rf/{world}/robot/{id}/cmd/{command}/by/{user}``.

    The user is part of the key so a router's access control can allow each identity its own
    keys only; the sim peer takes the sender from the key, not from the payload."""
    return f"{world_root(world)}/robot/{validate_id(robot, what='robot id')}/cmd/{_choice(command, COMMANDS, 'command')}/{_by(user)}"


def robot_cmd_all(world: str, robot: str = "*") -> str:
    """Every command to ``robot`` (default: every robot) from every user."""
    r = robot if robot == "*" else validate_id(robot, what="robot id")
    return f"{world_root(world)}/robot/{r}/cmd/*/{BY}/*"


def robot_all(world: str, robot: str = "*") -> str:
    r = robot if robot == "*" else validate_id(robot, what="robot id")
    return f"{world_root(world)}/robot/{r}/**"


def object_pose(world: str, obj: str, user: str) -> str:
    """Where ``user`` moves scene object ``obj``: ``rf/{world}/object/{id}/pose/by/{user}``."""
    return f"{world_root(world)}/object/{validate_id(obj, what='object id')}/pose/{_by(user)}"


def object_pose_all(world: str, obj: str = "*") -> str:
    """Poses of ``obj`` (default: every object) from every writer: what readers subscribe to."""
    o = obj if obj == "*" else validate_id(obj, what="object id")
    return f"{world_root(world)}/object/{o}/pose/{BY}/*"


def map_key(world: str, name: str) -> str:
    return f"{world_root(world)}/map/{validate_id(name, what='map name')}"


#: Between a user and her map's name in the maps she builds: ``alice.map``. A class's logins are letters,
#: digits, ``-`` and ``_`` (robofabric.secure), so the user before the first ``.`` is never in doubt.
USER_MAP_SEP = "."


def user_map(name: str, user: str) -> str:
    """The map ``user`` gets when she builds ``name`` in her own name: ``{user}.{name}`` (kept as it is when it
    already starts with ``{user}.``). A build asked on ``srv/map/.../by/{user}`` never writes the class's map."""
    prefix = f"{validate_id(user, what='user id')}{USER_MAP_SEP}"
    name = validate_id(name, what="map name")
    return name if name.startswith(prefix) and len(name) > len(prefix) else prefix + name


def own(world: str, obj: str) -> str:
    return f"{world_root(world)}/own/{validate_id(obj, what='object id')}"


def own_all(world: str) -> str:
    return f"{world_root(world)}/own/*"


def own_request(world: str, obj: str, user: str) -> str:
    """Where ``user`` asks the authority for ``obj`` (request, release, renew): ``own/{obj}/by/{user}``.

    ``own/{obj}`` itself only carries the record (written and served by the authority)."""
    return f"{world_root(world)}/own/{validate_id(obj, what='object id')}/{_by(user)}"


def own_request_all(world: str, obj: str = "*") -> str:
    """Every user's requests for ``obj`` (default: every object): what the authority serves."""
    o = obj if obj == "*" else validate_id(obj, what="object id")
    return f"{world_root(world)}/own/{o}/{BY}/*"


STAFF = "staff"


def own_staff(world: str, obj: str, login: str) -> str:
    """Where instructor ``login`` asks the authority for a staff action on ``obj`` (``fabric.interfaces.STAFF_OPS``):
    ``own/{obj}/staff/by/{login}``. A class's router lets the instructor logins alone ask there (robofabric.secure)."""
    return f"{world_root(world)}/own/{validate_id(obj, what='object id')}/{STAFF}/{_by(login)}"


def own_staff_all(world: str, obj: str = "*") -> str:
    """Every login's staff actions on ``obj`` (default: every object): what the authority serves."""
    o = obj if obj == "*" else validate_id(obj, what="object id")
    return f"{world_root(world)}/own/{o}/{STAFF}/{BY}/*"


def srv(world: str, service: str, *rest: str) -> str:
    """A service key: ``srv(w, "ik", "arm1")`` -> ``rf/w/srv/ik/arm1``."""
    base = f"{world_root(world)}/srv/{_choice(service, SERVICES, 'service')}"
    parts = [validate_id(p, what="service argument") for p in rest]
    return "/".join([base, *parts])


def srv_per_subject(world: str, service: str, peer_id: str | None = None) -> str:
    """``srv/{service}/*`` (any peer's) or ``srv/{service}/*/{peer_id}`` (one peer's, to pick or spread)."""
    base = f"{world_root(world)}/srv/{_choice(service, SERVICES, 'service')}/*"
    return base if peer_id is None else f"{base}/{validate_id(peer_id, what='peer id')}"


def srv_asked(world: str, service: str, subject: str, user: str, peer_id: str | None = None) -> str:
    """``user`` asking a shared service: ``srv/{service}/{subject}[/{peer_id}]/by/{user}``.

    Like commands, the asker is in the key: a router lets each login ask on its own ``by/{user}`` only,
    and the service takes the asker from the key (docs/architecture.md, "Identity in the key"). The
    forms without ``by/{user}`` are the staff's (sim, compute and instructor logins; anyone in a world
    without access control)."""
    parts = [subject] if peer_id is None else [subject, peer_id]
    return f"{srv(world, service, *parts)}/{_by(user)}"


def srv_asked_all(world: str, service: str, peer_id: str | None = None) -> str:
    """What a service serves to askers who name themselves: ``srv/{service}/*[/{peer_id}]/by/*``."""
    return f"{srv_per_subject(world, service, peer_id)}/{BY}/*"


def srv_move(world: str, sim: str, login: str) -> str:
    """``login`` asking sim ``sim`` for one step of a move: ``srv/move/{sim}/by/{login}``. Only the staff's
    logins (instructor, sim) may ask there (robofabric.secure); ``srv/state``, which every login may ask, carries
    no move (docs/sim.md, "Moving a robot between sims")."""
    return srv_asked(world, "move", sim, login)


def srv_move_served(world: str, sim: str) -> str:
    """What sim ``sim`` serves of the move service: ``srv/move/{sim}/by/*`` (any asker the router let through)."""
    return f"{srv(world, 'move', sim)}/{BY}/*"


def asker(parsed: "ParsedKey") -> str:
    """The user a parsed service key names as its asker (``.../by/{user}``), '' for the staff's forms."""
    rest = parsed.rest
    return rest[-1] if parsed.category == "srv" and len(rest) >= 3 and rest[-2] == BY else ""


def peer(world: str, kind: str, peer_id: str) -> str:
    return f"{world_root(world)}/peer/{_choice(kind, PEER_KINDS, 'peer kind')}/{validate_id(peer_id, what='peer id')}"


def peers_all(world: str, kind: str = "*") -> str:
    k = kind if kind == "*" else _choice(kind, PEER_KINDS, "peer kind")
    return f"{world_root(world)}/peer/{k}/*"


SIM_ROLES = ("primary", "standby")
"""What a sim publishes it is (:func:`sim_role`): its shard's authority, or a standby following one."""


def sim_role(world: str, sim: str, role: str, term: int, leader: str) -> str:
    """The liveliness token a sim holds while it is ``role`` under ``term``, ``leader`` leading its shard (itself when
    primary): ``peer/sim/{sim}/{role}/{term}/{leader}`` beside its own ``peer/sim/{sim}``. Tests, the soak and tools
    learn a sim's role from it, never from its log; nothing decides on it (the election reads the sims' own tokens
    and the terms it hears)."""
    if isinstance(term, bool) or not isinstance(term, int) or term < 0:
        raise ValueError(f"a sim's term is a non-negative integer, not {term!r}")
    return (
        f"{peer(world, 'sim', sim)}/{_choice(role, SIM_ROLES, 'sim role')}/{term}/"
        f"{validate_id(leader, what='leader id')}"
    )


def sim_roles_all(world: str, sim: str = "*") -> str:
    """Every sim's role token (:func:`sim_role`), or ``sim``'s."""
    s = sim if sim == "*" else validate_id(sim, what="peer id")
    return f"{world_root(world)}/peer/sim/{s}/*/*/*"


def event(world: str, *parts: str) -> str:
    if not parts:
        raise ValueError("an event key needs at least one part, e.g. event(world, 'reject', robot)")
    return "/".join([f"{world_root(world)}/event", *(validate_id(p, what="event part") for p in parts)])


def event_all(world: str) -> str:
    return f"{world_root(world)}/event/**"


DECODE = "decode"
"""The event kind chunk of decode reports, which every login writes (on its own ``by/{writer}`` key)."""


def event_decode(world: str, writer: str) -> str:
    """Where ``writer`` (its login, else its peer id) reports payloads it could not decode:
    ``event/decode/by/{writer}``. Any login may write one, so what arrives there is display-only."""
    return f"{world_root(world)}/event/{DECODE}/{_by(writer)}"


@dataclass(frozen=True, slots=True)
class ParsedKey:
    """What a concrete key names. ``category`` is robot, cmd, object, map, own, srv, peer, sim_role or event."""

    world: str
    category: str
    subject: str = ""  # robot id, object id, map name, service name, peer kind
    leaf: str = ""  # stream name, command, peer id, event tail
    rest: tuple[str, ...] = ()
    user: str = ""  # the writer named by a user key (cmd, own request, object pose): ``.../by/{user}``


def is_latched(key: str) -> bool:
    """Keys whose latest value a late joiner needs at once: scene objects, maps and planned paths.

    A goal set before the compute peer started, a map built before the viewer joined: their
    publishers keep the last sample in a cache and subscribers that ask for history get it on
    joining (the role Firebase's latest value played in the paper). Streams that refresh at a
    fixed rate and commands (never to be replayed to a robot) are not latched.
    """
    try:
        p = parse(key)
    except ValueError:
        return False
    return p.category in ("object", "map") or (p.category == "robot" and p.leaf in LATCHED_STREAMS)


KEPT_EVENTS = 32
"""How many of its last samples an ownership record's or an ownership or reject event's publisher keeps
(:func:`cache_size`)."""
KEPT_EVENT_KINDS = frozenset({"own", "reject"})


def cache_size(key: str) -> int:
    """How many of its last samples the publisher of ``key`` keeps for subscribers that ask for history: 1 on a
    latched key (:func:`is_latched`), :data:`KEPT_EVENTS` on an ownership record's key (``own/{object}``) and on an
    ownership or reject event key (``event/own/{object}``, ``event/reject/{robot}``: a subscriber whose link was down, through a router's
    restart, gets the ones it missed when the publisher's token is back, :mod:`fabric.history`), 0 elsewhere."""
    if is_latched(key):
        return 1
    try:
        p = parse(key)
    except ValueError:
        return 0
    if p.category == "own":  # the records themselves: each change bumps the epoch, so a gap shows a miss
        return KEPT_EVENTS
    return KEPT_EVENTS if p.category == "event" and p.subject in KEPT_EVENT_KINDS and p.leaf else 0


def parse(key: str) -> ParsedKey:
    """Parse a concrete key; raise ``ValueError`` saying what is wrong with it."""
    parts = str(key).split("/")
    if len(parts) < 3 or parts[0] != PREFIX:
        raise ValueError(f"key {key!r} is not a robofabric key (expected '{PREFIX}/WORLD/...')")
    world, kind, tail = parts[1], parts[2], parts[3:]
    validate_id(world, what="world")
    for p in tail:
        validate_id(p, what=f"part of key {key!r}")
    if kind == "robot" and len(tail) == 2 and tail[1] in ROBOT_STREAMS:
        return ParsedKey(world, "robot", tail[0], tail[1])
    if kind == "robot" and len(tail) == 5 and tail[1] == "cmd" and tail[2] in COMMANDS and tail[3] == BY:
        return ParsedKey(world, "cmd", tail[0], tail[2], user=tail[4])
    if kind == "object" and len(tail) == 4 and tail[1] == "pose" and tail[2] == BY:
        return ParsedKey(world, "object", tail[0], "pose", user=tail[3])
    if kind == "map" and len(tail) == 1:
        return ParsedKey(world, "map", tail[0])
    if kind == "own" and len(tail) == 1:
        return ParsedKey(world, "own", tail[0])
    if kind == "own" and len(tail) == 3 and tail[1] == BY:
        return ParsedKey(world, "own_request", tail[0], user=tail[2])
    if kind == "own" and len(tail) == 4 and tail[1] == STAFF and tail[2] == BY:
        return ParsedKey(world, "own_staff", tail[0], user=tail[3])
    if kind == "srv" and len(tail) >= 1 and tail[0] in SERVICES:
        return ParsedKey(world, "srv", tail[0], "/".join(tail[1:]), tuple(tail[1:]))
    if kind == "peer" and len(tail) == 2 and tail[0] in PEER_KINDS:
        return ParsedKey(world, "peer", tail[0], tail[1])
    if kind == "peer" and len(tail) == 5 and tail[0] == "sim" and tail[2] in SIM_ROLES and tail[3].isdigit():
        return ParsedKey(world, "sim_role", tail[1], tail[2], (tail[3], tail[4]))  # sim, role, (term, leader)
    if kind == "event" and len(tail) >= 1:
        return ParsedKey(world, "event", tail[0], "/".join(tail[1:]), tuple(tail))
    raise ValueError(f"key {key!r} does not match any robofabric key layout")

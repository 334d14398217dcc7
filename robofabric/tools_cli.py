"""The fabric's own commands: router, ps, echo, hz, pub, call (introspection in the spirit of ``ros2 node/topic/service``)."""

from __future__ import annotations

import json
import sys
import threading
import time
from collections import defaultdict
from dataclasses import replace
from typing import Annotated, Optional, TYPE_CHECKING

import typer
import zenoh

from fabric import keys
from fabric.cli_common import (
    Connect, Listen, NothingThere, PeerId, Profile, UserError, World, ZenohConfig, make_config, open_fabric, print_folded, print_table, say,
    watch_reader,
)
from robofabric.complete import complete_keys, complete_peers, complete_types

if TYPE_CHECKING:  # imported where used: `robofabric --help` must not load numpy
    from fabric.session import Fabric


def _open(kind: str, world, connect, listen, profile, zenoh_config, peer_id=None, *, key: str | None = None) -> Fabric:
    """Join the world; a key given is checked first, so a typo fails before any network wait."""
    cfg = make_config(world, connect, listen, profile, zenoh_config)
    if key is not None:
        resolve_key(key, cfg.world)
    return open_fabric(cfg, kind, peer_id)


def resolve_key(key: str, world: str) -> str:
    """Accept full keys (``rf/demo/robot/arm1/joints``) or world-relative ones (``robot/arm1/joints``)."""
    try:
        return keys.in_world(key, world)
    except ValueError as exc:
        raise UserError(str(exc)) from None


def _user_key(full: str, user: str | None) -> str:
    """``robot/arm1/cmd/joints`` with ``--user alice`` is alice's command key ``.../cmd/joints/by/alice``
    (the sim takes the sender from the key); a key that already names its writer is kept."""
    parts = full.split("/")
    if user and len(parts) == 6 and parts[2] == "robot" and parts[4] == "cmd":
        try:
            return keys.robot_cmd(parts[1], parts[3], parts[5], user)
        except ValueError as exc:
            raise UserError(str(exc)) from None
    if user and len(parts) == 5 and parts[2] == "object" and parts[4] == "pose":
        return keys.object_pose(parts[1], parts[3], user)
    return full


def router(
    listen: Listen = None,
    connect: Connect = None,
    world: World = None,
    zenoh_config: ZenohConfig = None,
    peer_id: PeerId = None,
    audit: Annotated[bool, typer.Option("--audit", help="Count what access control refuses (by login, message and key) and print a summary per interval; costs CPU with traffic.")] = False,
    audit_every: Annotated[float, typer.Option(help="Seconds between --audit summaries.")] = 10.0,
) -> None:
    """Run a zenoh router for the fabric (any standard zenohd works in its place)."""
    from fabric.session import Fabric, shutdown_event
    cfg = make_config(world, connect, listen, "embedded", zenoh_config)
    if not listen and not cfg.file_value("listen/endpoints"):
        cfg = replace(cfg, listen=("tcp/0.0.0.0:7447",))
    if audit and audit_every <= 0:
        raise UserError("--audit-every must be positive")
    stop = shutdown_event()
    auditor = None
    if audit:
        from robofabric.router_audit import Audit

        auditor = Audit(every=audit_every)
    try:
        fab = Fabric(cfg, kind="router", peer_id=peer_id)
    except Exception as exc:
        raise UserError(f"cannot start router on {', '.join(cfg.endpoints()[1])}: {exc}") from None
    with fab:
        print(f"router {fab.peer_id} listening on {', '.join(cfg.endpoints()[1])} (world {cfg.world}); Ctrl-C to stop", flush=True)
        while not stop.wait(0.5):
            pass
    if auditor is not None:
        auditor.close()
    print("router stopped", flush=True)


def ps(
    peer: Annotated[Optional[str], typer.Argument(help="With -v: only this peer (its id).", autocompletion=complete_peers)] = None,
    verbose: Annotated[bool, typer.Option("--verbose", "-v", help="What each peer publishes, subscribes to and serves (like ros2 node info).")] = False,
    as_json: Annotated[bool, typer.Option("--json", help=(
        'One JSON document instead of a table: {"world", "peers": {KIND: [ID]}, "count", "bad_tokens"}; '
        'with -v also "declarations_visible" and "info": {ID: {publishes, subscribes, serves}}.'))] = False,
    timeout: Annotated[float, typer.Option(help="Seconds to wait for liveliness replies.")] = 1.0,
    duration: Annotated[float, typer.Option(help="With -v: seconds to watch the world's traffic for what each peer publishes.")] = 1.5,
    world: World = None,
    connect: Connect = None,
    listen: Listen = None,
    profile: Profile = None,
    zenoh_config: ZenohConfig = None,
    peer_id: PeerId = None,
) -> None:
    """List the live peers of a world, by kind, from their liveliness tokens; -v: what each publishes, subscribes, serves.

    A token whose key names no peer (any login may declare one) is shown quoted on stderr and skipped."""
    from robofabric.declarations import live_tokens, quoted, read_declarations

    if peer is not None and not verbose:
        verbose = True
    decl = None
    published: dict[str, list[str]] = {}
    with _open("tool", world, connect, listen, profile, zenoh_config, peer_id) as fab:
        found, bad = live_tokens(fab, timeout=timeout)
        peers = [(p.kind, p.id) for p in found if p.id != fab.peer_id]
        if verbose:
            from robofabric.introspect_cli import observe

            decl = read_declarations(fab.session, fab.world, timeout=timeout)  # zenoh's admin space: the raw session
            for s in observe(fab, keys.world_all(fab.world), duration):
                for src in s.publishers:
                    published.setdefault(src, []).append(s.key)
    print_folded(*(f"skipped a token that names no peer: {quoted(k)}" for k in bad), stderr=True)
    if peer is not None:
        peers = [(k, i) for k, i in peers if i == peer]
        if not peers:
            raise NothingThere(f"no live peer {peer!r} in world {fab.world!r}")

    def detail(pid: str) -> dict:
        subs, served = decl.of_peer(pid) if decl is not None else ([], [])
        return {"publishes": sorted(published.get(pid, [])), "subscribes": subs, "serves": served}

    if as_json:
        by_kind: dict[str, list[str]] = defaultdict(list)
        for k, i in peers:
            by_kind[k].append(i)
        doc: dict = {"world": fab.world, "peers": dict(by_kind), "count": len(peers), "bad_tokens": bad}
        if verbose:
            doc["declarations_visible"] = bool(decl and decl.available)
            doc["info"] = {i: detail(i) for _k, i in peers}
        print(json.dumps(doc))
        if not peers:
            raise NothingThere(f"no live peer in world {fab.world!r}")
        return
    if verbose:
        from robofabric.declarations import service_types

        if decl is not None and not decl.available:
            print("(the router does not show its admin space: subscriptions and services unknown)", file=sys.stderr)
        lines = []
        for k, i in peers:
            d = detail(i)
            lines.append(f"{i} ({k})")
            lines.append("  publishes:" + ("" if d["publishes"] else " -"))
            lines.extend(f"    {key}" for key in d["publishes"])
            lines.append("  subscribes:" + ("" if d["subscribes"] else " -"))
            lines.extend(f"    {key}" for key in d["subscribes"])
            lines.append("  serves:" + ("" if d["serves"] else " -"))
            for key in d["serves"]:
                req, rep = service_types(key)
                lines.append(f"    {key}  ({req} -> {rep})")
        print_folded(*lines)  # a key longer than the terminal folds, never runs past its edge
        return
    print_table(f"world {fab.world}: {len(peers)} peer(s)", ("kind", "id"), peers)
    if not peers:
        raise NothingThere(f"no live peer in world {fab.world!r}")


def echo(
    key: Annotated[str, typer.Argument(help="Key expression, full (rf/demo/robot/arm1/joints) or world-relative (robot/*/pose).", autocompletion=complete_keys)],
    count: Annotated[Optional[int], typer.Option("--count", "-n", help="Exit after N messages.")] = None,
    duration: Annotated[Optional[float], typer.Option(help="Exit after S seconds (exit 1 if nothing came).")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="One JSON object per line: {key, message}.")] = False,
    timeout: Annotated[Optional[float], typer.Option(help="Exit 1 with 'nothing on KEY in S s' when no message came within S seconds.")] = None,
    latest: Annotated[
        bool, typer.Option("--latest/--no-latest", help="First the latest value of latched keys (maps, paths, scene objects) set before echo started.")
    ] = True,
    world: World = None,
    connect: Connect = None,
    listen: Listen = None,
    profile: Profile = None,
    zenoh_config: ZenohConfig = None,
    peer_id: PeerId = None,
) -> None:
    """Print decoded messages on a key; malformed payloads are reported on stderr and skipped."""
    from fabric.codec import DecodeError, decode, to_plain
    from fabric.session import shutdown_event
    if count is not None and count <= 0:
        raise UserError("--count must be positive")
    if timeout is not None and not timeout > 0:
        raise UserError("--timeout must be positive")
    stop = shutdown_event()
    watch_reader(stop)  # `echo KEY | head -3` ends with head, even on a key gone quiet
    printed = 0
    bad = 0
    lock = threading.Lock()
    with _open("tool", world, connect, listen, profile, zenoh_config, peer_id, key=key) as fab:
        full = resolve_key(key, fab.world)

        def on_sample(sample: zenoh.Sample) -> None:
            nonlocal printed, bad
            k = str(sample.key_expr)
            try:
                msg = decode(sample.payload.to_bytes())
            except DecodeError as exc:
                with lock:
                    bad += 1
                print(f"{k}: bad payload: {exc}", file=sys.stderr, flush=True)
                return
            with lock:
                if count is not None and printed >= count:
                    return
                printed += 1
                if as_json:
                    line = json.dumps({"key": k, "message": to_plain(msg)})
                else:
                    line = f"--- {k}\n{msg}"
                say(line, stop=stop)  # a closed pipe (`| head -3`) ends echo with 0
                if count is not None and printed >= count:
                    stop.set()

        fab.subscribe_raw(full, on_sample, history=latest)
        early = timeout is not None and (duration is None or timeout < duration)
        stop.wait(timeout if early else duration)
        with lock:
            silent = printed == 0 and bad == 0
        if early and not silent and not stop.is_set():
            stop.wait(None if duration is None else duration - timeout)
        # set by Ctrl-C / SIGTERM (asked to stop: 0 even with nothing), --count or a closed pipe
        stopped = stop.is_set()
    if bad:
        print(f"{bad} malformed payload(s) skipped", file=sys.stderr)
    if silent and not stopped:  # --timeout or --duration ran out with nothing: the world had nothing there
        raise NothingThere(f"nothing on {full} in {timeout if early else duration:g} s")


def hz(
    key: Annotated[str, typer.Argument(help="Key expression; each matching key is measured separately.", autocompletion=complete_keys)],
    duration: Annotated[Optional[float], typer.Option(help="Measure for S seconds, then print the summary and exit.")] = None,
    window: Annotated[int, typer.Option(help="Intervals kept per key for the running statistics.")] = 10_000,
    as_json: Annotated[bool, typer.Option("--json", help='Print only the final summary, as one JSON document: {"key", "streams": {KEY: {count, rate_hz, jitter_ms, min_ms, max_ms, bytes, bytes_per_s}}}.')] = False,
    world: World = None,
    connect: Connect = None,
    listen: Listen = None,
    profile: Profile = None,
    zenoh_config: ZenohConfig = None,
    peer_id: PeerId = None,
) -> None:
    """Rate, jitter and bandwidth of the keys matching KEY (like ``ros2 topic hz`` and ``bw``)."""
    from fabric.session import shutdown_event
    from robofabric.stats import StreamStats
    stop = shutdown_event()
    stats: dict[str, StreamStats] = {}
    lock = threading.Lock()
    with _open("tool", world, connect, listen, profile, zenoh_config, peer_id, key=key) as fab:
        full = resolve_key(key, fab.world)

        def on_sample(sample: zenoh.Sample) -> None:
            now = time.monotonic()
            k = str(sample.key_expr)
            with lock:
                st = stats.get(k)
                if st is None:
                    st = stats[k] = StreamStats(window=window)
                st.add(now, len(sample.payload))

        fab.subscribe_raw(full, on_sample)
        start = time.monotonic()
        end = None if duration is None else start + duration
        while not stop.is_set():
            left = 1.0 if end is None else min(1.0, end - time.monotonic())
            if left <= 0 or stop.wait(left):
                break
            if not as_json:
                with lock:
                    snap = {k: s.summary() for k, s in stats.items()}
                print_folded(*(_hz_line(k, s) for k, s in sorted(snap.items())))  # as wide as the terminal
                if not snap and not say(f"no messages on {full} yet", stop=stop):
                    break
    with lock:
        final = {k: s.summary() for k, s in sorted(stats.items())}
    if as_json:
        say(json.dumps({"key": full, "streams": final}))
    elif final:
        say("summary:")
        print_folded(*(_hz_line(k, s) for k, s in final.items()))
    elif stop.is_set():
        print(f"no messages on {full}", file=sys.stderr)
    if not final and not stop.is_set():  # --duration ran out with nothing to measure (Ctrl-C: asked to stop, 0)
        raise NothingThere(f"no messages on {full} in {duration:g} s")


def pub(
    key: Annotated[str, typer.Argument(help="Concrete key, full or world-relative (robot/base1/cmd/twist: with --user, that user's key .../by/USER).", autocompletion=complete_keys)],
    msg_type: Annotated[str, typer.Option("--type", "-t", help="Message type, e.g. Twist, JointTarget, Pose, Stop.", autocompletion=complete_types)],
    data: Annotated[str, typer.Option("--data", "-d", help='Fields as JSON, e.g. \'{"v": 0.3, "omega": 0.1}\'.')] = "{}",
    user: Annotated[Optional[str], typer.Option(help="Wrap in a Command from this user (required for cmd/* keys unless the login names the user).")] = None,
    epoch: Annotated[Optional[int], typer.Option(help="Ownership epoch stamped on the Command (default: the user's current one, read from own/ROBOT).")] = None,
    rate: Annotated[float, typer.Option(help="Publish at this rate in Hz (0: once).")] = 0.0,
    count: Annotated[Optional[int], typer.Option("--count", "-n", help="Number of messages (default 1, or forever with --rate).")] = None,
    wait: Annotated[float, typer.Option(help="Seconds to wait for the sim's answer to a command (0: do not wait).")] = 1.0,
    world: World = None,
    connect: Connect = None,
    listen: Listen = None,
    profile: Profile = None,
    zenoh_config: ZenohConfig = None,
    peer_id: PeerId = None,
) -> None:
    """Publish a message built from JSON (like ``ros2 topic pub``); checked by the codec before it leaves.

    The key must match a robofabric key layout (refused before sending otherwise). A command (``robot/ID/cmd/NAME``)
    needs its user, from ``--user`` or the login; ``pub`` then listens for the sim's refusal for ``--wait`` s:
    exit 1 with the sim's reason when it refuses, or when no sim listens on the key; exit 0 when none came."""
    from fabric.session import shutdown_event
    from fabric.codec import encode
    from fabric.interfaces import Command
    from fabric.rate import RateLoop

    from robofabric.declarations import key_type

    body = _message_from_json(msg_type, data)
    cfg = make_config(world, connect, listen, profile, zenoh_config)
    try:
        user = cfg.user_id(user)  # a secure login is the user
    except ValueError as exc:
        raise UserError(str(exc)) from None
    if wait < 0:
        raise UserError("--wait must not be negative")
    n = count if count is not None else (None if rate > 0 else 1)
    # the key is checked before joining: a typo or a wrong type fails at once, and nothing is sent
    full = _user_key(resolve_key(key, cfg.world), user)
    if "*" in full or "$" in full:
        raise UserError(f"{full!r} is a pattern; pub needs a concrete key")
    parsed = _parse_pub_key(full, user)
    declared = key_type(full)
    if declared is not None and declared != msg_type:
        what = "commands" if parsed.category == "cmd" else "messages"
        raise UserError(f"{full} carries {declared} {what}, not {msg_type}; nothing sent")
    is_cmd = parsed.category == "cmd"
    if is_cmd and not user:
        user = parsed.user  # a key that names its writer (.../by/ann) is that user's command
    stop = shutdown_event()
    with open_fabric(cfg, "tool", peer_id) as fab:
        if is_cmd and wait > 0:
            _check_robot(fab, parsed.subject, timeout=max(wait, 1.0))
        if is_cmd and epoch is None:
            epoch = _current_epoch(fab, parsed.subject, parsed.user)
        try:
            msg = Command(user=user, epoch=epoch or 0, body=body) if user else body
            encode(msg)
        except (ValueError, TypeError) as exc:
            raise UserError(f"cannot build {msg_type} from {data!r}: {exc}") from None
        refusals: list[str] = []
        refused = threading.Event()
        if is_cmd and wait > 0:
            from fabric.interfaces import Event, EventKind

            def on_event(_key: str, ev: Event) -> None:
                # a refusal of this user's command, or of any command for a robot the sim does not have
                # (refused from the key alone: the sender is not known, and the event names no user)
                if ev.kind == EventKind.REJECT and (ev.user == parsed.user or (not ev.user and ev.object == parsed.subject)):
                    refusals.append(ev.reason)
                    refused.set()

            fab.subscribe(keys.event(fab.world, "reject", parsed.subject), on_event, expected=Event)
            fab.subscribe(keys.event(fab.world, "reject"), on_event, expected=Event)  # ids the sim has not
        heard = fab.wait_matching(full, 0.5)  # the publisher routes to existing subscribers before the first put
        sent = 0

        def tick(_now: float) -> None:
            nonlocal sent
            fab.publish(full, msg)
            sent += 1
            if n is not None and sent >= n:
                stop.set()

        if rate > 0:
            loop = RateLoop(rate, tick)
            loop.run(stop)
        else:
            for _ in range(n or 1):
                tick(0.0)
        if is_cmd and wait > 0 and heard:
            refused.wait(wait)  # the sim's refusal, if one comes
        # closing the session sends what is still queued before the link goes (zenoh drains its pipeline)
    if refusals:
        print(f"refused: {refusals[0]} ({sent} {msg_type} sent on {full})", file=sys.stderr)
        raise typer.Exit(1)
    if is_cmd and wait > 0 and not heard:
        print(f"no sim listens on {full}: {sent} {msg_type} sent, nobody took it", file=sys.stderr)
        raise typer.Exit(1)
    if is_cmd and wait > 0:
        print(f"published {sent} {msg_type} on {full}; applied (not refused within {wait:g} s)")
    else:
        print(f"published {sent} {msg_type} on {full}")


def _parse_pub_key(full: str, user: str | None):
    """The layout ``full`` matches; a key of none, or a command without its user, is refused before sending."""
    try:
        parsed = keys.parse(full)
    except ValueError as exc:
        parts = full.split("/")
        if len(parts) == 6 and parts[2] == "robot" and parts[4] == "cmd" and not user:
            raise UserError(f"{full!r} is a command key: a command needs its user (--user NAME, or a login that names it); "
                            "the sim takes the sender from the key .../by/USER") from None
        raise UserError(f"{exc}; nothing sent") from None
    if parsed.category == "cmd" and user and parsed.user != user:
        raise UserError(f"{full!r} is {parsed.user}'s command key, not {user}'s") from None
    return parsed


def _check_robot(fab: Fabric, robot: str, *, timeout: float) -> None:
    """Refuse (exit 1, nothing sent) a command for a robot the world's sims do not have, as they would.

    A sim refuses such a command with ``unknown_robot`` but at most a few times per interval, and in a
    sharded world every sim leaves it to the others: asking the world's description first is what
    makes the answer certain. No answer (no sim): the command goes, and ``pub`` says nobody took it."""
    from fabric.interfaces import ServiceError
    from fabric.worldview import describe

    try:
        info = describe(fab, timeout=timeout)
    except ServiceError:
        return
    ids = sorted(r.id for r in info.robots)
    if robot not in ids:
        raise NothingThere(f"refused: unknown_robot: no robot {robot!r} in world {fab.world!r} (robots: {', '.join(ids) or 'none'}); nothing sent")


def _current_epoch(fab: Fabric, robot: str, user: str) -> int:
    """The ownership epoch ``user`` holds ``robot`` under (0 when she does not own it or no authority answers)."""
    from fabric.interfaces import OwnershipRecord, ServiceError

    try:
        replies = fab.rpc.query(keys.own(fab.world, robot), timeout=0.5, expected=OwnershipRecord)
    except (ServiceError, ValueError):
        return 0
    for rep in replies:
        rec = rep.message
        if isinstance(rec, OwnershipRecord) and rec.owner == user:
            return int(rec.epoch)
    return 0


def _message_from_json(msg_type: str, data: str):
    """A message of any installed type (plugins included) from a JSON object of its fields.

    What is wrong is said in words, naming the field (``Twist needs field 'omega' (a number)``), never as
    Python's ``Twist.__init__() missing 1 required positional argument``; the message is checked as a
    receiver would decode it, so nothing the sim would refuse as undecodable leaves."""
    from fabric.codec import DecodeError, decode, encode, load_plugins, registered

    load_plugins()
    types = registered()
    cls = types.get(msg_type)
    if cls is None:
        raise UserError(f"unknown message type {msg_type!r}; known: {', '.join(sorted(types))}")
    try:
        fields = json.loads(data)
    except ValueError as exc:
        raise UserError(f"--data is not JSON: {exc}") from None
    if not isinstance(fields, dict):
        raise UserError(f"--data must be a JSON object of {msg_type}'s fields ({_fields_words(cls)}), got {data!r}")
    fields = _checked_fields(cls, fields)
    try:
        msg = cls(**fields)
        decode(encode(msg), cls)  # as the receiver will: finiteness, ranges, shapes
    except DecodeError as exc:
        raise UserError(f"bad {msg_type}: {exc}") from None
    except (ValueError, TypeError) as exc:
        raise UserError(f"cannot build {msg_type} from {data!r}: {exc}") from None
    return msg


def _spec_words(spec) -> str:
    """What a field's codec spec asks for, in words."""
    name = type(spec).__name__
    if name == "F":
        bounds = f" in [{spec.lo}, {spec.hi}]" if spec.lo is not None or spec.hi is not None else ""
        return f"a number{bounds}"
    if name == "I":
        return "an integer"
    if name in ("S", "User"):
        return "a string"
    if name == "Strs":
        return "a list of strings"
    if name == "Arr":
        return "a list of numbers" if getattr(spec, "ndim", None) in (None, 1) else f"a {spec.ndim}-D array of numbers"
    return "a value"


def _fields_words(cls) -> str:
    import dataclasses

    spec = getattr(cls, "SPEC", {})
    return ", ".join(f"{f.name}: {_spec_words(spec.get(f.name))}" for f in dataclasses.fields(cls) if f.name != "header")


def _checked_fields(cls, fields: dict) -> dict:
    """``fields`` for ``cls``, each checked against its spec; a missing, unknown or bad one is a :class:`UserError`
    naming it."""
    import dataclasses

    import numpy as np

    from fabric.codec import DecodeError

    name = cls.__name__
    known = {f.name: f for f in dataclasses.fields(cls)}
    spec = getattr(cls, "SPEC", {})
    for k in fields:
        if k not in known:
            raise UserError(f"{name} has no field {k!r}; its fields: {_fields_words(cls)}")
    for k, f in known.items():
        if k not in fields and f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise UserError(f"{name} needs field {k!r} ({_spec_words(spec.get(k))}); its fields: {_fields_words(cls)}")
    out = dict(fields)
    for k, v in fields.items():
        s = spec.get(k)
        kind = type(s).__name__
        if kind not in ("F", "I", "S", "Strs", "Arr"):
            continue  # nested messages and maps: the constructor and the codec say what is wrong
        try:
            if kind == "Arr":
                if not isinstance(v, list):
                    raise DecodeError(f"{name}.{k}: expected {_spec_words(s)}, got {json.dumps(v)}")
                try:
                    v = np.asarray(v, dtype=s.dtype)
                except (ValueError, TypeError):
                    raise DecodeError(f"{name}.{k}: expected {_spec_words(s)}, got {json.dumps(v)}") from None
            elif kind == "Strs" and isinstance(v, list):
                v = tuple(v)
            out[k] = s.check(v, f"{name}.{k}")
        except DecodeError as exc:
            raise UserError(str(exc)) from None
    return out


def call(
    key: Annotated[str, typer.Argument(help="Service key, full or world-relative: srv/world, srv/ik/arm1, srv/map/map/PEER.", autocompletion=complete_keys)],
    msg_type: Annotated[Optional[str], typer.Option("--type", "-t", help="Request type, e.g. IKRequest, FKRequest, MapRequest, PlanRequest (none: an empty query).", autocompletion=complete_types)] = None,
    data: Annotated[str, typer.Option("--data", "-d", help='Request fields as JSON, e.g. \'{"q": [0, 0, 0, 0, 0, 0]}\'.')] = "{}",
    all_replies: Annotated[bool, typer.Option("--all", help="Ask every peer serving the key, not only the nearest.")] = False,
    as_json: Annotated[bool, typer.Option("--json", help="One JSON object per reply: {key, source, message}.")] = False,
    timeout: Annotated[float, typer.Option(help="Seconds to wait for replies.")] = 5.0,
    world: World = None,
    connect: Connect = None,
    listen: Listen = None,
    profile: Profile = None,
    zenoh_config: ZenohConfig = None,
    peer_id: PeerId = None,
) -> None:
    """Call a service and print its replies (like ``ros2 service call``); a refusal prints its reason, exit 1."""
    from fabric.codec import to_plain
    from fabric.interfaces import ServiceError

    if timeout <= 0:
        raise UserError("--timeout must be positive")
    request = _message_from_json(msg_type, data) if msg_type else None
    with _open("tool", world, connect, listen, profile, zenoh_config, peer_id, key=key) as fab:
        full = resolve_key(key, fab.world)
        try:
            if full == keys.srv(fab.world, "world") and not all_replies and request is None:
                from fabric.rpc import Reply
                from fabric.worldview import describe

                info = describe(fab, timeout=timeout)  # one world: every sim's part (--all: each part)
                replies = [Reply(full, info, ",".join(sorted({r.sim for r in info.robots if r.sim})) or info.header.source)]
            else:
                replies = fab.rpc.query(full, request, timeout=timeout, all_replies=all_replies)
        except ServiceError as exc:
            print(f"{full}: {exc.reason}", file=sys.stderr, flush=True)
            raise typer.Exit(1) from None
        for rep in replies:
            if as_json:
                print(json.dumps({"key": rep.key, "source": rep.source, "message": to_plain(rep.message)}), flush=True)
            else:
                print(f"--- {rep.key} (from {rep.source or '?'})\n{rep.message}", flush=True)


def _hz_line(key: str, s: dict) -> str:
    return (
        f"{key}: {s['rate_hz']:.1f} Hz  jitter {s['jitter_ms']:.3f} ms  min {s['min_ms']:.3f} ms  "
        f"max {s['max_ms']:.3f} ms  {s['bytes_per_s'] / 1000:.1f} kB/s  n={s['count']}"
    )


def register(app: typer.Typer) -> None:
    app.command("router")(router)
    app.command("ps")(ps)
    app.command("echo")(echo)
    app.command("hz")(hz)
    app.command("pub")(pub)
    app.command("call")(call)

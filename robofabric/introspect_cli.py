"""``robofabric list``, ``robofabric info KEY`` and ``robofabric interfaces``: what is live, and what the types are.

In the spirit of ``ros2 topic list -v``, ``ros2 topic info`` and ``ros2 interface show``.
``info`` also reads recordings: ``robofabric info FILE.mcap`` (an argument ending in ``.mcap``
or naming an existing file) keeps its recording summary; anything else is a live key. The
dispatch lives in :mod:`robofabric.recording.cli`, which owns the ``info`` command.
"""

from __future__ import annotations

import json
import sys
import threading
import time
from typing import Annotated, Optional, TYPE_CHECKING

import typer
import zenoh

from fabric import keys
from fabric.cli_common import Joining, NothingThere, UserError, join_flags, print_table
from robofabric.terminal import plain_doc, print_folded
from robofabric.complete import complete_keys, complete_types

if TYPE_CHECKING:  # imported where used: `robofabric --help` must not load numpy
    from robofabric.introspect import KeyStats

__all__ = ["register", "list_keys", "key_info", "interfaces", "observe"]


def _resolve(expr: str, world: str) -> str:
    try:
        return keys.in_world(expr, world)
    except ValueError as exc:
        raise UserError(str(exc)) from None


def observe(fab, expr: str, duration: float) -> list[KeyStats]:
    """Watch ``expr`` for ``duration`` s (latched keys' latest values included) and summarise per key."""
    from robofabric.introspect import KeyObserver

    obs = KeyObserver()
    lock = threading.Lock()

    def on_sample(sample: zenoh.Sample) -> None:
        if sample.kind != zenoh.SampleKind.PUT:
            return
        t = time.monotonic()
        payload = sample.payload.to_bytes()
        with lock:
            obs.add(str(sample.key_expr), payload, t)

    fab.subscribe_raw(expr, on_sample, history=True)
    time.sleep(duration)
    with lock:
        return obs.snapshot()


@join_flags()
def list_keys(
    keyexpr: Annotated[
        Optional[str],
        typer.Argument(
            help="Key expression, full or world-relative (default: the whole world).", autocompletion=complete_keys
        ),
    ] = None,
    as_json: Annotated[
        bool,
        typer.Option(
            "--json",
            help=(
                'One JSON document instead of a table: {"world", "keyexpr", "duration_s", "declarations_visible", '
                '"keys": [{key, type, publishers, subscribers, messages, rate_hz, bytes_per_s, last_bytes, latched}]}; '
                'with --services: {"world", "keyexpr", "declarations_visible", "services": [{key, kind, request, reply, servers}]}.'
            ),
        ),
    ] = False,
    duration: Annotated[float, typer.Option(help="Seconds to watch (rates are measured over this window).")] = 2.0,
    services: Annotated[
        bool,
        typer.Option(
            "--services", help="Services (queryables) with their request and reply types and who serves them."
        ),
    ] = False,
    join: Joining = Joining(),
) -> None:
    """Live keys with their type, publishers, subscribers and rate (like ``ros2 topic list -v``); --services: services."""
    from robofabric.declarations import read_declarations, service_types

    if not duration > 0:
        raise UserError("--duration must be positive")
    cfg = join.config()
    expr = _resolve(keyexpr, cfg.world) if keyexpr else keys.world_all(cfg.world)
    with join.open("tool", cfg) as fab:
        decl = read_declarations(fab.session, cfg.world)  # what each peer tells (fabric.declared)
        stats = [] if services else observe(fab, expr, duration)
    if services:
        rows = [
            {"key": k, "kind": "service", "request": service_types(k)[0], "reply": service_types(k)[1], "servers": who}
            for k, who in decl.queryables.items()
            if _intersects(k, expr)
        ]
        if as_json:
            print(
                json.dumps(
                    {"world": cfg.world, "keyexpr": expr, "declarations_visible": decl.available, "services": rows}
                )
            )
            return
        print_table(
            f"{expr}: {len(rows)} service(s)",
            ("key", "request", "reply", "served by"),
            [(r["key"], r["request"], r["reply"], ", ".join(r["servers"])) for r in rows],
        )
        if not decl.available:
            print(
                "no peer told what it serves (this login may not ask, or the peers are older): services unknown",
                file=sys.stderr,
            )
        return
    subs = {s.key: decl.matching(decl.subscribers, s.key) for s in stats}
    if as_json:
        docs = [{**s.to_json(), "subscribers": subs[s.key]} for s in stats]
        print(
            json.dumps(
                {
                    "world": cfg.world,
                    "keyexpr": expr,
                    "duration_s": duration,
                    "declarations_visible": decl.available,
                    "keys": docs,
                }
            )
        )
        if not stats:
            raise NothingThere(f"nothing published on {expr} in {duration:g} s (world {cfg.world!r})")
        return
    rows = [
        (
            s.key + (" (latched)" if s.latched else ""),
            ", ".join(s.types),
            ", ".join(s.publishers) or "-",
            (", ".join(subs[s.key]) or "-") if decl.available else "?",
            f"{s.rate_hz:.1f}",
            str(s.messages),
            f"{s.bytes_per_s / 1000:.1f}",
        )
        for s in stats
    ]
    print_table(
        f"{expr}: {len(stats)} key(s) in {duration:g} s",
        ("key", "type", "publishers", "subscribers", "rate Hz", "msgs", "kB/s"),
        rows,
        numeric=NUMERIC,
    )
    if not stats:
        raise NothingThere(
            f"nothing published on {expr} in {duration:g} s (world {cfg.world!r}); services: robofabric list --services"
        )


def _intersects(a: str, b: str) -> bool:
    try:
        return zenoh.KeyExpr(a).intersects(zenoh.KeyExpr(b))
    except Exception:
        return False


NUMERIC = ("rate Hz", "msgs", "kB/s", "fields")
"""Columns shown right-aligned."""


def key_info(key: str, *, as_json: bool, duration: float, join: Joining) -> None:
    """``robofabric info KEY``: type and its fields, publishers, rate, whether anyone subscribes."""
    from robofabric.interface_fields import fields_of, message_types

    if not duration > 0:
        raise UserError("--duration must be positive")
    cfg = join.config()
    full = _resolve(key, cfg.world)
    from robofabric.declarations import read_declarations, service_types

    with join.open("tool", cfg) as fab:
        decl = read_declarations(fab.session, cfg.world)  # what each peer tells (fabric.declared)
        stats = observe(fab, full, duration)
        subscribed = None
        if "*" not in full and "$" not in full:
            try:
                # a plain publisher of its own, undeclared at once: the Fabric's publisher of a latched key (an
                # advanced publisher) has no matching status to ask
                pub = fab.session.declare_publisher(full)
                time.sleep(0.2)  # let the routing tables tell the new publisher about subscribers
                subscribed = bool(pub.matching_status.matching)
                pub.undeclare()
            except Exception:
                subscribed = None
    types = message_types()
    seen_types = sorted({t for s in stats for t in s.types})
    subscriber_names = decl.matching(decl.subscribers, full)
    servers = {k: who for k, who in decl.queryables.items() if _intersects(k, full)}
    if as_json:
        doc = {
            "key": full,
            "latched": keys.is_latched(full) if "*" not in full else None,
            "subscribers": subscribed,
            "subscribed_by": subscriber_names,
            "declarations_visible": decl.available,
            "services": [
                {"key": k, "request": service_types(k)[0], "reply": service_types(k)[1], "servers": who}
                for k, who in servers.items()
            ],
            "keys": [s.to_json() for s in stats],
            "types": {t: [f.__getattribute__("name") for f in fields_of(types[t])] for t in seen_types if t in types},
        }
        print(json.dumps(doc))
        if not stats and not servers:
            raise NothingThere(f"no message on {full} in {duration:g} s and no service there")
        return
    lines = [f"key: {full}"]
    for k, who in servers.items():
        req, rep = service_types(k)
        lines.append(f"  service {k}: request {req}, reply {rep}; served by {', '.join(who)}")
    nothing = not stats and not servers
    if nothing:
        lines.append(f"no message on {full} in {duration:g} s")
    for s in stats:
        lines.append(
            f"  {s.key}: type {', '.join(s.types)}; publishers {', '.join(s.publishers) or '-'}; "
            f"{s.rate_hz:.1f} Hz, {s.bytes_per_s / 1000:.1f} kB/s, last {s.last_bytes} B, {s.messages} msgs in {duration:g} s"
            + ("; latched (late joiners get the latest value)" if s.latched else "")
        )
    if decl.available and not servers:
        lines.append(f"subscribers: {', '.join(subscriber_names) or 'none'}")
    elif subscribed is not None and not servers:
        lines.append(f"subscribers: {'yes' if subscribed else 'none'} (zenoh matching status)")
    for t in seen_types:
        if t in types:
            lines.append(f"{t}:")
            for f in fields_of(types[t]):
                lines.append(f"  {f.name}: {f.type}" + (f"  {f.constraints}" if f.constraints else ""))
    print_folded(*lines)  # as wide as the terminal: a long key folds, never runs past the edge
    if nothing:
        raise NothingThere(f"nothing publishes or serves {full}")  # exit 1: the world had nothing there


def interfaces(
    type_name: Annotated[
        Optional[str],
        typer.Argument(
            help="A message type, e.g. JointState (default: list every type).", autocompletion=complete_types
        ),
    ] = None,
    as_json: Annotated[
        bool,
        typer.Option(
            "--json",
            help='One JSON document: {"types": [{name, module, fields, doc}]}, or with TYPE {"name", "module", "doc", "fields": [{name, type, constraints, default}]}.',
        ),
    ] = False,
    schema: Annotated[
        bool, typer.Option("--schema", help="Print the type's JSON Schema (what Foxglove exports declare).")
    ] = False,
) -> None:
    """Message types and their fields (like ``ros2 interface list`` / ``show``), plugins' types included."""
    from user_peer.message_schema import json_schema, type_doc
    from robofabric.interface_fields import fields_of, message_types

    types = message_types()
    if type_name is None:
        if schema:
            raise UserError("--schema needs a TYPE")
        rows = [(n, c.__module__, len(c.SPEC), type_doc(c)) for n, c in types.items()]
        if as_json:
            print(json.dumps({"types": [{"name": n, "module": m, "fields": k, "doc": d} for n, m, k, d in rows]}))
            return
        # the whole description, as plain text: it wraps in its column (it was cut at 90 characters)
        print_table(
            f"{len(rows)} message types",
            ("type", "module", "fields", "what"),
            [(n, m, str(k), plain_doc(d)) for n, m, k, d in rows],
            numeric=NUMERIC,
            fold_first=False,
        )
        return
    cls = types.get(type_name)
    if cls is None:
        raise UserError(f"unknown message type {type_name!r}; known: {', '.join(types)}")
    if schema:
        print(json.dumps(json_schema(cls), indent=2))
        return
    fields = fields_of(cls)
    if as_json:
        print(
            json.dumps(
                {
                    "name": type_name,
                    "module": cls.__module__,
                    "doc": type_doc(cls),
                    "fields": [
                        {"name": f.name, "type": f.type, "constraints": f.constraints, "default": f.default}
                        for f in fields
                    ],
                }
            )
        )
        return
    print_folded(f"{type_name} ({cls.__module__})" + (f": {plain_doc(type_doc(cls))}" if type_doc(cls) else ""))
    width = max(len(f.name) for f in fields) if fields else 0
    for f in fields:
        extra = "  ".join(x for x in (f.constraints, f"default {f.default}" if f.default else "") if x)
        print(f"  {f.name.ljust(width)}  {f.type}" + (f"  ({extra})" if extra else ""))


def register(app: typer.Typer) -> None:
    app.command("list")(list_keys)
    app.command("interfaces")(interfaces)

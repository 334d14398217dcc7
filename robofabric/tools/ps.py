"""``robofabric ps``: the live peers of a world from their liveliness tokens; -v what each publishes, subscribes, serves."""

from __future__ import annotations

import json
import sys
from collections import defaultdict
from typing import Annotated, Optional

import typer

from fabric import keys
from fabric.cli_common import Joining, NothingThere, join_flags, print_table
from robofabric.terminal import print_folded
from robofabric.complete import complete_peers
from robofabric.tools.common import open_world


@join_flags()
def ps(
    peer: Annotated[
        Optional[str], typer.Argument(help="With -v: only this peer (its id).", autocompletion=complete_peers)
    ] = None,
    verbose: Annotated[
        bool,
        typer.Option(
            "--verbose", "-v", help="What each peer publishes, subscribes to and serves (like ros2 node info)."
        ),
    ] = False,
    as_json: Annotated[
        bool,
        typer.Option(
            "--json",
            help=(
                'One JSON document instead of a table: {"world", "peers": {KIND: [ID]}, "count", "bad_tokens"}; '
                'with -v also "declarations_visible" and "info": {ID: {publishes, subscribes, serves}}.'
            ),
        ),
    ] = False,
    timeout: Annotated[float, typer.Option(help="Seconds to wait for liveliness replies.")] = 1.0,
    duration: Annotated[
        float, typer.Option(help="With -v: seconds to watch the world's traffic for what each peer publishes.")
    ] = 1.5,
    join: Joining = Joining(),
) -> None:
    """List the live peers of a world, by kind, from their liveliness tokens; -v: what each publishes, subscribes, serves.

    A token whose key names no peer (any login may declare one) is shown quoted on stderr and skipped."""
    from robofabric.declarations import live_tokens, quoted, read_declarations

    if peer is not None and not verbose:
        verbose = True
    decl = None
    published: dict[str, list[str]] = {}
    with open_world("tool", join) as fab:
        found, bad = live_tokens(fab, timeout=timeout)
        peers = [(p.kind, p.id) for p in found if p.id != fab.peer_id]
        if verbose:
            from robofabric.introspect_cli import observe

            decl = read_declarations(fab.session, fab.world, timeout=timeout)  # what each peer tells (fabric.declared)
            for s in observe(fab, keys.world_all(fab.world), duration):
                for src in s.publishers:
                    published.setdefault(src, []).append(s.key)
    print_folded(*(f"skipped a token that names no peer: {quoted(k)}" for k in bad), stderr=True)
    if peer is not None:
        peers = [(k, i) for k, i in peers if i == peer]
        if not peers:
            raise NothingThere(f"no live peer {peer!r} in world {fab.world!r}")

    def detail(pid: str) -> dict:
        """What ``pid`` publishes (seen), subscribes to and serves (told; None for a peer that did not tell)."""
        told = decl.of_peer(pid) if decl is not None else None
        subs, served = told if told is not None else (None, None)
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
            print(
                "(no peer told what it subscribes to and serves: this login may not ask, as a class world's students "
                "may not, or the peers are older; subscriptions and services unknown)",
                file=sys.stderr,
            )
        lines = []
        for k, i in peers:
            d = detail(i)
            lines.append(f"{i} ({k})")
            lines.append("  publishes:" + ("" if d["publishes"] else " -"))
            lines.extend(f"    {key}" for key in d["publishes"])
            if d["subscribes"] is None:  # a peer that did not tell (older, or raw zenoh): unknown, not none
                lines.append("  subscribes, serves: ? (it did not tell)")
                continue
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

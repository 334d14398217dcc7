"""``robofabric call``: call a service and print its replies (like ``ros2 service call``)."""

from __future__ import annotations

import json
import sys
from typing import Annotated, Optional

import typer

from fabric import keys
from fabric.cli_common import Joining, UserError, join_flags
from robofabric.complete import complete_keys, complete_types
from robofabric.tools.common import open_world, resolve_key
from robofabric.tools.message_json import message_from_json


@join_flags()
def call(
    key: Annotated[
        str,
        typer.Argument(
            help="Service key, full or world-relative: srv/world, srv/ik/arm1, srv/map/map/PEER.",
            autocompletion=complete_keys,
        ),
    ],
    msg_type: Annotated[
        Optional[str],
        typer.Option(
            "--type",
            "-t",
            help="Request type, e.g. IKRequest, FKRequest, MapRequest, PlanRequest (none: an empty query).",
            autocompletion=complete_types,
        ),
    ] = None,
    data: Annotated[
        str, typer.Option("--data", "-d", help="Request fields as JSON, e.g. '{\"q\": [0, 0, 0, 0, 0, 0]}'.")
    ] = "{}",
    all_replies: Annotated[
        bool, typer.Option("--all", help="Ask every peer serving the key, not only the nearest.")
    ] = False,
    as_json: Annotated[bool, typer.Option("--json", help="One JSON object per reply: {key, source, message}.")] = False,
    timeout: Annotated[float, typer.Option(help="Seconds to wait for replies.")] = 5.0,
    join: Joining = Joining(),
) -> None:
    """Call a service and print its replies (like ``ros2 service call``); a refusal prints its reason, exit 1."""
    from fabric.codec import to_plain
    from fabric.interfaces import ServiceError

    if timeout <= 0:
        raise UserError("--timeout must be positive")
    request = message_from_json(msg_type, data) if msg_type else None
    with open_world("tool", join, key=key) as fab:
        full = resolve_key(key, fab.world)
        try:
            if full == keys.srv(fab.world, "world") and not all_replies and request is None:
                from fabric.rpc import Reply
                from fabric.worldview import describe

                info = describe(fab, timeout=timeout)  # one world: every sim's part (--all: each part)
                replies = [
                    Reply(full, info, ",".join(sorted({r.sim for r in info.robots if r.sim})) or info.header.source)
                ]
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

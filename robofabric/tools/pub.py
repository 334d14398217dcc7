"""``robofabric pub``: publish a message built from JSON (like ``ros2 topic pub``), a command as its user.

A command waits for the sim's refusal (an event) for ``--wait`` s; nothing here sleeps for a fixed time
or polls: the subscriber match is :func:`fabric.matching.wait_matched`'s.
"""

from __future__ import annotations

import sys
import threading
from typing import TYPE_CHECKING, Annotated, Optional

import typer

from fabric import keys
from fabric.cli_common import Joining, NothingThere, UserError, join_flags
from fabric.text import one_line
from robofabric.complete import complete_keys, complete_types
from robofabric.tools.common import resolve_key, user_key
from robofabric.tools.message_json import message_from_json

if TYPE_CHECKING:
    from fabric.session import Fabric


@join_flags()
def pub(
    key: Annotated[
        str,
        typer.Argument(
            help="Concrete key, full or world-relative (robot/base1/cmd/twist: with --user, that user's key .../by/USER).",
            autocompletion=complete_keys,
        ),
    ],
    msg_type: Annotated[
        str,
        typer.Option(
            "--type", "-t", help="Message type, e.g. Twist, JointTarget, Pose, Stop.", autocompletion=complete_types
        ),
    ],
    data: Annotated[
        str, typer.Option("--data", "-d", help='Fields as JSON, e.g. \'{"v": 0.3, "omega": 0.1}\'.')
    ] = "{}",
    user: Annotated[
        Optional[str],
        typer.Option(
            help="Wrap in a Command from this user (required for cmd/* keys unless the login names the user)."
        ),
    ] = None,
    epoch: Annotated[
        Optional[int],
        typer.Option(
            help="Ownership epoch stamped on the Command (default: the user's current one, read from own/ROBOT)."
        ),
    ] = None,
    rate: Annotated[float, typer.Option(help="Publish at this rate in Hz (0: once).")] = 0.0,
    count: Annotated[
        Optional[int], typer.Option("--count", "-n", help="Number of messages (default 1, or forever with --rate).")
    ] = None,
    wait: Annotated[
        float, typer.Option(help="Seconds to wait for the sim's answer to a command (0: do not wait).")
    ] = 1.0,
    join: Joining = Joining(),
) -> None:
    """Publish a message built from JSON (like ``ros2 topic pub``); checked by the codec before it leaves.

    The key must match a robofabric key layout (refused before sending otherwise). A command (``robot/ID/cmd/NAME``)
    needs its user, from ``--user`` or the login; ``pub`` then listens for the sim's refusal for ``--wait`` s:
    exit 1 with the sim's reason when it refuses, or when no sim listens on the key; exit 0 when none came."""
    from fabric.session import shutdown_event
    from fabric.codec import encode
    from fabric.interfaces import Command
    from fabric.rate import RateLoop

    body = message_from_json(msg_type, data)
    cfg = join.config()
    try:
        user = cfg.user_id(user)  # a secure login is the user
    except ValueError as exc:
        raise UserError(str(exc)) from None
    if wait < 0:
        raise UserError("--wait must not be negative")
    n = count if count is not None else (None if rate > 0 else 1)
    # the key is checked before joining: a typo or a wrong type fails at once, and nothing is sent
    full = user_key(resolve_key(key, cfg.world), user)
    parsed = _parse_pub_key(full, user, msg_type)
    is_cmd = parsed.category == "cmd"
    if is_cmd and not user:
        user = parsed.user  # a key that names its writer (.../by/ann) is that user's command
    stop = shutdown_event()
    with join.open("tool", cfg) as fab:
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
            _listen_for_refusals(fab, parsed, refusals, refused)
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
    _say_outcome(f"{sent} {msg_type}", full, refusals, waited=wait if is_cmd else 0.0, heard=heard)


def _listen_for_refusals(fab: "Fabric", parsed: keys.ParsedKey, refusals: list[str], refused: threading.Event) -> None:
    """Collect the sim's refusals of this user's command into ``refusals`` and set ``refused`` at the first."""
    from fabric.interfaces import Event, EventKind

    def on_event(_key: str, ev: Event) -> None:
        # a refusal of this user's command, or of any command for a robot the sim does not have
        # (refused from the key alone: the sender is not known, and the event names no user)
        if ev.kind == EventKind.REJECT and (ev.user == parsed.user or (not ev.user and ev.object == parsed.subject)):
            refusals.append(ev.reason)
            refused.set()

    fab.subscribe(keys.event(fab.world, "reject", parsed.subject), on_event, expected=Event)
    fab.subscribe(keys.event(fab.world, "reject"), on_event, expected=Event)  # ids the sim has not


def _say_outcome(what: str, full: str, refusals: list[str], *, waited: float, heard: bool) -> None:
    """The last line: exit 1 with the sim's reason when it refused, or when no sim listens on a command's
    key (``waited`` > 0: a command whose answer was awaited); else what was published."""
    if refusals:
        print(f"refused: {one_line(refusals[0])} ({what} sent on {full})", file=sys.stderr)  # the sim's words, escaped
        raise typer.Exit(1)
    if waited > 0 and not heard:
        print(f"no sim listens on {full}: {what} sent, nobody took it", file=sys.stderr)
        raise typer.Exit(1)
    if waited > 0:
        print(f"published {what} on {full}; applied (not refused within {waited:g} s)")
    else:
        print(f"published {what} on {full}")


def _parse_pub_key(full: str, user: str | None, msg_type: str) -> keys.ParsedKey:
    """The layout ``full`` matches; a pattern, a key of no layout, a command without its user, or a key declared
    to carry another type than ``msg_type`` is refused before sending."""
    from robofabric.declarations import key_type

    if "*" in full or "$" in full:
        raise UserError(f"{full!r} is a pattern; pub needs a concrete key")
    try:
        parsed = keys.parse(full)
    except ValueError as exc:
        parts = full.split("/")
        if len(parts) == 6 and parts[2] == "robot" and parts[4] == "cmd" and not user:
            raise UserError(
                f"{full!r} is a command key: a command needs its user (--user NAME, or a login that names it); "
                "the sim takes the sender from the key .../by/USER"
            ) from None
        raise UserError(f"{exc}; nothing sent") from None
    if parsed.category == "cmd" and user and parsed.user != user:
        raise UserError(f"{full!r} is {parsed.user}'s command key, not {user}'s") from None
    declared = key_type(full)
    if declared is not None and declared != msg_type:
        what = "commands" if parsed.category == "cmd" else "messages"
        raise UserError(f"{full} carries {declared} {what}, not {msg_type}; nothing sent")
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
        raise NothingThere(
            f"refused: unknown_robot: no robot {robot!r} in world {fab.world!r} (robots: {', '.join(ids) or 'none'}); nothing sent"
        )


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

"""``robofabric own list|request|release|watch|staff`` (its benchmarks: robofabric/bench/ownership.py and flood.py)."""

from __future__ import annotations

import json
import sys
import time
from typing import TYPE_CHECKING, Annotated, Any, Optional

import typer

from fabric.cli_common import Joining, NothingThere, UserError, join_flags, open_fabric, print_table, say, watch_reader
from fabric.text import one_line

if TYPE_CHECKING:  # imported where used: `robofabric --help` must not load numpy
    import threading

    from fabric.interfaces import OwnershipRecord
    from fabric.session import Fabric
    from ownership.client import OwnershipClient


own_app = typer.Typer(help="Ownership of shared robots: who owns what, request, release, watch.", no_args_is_help=True)

User = Annotated[Optional[str], typer.Option("--user", "-u", help="Your user id (default: $USER).")]


def _user(user: str | None) -> str:
    import getpass

    return user or getpass.getuser()


def _client(join: Joining, user: str | None) -> tuple[Fabric, OwnershipClient]:
    from ownership.client import OwnershipClient

    cfg = join.config()
    try:
        uid = cfg.user_id(user) or _user(None)  # with a secure config, the login is the user
    except ValueError as exc:
        raise UserError(str(exc)) from None
    fab = open_fabric(cfg, "user", uid)
    return fab, OwnershipClient(fab, fab.peer_id).start()


RECORDS_WAIT_S = 5.0
"""How long ``own list`` waits for the first record. The client's first query is answered at once, but on a loaded
machine the sim's token can come after it, and its replies are refused as no live sim's until the token comes and
the client asks again: a `list` that looked once said "no ownership authority answered" of a world that had one."""


def _first_records(cl: OwnershipClient, timeout: float) -> dict[str, Any]:
    """The client's records once it trusts any (a copy taken under its lock: Zenoh's threads write the replica), or
    none after ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while not (records := cl.snapshot()) and time.monotonic() < deadline:
        time.sleep(0.05)
    return records


def _shown(text: str) -> str:
    """A name from the network as printed: control characters escaped, so none reaches the terminal, and capped."""
    return one_line(text, 64)


def record_line(rec: OwnershipRecord) -> str:
    """One record as a line of ``own list``/``watch``: names from the network escaped, never run as terminal codes."""
    obj = _shown(rec.object)
    if rec.policy == "scene":
        return f"{obj:16} scene      anyone writes"
    owner = _shown(rec.owner) or "(free)"
    queue = ", ".join(_shown(u) for u in rec.queue) or "-"
    locked = f"  locked by {_shown(rec.locked)}" if rec.locked else ""
    return f"{obj:16} exclusive  owner {owner:12} epoch {rec.epoch:<5} {rec.state:7} queue {queue}{locked}"


def record_json(rec: OwnershipRecord) -> dict[str, Any]:
    """One ownership record as ``own list --json`` writes it (stable field names)."""
    return {
        "object": rec.object,
        "policy": rec.policy,
        "owner": rec.owner,
        "epoch": rec.epoch,
        "queue": list(rec.queue),
        "state": rec.state,
        "authority": rec.authority,
        "locked": rec.locked,
    }


@own_app.command("list")
@join_flags(client=True)
def list_cmd(
    join: Joining = Joining(),
    user: User = None,
    as_json: Annotated[
        bool,
        typer.Option(
            "--json",
            help='One JSON document: {"world", "records": [{object, policy, owner, epoch, queue, state, authority, locked}]}.',
        ),
    ] = False,
) -> None:
    """Every object's owner, epoch, motion state and queue (a table as wide as the terminal; --json for scripts)."""
    fab, cl = _client(join, user)
    with fab:
        try:
            records = _first_records(cl, RECORDS_WAIT_S)
            if not records:  # the world had nothing to list: exit 1 (2 is for what the user got wrong)
                raise NothingThere(f"no ownership authority answered in world {fab.world!r} (is a sim peer running?)")
        finally:
            cl.close()
    rows = [records[obj] for obj in sorted(records)]
    if as_json:
        print(json.dumps({"world": fab.world, "records": [record_json(r) for r in rows]}))
        return
    table = [
        (_shown(r.object), "scene", "anyone writes", "-", "-", "-")
        if r.policy == "scene"
        else (
            _shown(r.object),
            "exclusive",
            _shown(r.owner) or "(free)",
            str(r.epoch),
            r.state + (f", locked by {_shown(r.locked)}" if r.locked else ""),
            ", ".join(_shown(u) for u in r.queue) or "-",
        )
        for r in rows
    ]
    print_table(
        f"world {fab.world}: {len(rows)} object(s)",
        ("object", "policy", "owner", "epoch", "state", "queue"),
        table,
        numeric=("epoch",),
    )


def _ask(
    op: str,
    obj: str,
    join: Joining,
    user: str | None,
    wait: bool = False,
    hold: bool = False,
    duration: float | None = None,
) -> None:
    from fabric.interfaces import ServiceError
    from fabric.session import shutdown_event

    stop = shutdown_event() if hold else None
    fab, cl = _client(join, user)
    with fab:
        try:
            try:
                out = cl.request(obj, wait=wait) if op == "request" else cl.release(obj)
            except ServiceError as exc:  # refused, or no authority answered: the world said no (exit 1)
                raise NothingThere(f"{op} {obj}: {exc.reason}") from None
            print(f"{obj}: {out}", flush=True)
            if out.outcome == "denied":
                raise typer.Exit(1)
            if stop is not None:
                _hold(cl, obj, stop, duration)
        finally:
            cl.close()


def _hold(cl: OwnershipClient, obj: str, stop: threading.Event, duration: float | None) -> None:
    """Keep the lease (token + renewals) until Ctrl-C / SIGTERM / ``duration``, then give the object up.

    Prints each change of the object's record, so a queued user sees the moment it is granted."""
    from fabric.interfaces import ServiceError

    cl.on_change(lambda rec: say(record_line(rec), stop=stop) if rec.object == obj else None)
    say(f"holding {obj} as {cl.user} (Ctrl-C releases it)", stop=stop)
    stop.wait(duration)
    try:
        say(f"{obj}: {cl.release(obj)}")
    except ServiceError as exc:  # the authority went away: the lease lapses on its own
        say(f"{obj}: release not confirmed: {exc.reason}")


@own_app.command("request")
@join_flags(client=True)
def request_cmd(
    obj: Annotated[str, typer.Argument(help="Object id (robot or scene object).")],
    join: Joining = Joining(),
    user: User = None,
    wait: Annotated[bool, typer.Option("--wait", help="Queue if the robot is moving.")] = False,
    hold: Annotated[
        bool, typer.Option("--hold", help="Keep holding (renewing the lease) until Ctrl-C, then release.")
    ] = False,
    duration: Annotated[
        Optional[float], typer.Option("--duration", help="With --hold: release after S seconds.")
    ] = None,
) -> None:
    """Ask for OBJ: granted, denied (in motion / owned by X) or queued at position N.

    Ownership lasts while a renewing peer holds it. Without --hold this command exits at once, so
    the lease lapses after the lease time; with --hold it renews (and keeps a queue place, printing
    the grant when it comes) until Ctrl-C, like a program's OwnershipClient or the TUI.
    """
    if duration is not None and not hold:
        raise UserError("--duration needs --hold")
    _ask("request", obj, join, user, wait, hold, duration)


@own_app.command("release")
@join_flags(client=True)
def release_cmd(
    obj: Annotated[str, typer.Argument(help="Object id.")], join: Joining = Joining(), user: User = None
) -> None:
    """Give OBJ up (or leave its queue); the next waiting user owns it."""
    _ask("release", obj, join, user)


@own_app.command("staff")
@join_flags(client=True)
def staff_cmd(
    op: Annotated[str, typer.Argument(help="take_back, give, lock, unlock, stop or reset.")],
    obj: Annotated[str, typer.Argument(help="Robot id.")],
    join: Joining = Joining(),
    user: User = None,
    to: Annotated[
        Optional[str], typer.Option("--to", help="With give: the user who gets the robot (logged in now).")
    ] = None,
) -> None:
    """An instructor's action on OBJ, through the authority's rules (the teacher's page does the same): take it
    back from its owner, give it to a user, lock or unlock it, stop or reset it. A class's router passes it from
    instructor logins only (secure init --instructors); refused: exit 1 with the reason."""
    from fabric.interfaces import STAFF_OPS, ServiceError

    if op not in STAFF_OPS:
        raise UserError(f"unknown staff action {op!r}: one of {', '.join(STAFF_OPS)}")
    if (op == "give") != bool(to):
        raise UserError("--to USER goes with give, and only with it")
    fab, cl = _client(join, user)
    with fab:
        try:
            try:
                out = cl.staff(obj, op, to=to or "")
            except ServiceError as exc:  # no answer: the router passed it to no authority, or none runs
                raise NothingThere(
                    f"{op} {obj}: {exc.reason} (a class's router passes staff actions from instructor logins only)"
                ) from None
            print(f"{obj}: {out.outcome}: {_shown(out.reason)}", flush=True)
            if out.outcome != "done":
                raise typer.Exit(1)
        finally:
            cl.close()


@own_app.command("watch")
@join_flags(client=True)
def watch_cmd(
    join: Joining = Joining(),
    user: User = None,
    duration: Annotated[
        Optional[float], typer.Option("--duration", help="Stop after S seconds (default: until Ctrl-C).")
    ] = None,
) -> None:
    """Print every ownership change until Ctrl-C.

    What cannot be believed is skipped and counted, never printed: payloads that do not decode, and records
    from no live authority (a made-up sim, a stale term); the counts go to stderr at the end."""
    from fabric.session import shutdown_event

    if duration is not None and not duration > 0:
        raise UserError("--duration must be positive")
    stop = shutdown_event()
    watch_reader(stop)  # `own watch | head -2`: ends when head does, though nothing changes after
    fab, cl = _client(join, user)
    with fab:
        records = cl.snapshot()
        say(*(record_line(records[obj]) for obj in sorted(records)), stop=stop)
        cl.on_change(lambda rec: say(record_line(rec), stop=stop))  # a closed pipe ends the watch (exit 0)
        stop.wait(duration)
        cl.close()
        skipped = _skipped(fab, cl)
    if skipped:
        print(f"skipped {skipped}", file=sys.stderr, flush=True)


def _skipped(fab: object, cl: object) -> str:
    """'2 undecodable payload(s), 1 record(s) from no live authority' ("" when nothing was skipped)."""

    def count(counters: Any, name: str) -> int:
        try:
            return int(counters.get(name, 0))
        except Exception:
            return 0

    counters = getattr(cl, "counters", {})
    undecodable = count(getattr(fab, "counters", {}), "decode_errors")
    refused = sum(count(counters, f"records_{why}") for why in ("foreign", "stale", "implausible"))
    parts = [f"{undecodable} undecodable payload(s)"] * bool(undecodable) + [
        f"{refused} record(s) from no live authority"
    ] * bool(refused)
    return ", ".join(parts)


def register(app: typer.Typer) -> None:
    app.add_typer(own_app, name="own")

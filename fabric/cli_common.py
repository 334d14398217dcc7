"""Options every peer command shares, and the one way CLI errors are reported.

A command that joins a world takes the flags ``--world``, ``--connect``, ``--listen``, ``--profile``,
``--zenoh-config`` and ``--id`` from one definition (:func:`join_flags`, as one :class:`Joining`), so they
mean the same everywhere; a peer package's ``cli.py`` raises :class:`UserError` for anything the user got
wrong: the CLI prints one line and exits 2, no traceback.

The exit-code rule of every command (:data:`EXIT_RULE`): 0 when what was asked happened, 1 when the world
answered no or had nothing (:class:`NothingThere`), 2 for a usage error or an unreachable router
(:class:`UserError`). A streaming command writes through :func:`say`: when its reader goes away
(``robofabric echo KEY | head -3``) it ends quietly with 0, like Ctrl-C.
"""

from __future__ import annotations

import functools
import inspect
import os
import sys
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Callable, Collection, Optional, Sequence

import typer

from fabric.config import ConfigError, FabricConfig

if TYPE_CHECKING:
    from rich.console import Console

    from fabric.session import Fabric

__all__ = [
    "UserError",
    "NothingThere",
    "EXIT_RULE",
    "say",
    "reader_gone",
    "watch_reader",
    "stdout_closed",
    "World",
    "Connect",
    "Listen",
    "PeerId",
    "Profile",
    "ZenohConfig",
    "Joining",
    "join_flags",
    "make_config",
    "join_error",
    "open_fabric",
    "console",
    "print_table",
    "column_widths",
]


class UserError(Exception):
    """Something the user asked for cannot be done; printed as one line, exit code 2."""


class NothingThere(Exception):
    """The world answered no or had nothing to show (no such key, no sim, a refusal); printed as one line, exit 1."""


EXIT_RULE = (
    "Exit codes, the same for every command: 0 what was asked happened; 1 the world answered no or had "
    "nothing (no publisher, no sim, a refusal); 2 a usage error or a router that cannot be reached."
)

_stdout_gone = threading.Event()


def stdout_closed() -> bool:
    """Whether the reader of stdout went away (a closed pipe)."""
    return _stdout_gone.is_set()


def reader_gone() -> None:
    """The reader of stdout went away: stdout becomes /dev/null, so that nothing written later (another
    callback's line, the interpreter's flush at exit) raises or prints a traceback. Idempotent."""
    if _stdout_gone.is_set():
        return
    _stdout_gone.set()
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError):  # no file descriptor behind stdout (a test's capture): nothing to redirect
        pass


def watch_reader(stop: threading.Event) -> None:
    """Set ``stop`` when the reader of a piped stdout goes away, even while nothing is written.

    A command that writes only on change (``own watch | head -2`` after its first two lines) would learn of
    a closed pipe only at its next write, which may never come; Linux reports a pipe without readers as an
    error condition on the writing end, which a daemon thread waits for. Only for a pipe: a terminal or a
    file has no reader to lose."""
    import select
    import stat

    try:
        fd = sys.stdout.fileno()
        if not stat.S_ISFIFO(os.fstat(fd).st_mode) or not hasattr(select, "poll"):
            return
    except (OSError, ValueError):
        return

    def wait() -> None:
        poller = select.poll()
        poller.register(fd, 0)  # no events asked: only POLLERR / POLLHUP (no reader left) wake it
        try:
            while not poller.poll():
                pass
        except OSError:
            return
        reader_gone()
        stop.set()

    threading.Thread(target=wait, name="stdout-reader", daemon=True).start()


def say(*lines: str, stop: threading.Event | None = None) -> bool:
    """Write ``lines`` to stdout and flush: how a streaming command prints, from any thread.

    Returns False, and sets ``stop``, once the reader has gone (``| head -3`` closed the pipe): the command
    then ends as if it had been asked to (exit 0), instead of a traceback per message."""
    if not _stdout_gone.is_set():
        try:
            sys.stdout.write("".join(f"{line}\n" for line in lines))
            sys.stdout.flush()
            return True
        except BrokenPipeError:
            reader_gone()
        except OSError as exc:  # EPIPE under another name; anything else is a real failure
            import errno

            if exc.errno != errno.EPIPE:
                raise
            reader_gone()
    if stop is not None:
        stop.set()
    return False


World = Annotated[
    Optional[str],
    typer.Option("--world", "-w", help="World name: the key prefix rf/WORLD. Env ROBOFABRIC_WORLD; default 'demo'."),
]
Connect = Annotated[
    Optional[list[str]],
    typer.Option(
        "--connect",
        "-e",
        help="Router endpoint to connect to, e.g. tcp/192.168.1.10:7447 (repeatable). Env ROBOFABRIC_CONNECT (comma-separated).",
    ),
]
Listen = Annotated[
    Optional[list[str]],
    typer.Option("--listen", "-l", help="Endpoint to listen on, e.g. tcp/0.0.0.0:7447 (repeatable)."),
]
PeerId = Annotated[Optional[str], typer.Option("--id", help="This peer's id (default: KIND-HOST-RANDOM).")]
Profile = Annotated[
    Optional[str],
    typer.Option(
        "--profile",
        help="embedded (this process is the router), client (connect to routers; default) or peer (LAN multicast scouting).",
    ),
]
ZenohConfig = Annotated[
    Optional[Path],
    typer.Option(
        "--zenoh-config", help="A zenoh json5 config file (TLS, auth, access control...); flags override its endpoints."
    ),
]


def console(*, stderr: bool = False) -> Console:
    """The rich console every table and long line of the CLI goes through: as wide as the terminal
    (``$COLUMNS`` when set, 80 when the output is not a terminal), folding what does not fit rather than
    cutting it; no markup, highlighting or emoji, so keys and ids from the network print as they are."""
    return _console_class()(stderr=stderr, markup=False, highlight=False, emoji=False)


_CONSOLE: type[Console] | None = None


def _console_class() -> type[Console]:
    """rich's Console, but a closed stdout ends the command with 0 (rich's own exits 1), as :func:`say` does."""
    global _CONSOLE
    if _CONSOLE is None:
        from rich.console import Console

        class _Console(Console):
            def on_broken_pipe(self) -> None:
                self.quiet = True
                reader_gone()
                raise SystemExit(0)

        _CONSOLE = _Console
    return _CONSOLE


CELL_CAP = 500
"""A table cell's length at most (:func:`fabric.text.one_line`): a key of the network's is shown whole up to it."""
BOXED = 3
"""Columns a boxed table spends per column (a border and a space each side), plus one for the last border."""
PLAIN = 3
"""Columns a borderless table spends between two columns, and none at its edges."""


def column_widths(
    columns: Sequence[str],
    rows: Sequence[Sequence[str]],
    width: int,
    *,
    boxed: bool = True,
    fold_first: bool = True,
    whole: Collection[int] = (),
) -> list[int] | None:
    """Widths (without padding) for a table of ``columns`` and ``rows`` to fit ``width`` with no word cut,
    or None when it cannot.

    Every column is at least as wide as its longest word (an id, a type, a number never breaks), except,
    with ``fold_first``, the first, whose keys may fold from 12 columns up (they read whole down the
    column), and the columns in ``whole`` (numbers with their units: ``2.9 kB``) are as wide as their
    widest cell; what is left goes first to the columns that need least to show their cells on one line
    (a long description takes what the others leave)."""
    n = len(columns)
    room = width - (BOXED * n + 1 if boxed else PLAIN * (n - 1))
    cells = [[str(columns[i]), *(str(r[i]) for r in rows)] for i in range(n)]
    natural = [max(len(line) for c in col for line in (c.splitlines() or [""])) for col in cells]
    least = [max((len(w) for c in col for w in c.split()), default=1) for col in cells]
    for i in whole:
        least[i] = max(least[i], max(len(c) for c in cells[i][1:]) if rows else 0)
    if fold_first:
        least[0] = min(natural[0], max(12, len(str(columns[0]))))
    if sum(natural) <= room:
        return natural
    if sum(least) > room:
        return None
    left, want = room - sum(least), [nat - lo for nat, lo in zip(natural, least)]
    widths = list(least)
    order = sorted(range(n), key=lambda i: want[i])
    for k, i in enumerate(order):  # max-min fair: each gets its need or an even share of what is left
        give = min(want[i], left // (n - k))
        widths[i] += give
        left -= give
    return widths


def print_table(
    title: str,
    columns: Sequence[str],
    rows: Sequence[Sequence[str]],
    *,
    numeric: Collection[str] = (),
    fold_first: bool = True,
    stderr: bool = False,
) -> None:
    """The one way the CLI prints a table: as wide as the terminal at most, every cell whole.

    Cells wrap between words and no word is cut (:func:`column_widths`); a key in the first column folds
    and reads whole down it. When the columns cannot fit side by side (a narrow terminal), each row is
    printed as a block instead: its first cell, then one ``column: value`` line per other column, folded
    at the terminal's edge. No column is ever dropped. A table that fits only without its box (``list``'s
    seven columns at 80) is printed without it."""
    from rich import box
    from rich.table import Table

    from fabric.text import one_line

    # keys, ids and names come from the network: each cell one line, escaped (rich passes ESC on), capped
    title, rows = one_line(title, 500), [[one_line(v, CELL_CAP) for v in r] for r in rows]
    out = console(stderr=stderr)
    boxed = True
    whole = [i for i, c in enumerate(columns) if c in numeric]  # a number and its unit on one line
    widths = column_widths(columns, rows, out.width, fold_first=fold_first, whole=whole)
    if widths is None:
        boxed = False
        widths = column_widths(columns, rows, out.width, boxed=False, fold_first=fold_first, whole=whole)
    if widths is None:
        from rich.padding import Padding
        from rich.text import Text

        out.print(title, overflow="fold")
        for r in rows:
            out.print(str(r[0]), overflow="fold")
            for c, v in zip(columns[1:], r[1:]):  # a value that wraps stays indented under its row
                out.print(Padding(Text(f"{c}: {v}", overflow="fold"), (0, 0, 0, 2)))
        return
    table = Table(title=title) if boxed else Table(title=title, box=box.SIMPLE_HEAD, show_edge=False, pad_edge=False)
    for col, w in zip(columns, widths):
        table.add_column(col, justify="right" if col in numeric else "left", overflow="fold", width=w)
    for r in rows:
        table.add_row(*(str(v) for v in r))
    out.print(table)


def make_config(
    world: str | None = None,
    connect: list[str] | None = None,
    listen: list[str] | None = None,
    profile: str | None = None,
    zenoh_config: Path | None = None,
) -> FabricConfig:
    """Flags + environment -> FabricConfig, with configuration mistakes turned into :class:`UserError`."""
    try:
        return FabricConfig.resolve(
            world=world,
            profile=profile,
            connect=connect,
            listen=listen,
            config_file=str(zenoh_config) if zenoh_config else None,
        )
    except (ConfigError, ValueError) as exc:
        raise UserError(str(exc)) from None


def join_error(cfg: FabricConfig, exc: BaseException) -> UserError:
    """The one-line error for a session that could not open (:meth:`FabricConfig.join_failure`)."""
    return UserError(cfg.join_failure(exc))


def open_fabric(cfg: FabricConfig, kind: str, peer_id: str | None = None) -> "Fabric":
    """Join the world as a peer of ``kind``; a router that is not there is a :class:`UserError`, not a traceback."""
    from fabric.session import Fabric

    try:
        return Fabric(cfg, kind=kind, peer_id=peer_id)
    except Exception as exc:
        raise join_error(cfg, exc) from None


@dataclass(frozen=True, slots=True)
class Joining:
    """Which world a command joins, and how: its flags ``--world``, ``--connect``, ``--listen``, ``--profile``,
    ``--zenoh-config`` and ``--id`` as one value (:func:`join_flags` hands it to the command)."""

    world: str | None = None
    connect: list[str] | None = None
    listen: list[str] | None = None
    profile: str | None = None
    zenoh_config: Path | None = None
    peer_id: str | None = None

    def config(self, *, world: str | None = None) -> FabricConfig:
        """Flags + environment -> FabricConfig (:func:`make_config`); a ``world`` given here wins over
        ``--world`` (``replay --remap-world``)."""
        return make_config(world or self.world, self.connect, self.listen, self.profile, self.zenoh_config)

    def open(self, kind: str, cfg: FabricConfig | None = None) -> "Fabric":
        """Join the world (``cfg``, or the flags') as a peer of ``kind`` under ``--id`` (:func:`open_fabric`)."""
        return open_fabric(cfg if cfg is not None else self.config(), kind, self.peer_id)


JOIN_FLAGS: dict[str, Any] = {
    "world": World,
    "connect": Connect,
    "listen": Listen,
    "profile": Profile,
    "zenoh_config": ZenohConfig,
    "peer_id": PeerId,
}
"""Each joining flag's parameter name and its option, in the order ``--help`` lists them."""
CLIENT_FLAGS = ("world", "connect", "profile", "zenoh_config")
"""The flags of a command that talks to a world without being one of its peers (no listener, no id of its own)."""


def join_flags(*, client: bool = False) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Decorate a command whose parameter ``join: Joining`` stands for the flags that say which world to join:
    typer sees, at that parameter's place (so in ``--help`` too), ``--world``, ``--connect``, ``--listen``,
    ``--profile``, ``--zenoh-config`` and ``--id`` (with ``client``: :data:`CLIENT_FLAGS`), and the command
    gets them back as one :class:`Joining`.

    Twenty commands declared the same six parameters and passed them on one by one; this one definition
    keeps their names, help texts and order the same in every command. Typer reads the signature set here."""
    names = CLIENT_FLAGS if client else tuple(JOIN_FLAGS)
    keyword = inspect.Parameter.KEYWORD_ONLY

    def decorate(command: Callable[..., Any]) -> Callable[..., Any]:
        sig = inspect.signature(command, eval_str=True)
        params = list(sig.parameters.values())
        at = next((i for i, p in enumerate(params) if p.name == "join"), None)
        if at is None:
            raise TypeError(f"{command.__qualname__} has no parameter 'join' for join_flags to stand in for")
        flags = [inspect.Parameter(n, keyword, default=None, annotation=JOIN_FLAGS[n]) for n in names]
        shown = (
            [p.replace(kind=keyword) for p in params[:at]] + flags + [p.replace(kind=keyword) for p in params[at + 1 :]]
        )

        @functools.wraps(command)
        def run(**kwargs: Any) -> Any:
            return command(join=Joining(**{n: kwargs.pop(n, None) for n in names}), **kwargs)

        run.__signature__ = sig.replace(parameters=shown)  # type: ignore[attr-defined]
        run.__annotations__ = {p.name: p.annotation for p in shown}
        return run

    return decorate

"""The ``robofabric`` command line: the root app, its plugins, and the console script's entry.

Subcommands arrive as plugins through the entry-point group
``robofabric.commands``: each entry is a callable ``register(app)`` that adds
commands to the root Typer app. The CLI therefore names no peer package, and a
user can add a peer of their own by declaring an entry point. A plugin that
fails to load is reported and skipped: the rest still works.

:func:`main` first checks that our ``fabric`` package is still ours
(:mod:`robofabric.clash`): the SSH library Fabric installs into the same name,
and then ``fabric`` may not import at all, so its names are imported in a way
that lets :func:`main` say so instead of failing with a traceback. Peer
processes that launch files start run ``python -m robofabric.cli``.
"""

from __future__ import annotations

import logging
import os
import sys
from importlib.metadata import entry_points
from typing import Any

import typer
from typer.core import TyperGroup

from robofabric.clash import fabric_clash

try:  # our `fabric`, unless another package replaced its files: main() says so (robofabric.clash)
    from fabric.cli_common import EXIT_RULE, NothingThere, UserError, reader_gone, stdout_closed
    from fabric.config import ConfigError
    from robofabric.terminal import plain_doc
except ImportError as exc:  # pragma: no cover - only with a broken install
    _FABRIC_BROKEN: ImportError | None = exc
    EXIT_RULE = ""
else:
    _FABRIC_BROKEN = None

GROUP = "robofabric.commands"


class _RootGroup(TyperGroup):
    """The root command group: flags and counters show no type in help.

    typer 0.29's help prints a type after every option, ``<bool>`` after plain flags (``--help``,
    ``--json``) and ``<int>`` after counters (``-v``), which read as if they took a value. An empty
    ``metavar`` is click's own way to show none (typer prints an option's metavar in place of its
    type); the root sets it on the flags of each command it hands out, its own included, so every
    plugin's commands look the same without each option saying so. Every other option keeps its type,
    and parsing does not read a flag's metavar."""

    def get_params(self, ctx: Any) -> list[Any]:
        return _untyped_flags(super().get_params(ctx))

    def get_command(self, ctx: Any, cmd_name: str) -> Any:
        cmd = super().get_command(ctx, cmd_name)
        if cmd is not None:
            _untype_tree(cmd, ctx)
        return cmd


def _untyped_flags(params: list[Any]) -> list[Any]:
    for p in params:
        flag = getattr(p, "is_flag", False) or getattr(p, "count", False)  # typer's options are no click.Option
        if p.param_type_name == "option" and flag and p.metavar is None:
            p.metavar = ""
    return params


def _untype_tree(cmd: Any, ctx: Any) -> None:
    """The flags of ``cmd`` and of every command under it (``own list``'s as well as ``own``'s), ``--help``
    included (each command makes its help option once, on first ask)."""
    help_option = cmd.get_help_option(ctx)
    _untyped_flags([*cmd.params, *([help_option] if help_option is not None else [])])
    for sub in getattr(cmd, "commands", {}).values():  # a group (typer's click: no click.Group)
        _untype_tree(sub, ctx)


app = typer.Typer(
    name="robofabric",
    cls=_RootGroup,
    help="Multi-user robot simulation fabric over Zenoh: run routers and peers, inspect live keys, record and replay.\n\n"
    + EXIT_RULE,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=True,  # --install-completion / --show-completion (bash, zsh, fish, PowerShell)
)

_broken: list[tuple[str, str]] = []
_loaded: set[str] = set()  # the entry points whose commands are in :data:`app` (or that failed), by name


def resolve_annotations(typer_app: typer.Typer) -> None:
    """Evaluate each command's string annotations (``from __future__ import annotations``) once.

    typer reads a command's signature with ``inspect.signature(eval_str=True)`` and ``get_type_hints``,
    twice per command, so every string annotation was compiled and evaluated four times at each start
    (~20 ms of CPU over the whole tree). The evaluated objects are the ones typer would have made; a
    function whose annotations do not resolve is left as it is (typer reports it as before)."""
    from typing import get_type_hints

    for fn in _callbacks(typer_app):
        ann = getattr(fn, "__annotations__", None)
        if not ann or not any(isinstance(a, str) for a in ann.values()):
            continue
        try:
            fn.__annotations__ = get_type_hints(fn, include_extras=True)
        except Exception:
            continue


def _callbacks(t: typer.Typer):
    """Every function behind a command or group of ``t``, its sub-apps' included."""
    if t.registered_callback is not None:
        yield t.registered_callback.callback
    for c in t.registered_commands:
        yield c.callback
    for g in t.registered_groups:
        yield g.callback
        if g.typer_instance is not None:
            yield from _callbacks(g.typer_instance)


def _plain_help(typer_app: typer.Typer) -> None:
    """Help texts as a terminal shows them (:func:`robofabric.terminal.plain_doc`): docstrings are written for
    the API docs, with reStructuredText quoting (``ros2 topic hz`` showed its backquotes) and lines
    wrapped at the source's width, which the help then wrapped again at the terminal's (broken lines)."""
    for fn in _callbacks(typer_app):
        doc = getattr(fn, "__doc__", None)
        if doc and not getattr(fn, "_robofabric_plain", False):
            try:
                fn.__doc__ = plain_doc(doc)
                fn._robofabric_plain = True  # type: ignore[attr-defined]
            except (AttributeError, TypeError):  # a builtin or a bound method: left as it is
                continue

    def infos(t: typer.Typer):
        yield t.info
        yield from t.registered_commands
        for g in t.registered_groups:
            yield g
            if g.typer_instance is not None:
                yield from infos(g.typer_instance)

    for info in infos(typer_app):
        text = getattr(info, "help", None)
        if isinstance(text, str) and text:
            info.help = plain_doc(text)


def defer_rich_extras() -> None:
    """Import ``typer.rich_utils`` without ``rich.markdown`` (markdown-it) and ``rich.traceback`` (pygments).

    typer imports both at the top of its help renderer, for markdown help text and pretty tracebacks,
    neither of which robofabric uses (rich markup; ``pretty_exceptions_enable=False``): ~45 ms of the
    ~200 ms of CPU that ``robofabric --help`` costs. While ``typer.rich_utils`` loads, those two modules
    are stand-ins whose ``Markdown`` and ``Traceback`` are classes that import the real one on first use
    (a call, or an attribute such as ``Traceback.from_exception``); the stand-ins leave ``sys.modules``
    at once, so any later ``import rich.markdown`` is the real module."""
    import importlib

    if "typer.rich_utils" in sys.modules:
        return

    class _Later(type):
        def __getattr__(cls, attr: str):  # class attributes (Traceback.from_exception) of the real class
            return getattr(cls._real(), attr)

    def later(module: str, name: str) -> type:
        def real():
            return getattr(importlib.import_module(module), name)

        return _Later(
            name,
            (),
            {"__new__": lambda _cls, *a, **k: real()(*a, **k), "_real": staticmethod(real), "__module__": module},
        )

    import types

    stand_ins = {}
    for module, name in (("rich.markdown", "Markdown"), ("rich.traceback", "Traceback")):
        if module not in sys.modules:
            stub = types.ModuleType(module)
            setattr(stub, name, later(module, name))
            stand_ins[module] = sys.modules[module] = stub
    try:
        import typer.rich_utils  # noqa: F401
    except Exception:
        pass
    finally:
        for module, stub in stand_ins.items():
            if sys.modules.get(module) is stub:
                del sys.modules[module]


def load_plugins() -> None:
    """Add every installed package's commands (entry points of ``robofabric.commands``) to :data:`app`; a plug-in
    that fails to load is named in a warning at each run, never fatal.

    Once per entry point and process: :func:`main` calls it at each run, and a script or a test that ran the CLI
    again added every command again (in one process, the second help took 0.035 s of CPU, the eighth 0.1 s)."""
    for ep in sorted(entry_points(group=GROUP), key=lambda e: e.name):
        if ep.name in _loaded:
            continue
        _loaded.add(ep.name)
        try:
            register = ep.load()
            register(app)
        except Exception as exc:  # a broken plugin must not take the whole CLI down
            _broken.append((ep.name, f"{type(exc).__name__}: {exc}"))


def version_text() -> str:
    """``robofabric X.Y.Z`` from the installed distribution's metadata (``0+unknown`` in a bare source tree)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return f"robofabric {version('robofabric')}"
    except PackageNotFoundError:
        return "robofabric 0+unknown"


def _print_version(value: bool) -> None:
    if value:
        print(version_text())
        raise typer.Exit(0)


@app.callback()
def _root(
    verbose: int = typer.Option(0, "--verbose", "-v", count=True, help="More logging (-v info, -vv debug)."),
    version: bool = typer.Option(
        False, "--version", help="Print the version and exit.", callback=_print_version, is_eager=True
    ),
) -> None:
    level = logging.WARNING - 10 * min(verbose, 2)
    logging.basicConfig(
        level=int(os.environ.get("ROBOFABRIC_LOG_LEVEL", level)),
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    for name, why in _broken:
        print(f"warning: plugin {name!r} could not be loaded: {why}", file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    """Run ``robofabric ARGS``; the exit code (0 done, 1 nothing there, 2 usage or no router: :data:`EXIT_RULE`)."""
    warning = fabric_clash()
    if warning:
        print(warning, file=sys.stderr)
    if _FABRIC_BROKEN is not None:
        print(f"error: robofabric's package 'fabric' cannot be imported ({_FABRIC_BROKEN})", file=sys.stderr)
        if not warning:
            print("hint: is another package named 'fabric' on the path? (`pip show fabric`)", file=sys.stderr)
        return 2
    load_plugins()
    resolve_annotations(app)
    _plain_help(app)
    args = sys.argv[1:] if argv is None else argv
    if not args or "--help" in args or "-h" in args:
        defer_rich_extras()
    try:
        app(args=argv, prog_name="robofabric", standalone_mode=True)
    except (UserError, ConfigError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except NothingThere as exc:
        print(str(exc), file=sys.stderr)
        return 1
    except SystemExit as exc:
        if _stdout_was_closed():
            return 0  # the reader went away (`| head`): what it asked for, it got
        code = exc.code
        return code if isinstance(code, int) else (0 if code is None else 1)
    except BrokenPipeError:
        reader_gone()
        return 0
    return 0


def _stdout_was_closed() -> bool:
    """Whether typer ended the command on a closed stdout (it wraps stdout and exits 1 on EPIPE)."""
    if type(sys.stdout).__name__ == "PacifyFlushWrapper":  # by name: click 8.2 deprecates importing it
        reader_gone()
        return True
    return stdout_closed()


if __name__ == "__main__":
    sys.exit(main())

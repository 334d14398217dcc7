"""``robofabric bench``: one subcommand per entry of :data:`robofabric.bench.BENCHMARKS`, plus ``list`` and ``all``.

Registered as the plugin ``bench`` of the entry-point group ``robofabric.commands`` (pyproject.toml), like
every other subcommand; this is the only place a benchmark becomes a command.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Callable

import typer
import typer.main
from typer.core import TyperGroup

if TYPE_CHECKING:  # annotations only: importing click costs every `robofabric` start (typer carries its own)
    import click

from robofabric.bench import BENCHMARKS, Benchmark, get, names

__all__ = ["build_app", "register", "run_all", "BenchOutcome"]

HELP = "Benchmarks: each prints a table and can append it to docs/benchmarks.md (see --help of each)."


class _LazyBenchGroup(TyperGroup):
    """The ``bench`` group: each benchmark's module is imported when that benchmark is named (its command, or
    ``bench --help``), never when ``robofabric`` starts: most of them import numpy, zenoh or a peer at the top,
    and every ``robofabric`` command (``--help`` included) paid for all of them."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return [*names(), *super().list_commands(ctx)]

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        cmd = super().get_command(ctx, cmd_name)
        if cmd is not None or cmd_name not in names():
            return cmd
        b = get(cmd_name)
        one = typer.Typer()
        one.command(b.name, short_help=b.measures)(b.command())
        cmd = typer.main.get_command(one)
        cmd.name = b.name
        self.add_command(cmd, b.name)
        return cmd


def build_app() -> typer.Typer:
    """A ``bench`` group with every registered benchmark (loaded when named), ``list`` and ``all``."""
    app = typer.Typer(help=HELP, no_args_is_help=True, cls=_LazyBenchGroup)
    app.command("list", short_help="The registered benchmarks and the command lines of docs/benchmarks.md.")(list_cmd)
    app.command("all", short_help="Run every benchmark (or --only some), one process each, tables in one file.")(
        all_cmd
    )
    return app


def register(app: typer.Typer) -> None:
    """Entry point of the ``robofabric.commands`` group: add ``bench`` to the root app."""
    app.add_typer(build_app(), name="bench")


def list_cmd(
    quick: Annotated[
        bool, typer.Option("--quick", help="Show the smoke-sized arguments instead of the documented ones.")
    ] = False,
    as_json: Annotated[
        bool,
        typer.Option(
            "--json",
            help='One JSON document: {"benchmarks": [{name, measures, needs, argv}]} (argv: the command line after robofabric).',
        ),
    ] = False,
) -> None:
    """The registered benchmarks: name, what it measures, and the command line of its figures (or its quick run)."""
    if as_json:
        import json

        print(
            json.dumps(
                {
                    "benchmarks": [
                        {"name": b.name, "measures": b.measures, "needs": b.needs, "argv": b.argv(quick=quick)}
                        for b in BENCHMARKS
                    ]
                }
            )
        )
        return
    width = max(len(n) for n in names())
    for b in BENCHMARKS:
        need = f" [needs {b.needs}]" if b.needs else ""
        print(f"{b.name:<{width}}  {b.measures}{need}")
        print(f"{'':<{width}}  robofabric {' '.join(b.argv(quick=quick))}")


@dataclass(frozen=True, slots=True)
class BenchOutcome:
    """What ``bench all`` did with one benchmark: its exit code (None: skipped, with the reason) and its time."""

    name: str
    argv: tuple[str, ...]
    returncode: int | None
    seconds: float
    reason: str = ""


def _select(only: str, skip: str) -> list[Benchmark]:
    from fabric.cli_common import UserError

    def split(text: str) -> list[str]:
        return [x.strip() for x in text.split(",") if x.strip()]

    chosen, skipped = split(only), split(skip)
    unknown = [n for n in chosen + skipped if n not in names()]
    if unknown:
        raise UserError(f"unknown benchmark(s) {', '.join(unknown)}; known: {', '.join(names())}")
    return [b for b in BENCHMARKS if (not chosen or b.name in chosen) and b.name not in skipped]


def _run_streaming(argv: list[str]) -> tuple[int, str]:
    """Run a child, echo its output line by line as it comes, return (exit code, the output)."""
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines: list[str] = []
    try:
        assert proc.stdout is not None
        for line in proc.stdout:
            sys.stdout.write(line)
            sys.stdout.flush()
            lines.append(line)
        return proc.wait(), "".join(lines)
    finally:
        if proc.poll() is None:  # interrupted: end the child (it ends its own children) by pid
            proc.terminate()
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def _header() -> str:
    from robofabric.bench.common import machine

    try:
        rev = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, timeout=10
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        rev = ""
    return (
        f"# robofabric benchmarks, {time.strftime('%Y-%m-%dT%H:%MZ', time.gmtime())}\n\n"
        f"Machine: {machine()}; git {rev or '?'}\n"
    )


def run_all(
    selected: list[Benchmark], *, quick: bool, out: Path, progress: Callable[[str], None] = print
) -> list[BenchOutcome]:
    """Run each benchmark in its own process (``python -m robofabric bench NAME ...``), one after the other,
    and write its table (from its ``--out`` file, else its output) under a heading in ``out``."""
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(_header(), encoding="utf-8")
    outcomes: list[BenchOutcome] = []
    with tempfile.TemporaryDirectory(prefix="bench-all-") as tmp:
        for b in selected:
            shown = ("robofabric", *b.argv(quick=quick))
            why = b.unavailable()
            if why:
                progress(f"== {' '.join(shown)}: skipped ({why})")
                outcomes.append(BenchOutcome(b.name, shown, None, 0.0, why))
                with open(out, "a", encoding="utf-8") as f:
                    f.write(f"\n## `{' '.join(shown)}`\n\nskipped: {why}\n")
                continue
            argv = [sys.executable, "-m", "robofabric", *b.argv(quick=quick)]
            table = Path(tmp) / f"{b.name}.md"
            if b.out in ("append", "write"):
                argv += ["--out", str(table)]
            elif b.out == "dir":
                argv += ["--out", str(out.parent / f"{out.stem}-{b.name}-logs")]
            progress(f"== {' '.join(shown)}")
            t0 = time.monotonic()
            code, text = _run_streaming(argv)
            seconds = time.monotonic() - t0
            body = table.read_text(encoding="utf-8") if table.exists() else text
            outcomes.append(BenchOutcome(b.name, shown, code, seconds))
            with open(out, "a", encoding="utf-8") as f:
                f.write(f"\n## `{' '.join(shown)}`\n\n{body.rstrip()}\n")
                if code != 0:
                    f.write(f"\nFAILED (exit {code}); its last output:\n\n```text\n{text[-3000:]}\n```\n")
                f.write(f"\n({seconds:.0f} s)\n")
    return outcomes


def all_cmd(
    quick: Annotated[
        bool,
        typer.Option("--quick", help="Smoke-sized runs (seconds to a minute each) instead of the documented ones."),
    ] = False,
    only: Annotated[str, typer.Option("--only", help="Comma-separated names to run (default: all).")] = "",
    skip: Annotated[str, typer.Option("--skip", help="Comma-separated names not to run.")] = "",
    out: Annotated[Path, typer.Option("--out", help="The markdown file that collects the tables (replaced).")] = Path(
        "out/bench/all.md"
    ),
) -> None:
    """Run every registered benchmark with the arguments of docs/benchmarks.md, one process each, side by side on
    this machine, and collect the tables in one markdown file. Exit 1 if any failed; ones this machine cannot run
    (the lab without root) are skipped with the reason."""
    selected = _select(only, skip)
    outcomes = run_all(selected, quick=quick, out=out)
    print(f"\nwrote {out}")
    for o in outcomes:
        state = (
            f"skipped ({o.reason})"
            if o.returncode is None
            else ("ok" if o.returncode == 0 else f"FAILED (exit {o.returncode})")
        )
        print(f"  {o.name:<10} {state:<40} {o.seconds:6.0f} s")
    if any(o.returncode not in (0, None) for o in outcomes):
        raise typer.Exit(1)

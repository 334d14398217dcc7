"""Every command's ``--help`` reads as plain text: no reStructuredText markup from docstrings
(no backquotes around ``ros2 topic hz``), and paragraphs wrapped by the terminal, not by the source."""

from __future__ import annotations

import subprocess

import pytest
import typer

from robofabric import cli
from robofabric.terminal import plain_doc
from robofabric.testing import robofabric_cmd


def _paths() -> list[tuple[str, ...]]:
    cli.load_plugins()
    root = typer.main.get_command(cli.app)
    out: list[tuple[str, ...]] = []

    def walk(cmd, path: tuple[str, ...]) -> None:
        out.append(path)
        for name, sub in getattr(cmd, "commands", {}).items():
            walk(sub, (*path, name))

    walk(root, ())
    return out


def test_plain_doc_drops_markup_and_joins_a_paragraphs_lines():
    doc = """Rate of the keys (like ``ros2 topic hz``).

    Uses :class:`~fabric.session.Fabric` and :func:`fabric.keys.parse`, a line
    wrapped in the source.

    - one
    - two
    """
    assert (
        plain_doc(doc)
        == "Rate of the keys (like ros2 topic hz).\n\nUses Fabric and fabric.keys.parse, a line wrapped in the source.\n\n- one\n- two"
    )


def test_running_the_cli_again_in_one_process_adds_no_command_again(capsys):
    """:func:`cli.main` loads the plug-ins at each run; each run once added every command again, and a help
    took longer at each."""
    assert cli.main(["--help"]) == 0
    before = (len(cli.app.registered_commands), len(cli.app.registered_groups))
    for _ in range(3):
        assert cli.main(["hz", "--help"]) == 0
    capsys.readouterr()
    assert (len(cli.app.registered_commands), len(cli.app.registered_groups)) == before


@pytest.mark.slow  # a second: 40 helps rendered
def test_no_help_shows_markup_or_source_line_breaks(capsys, monkeypatch):
    """Every command's help, rendered in this process: a process per command cost 40 starts of the CLI (this test
    and the next, 10.9 s of CPU then, 2.4 s now); the next reads one from a real process, as a user's terminal does."""
    paths = _paths()
    assert ("own", "request") in paths and ("hz",) in paths, paths
    monkeypatch.setenv("COLUMNS", "80")
    for path in paths:
        assert cli.main([*path, "--help"]) == 0, (path, capsys.readouterr().err)
        out = capsys.readouterr().out
        assert "``" not in out and ":class:" not in out and ":func:" not in out, (path, out)
        assert max(len(line) for line in out.splitlines()) <= 80, (path, out)


@pytest.mark.slow  # a process
def test_a_commands_help_from_its_own_process_reflows_at_the_terminals_width():
    import os

    env = {**os.environ, "COLUMNS": "80"}
    out = subprocess.run(
        robofabric_cmd("own", "request", "--help"), capture_output=True, text=True, timeout=60, env=env
    )
    assert out.returncode == 0, out.stderr
    text = out.stdout
    assert max(len(line) for line in text.splitlines()) <= 80, text
    # the paragraph reflows at 80 columns: its source line breaks (after "so" and "renews") are gone
    assert "Without --hold this command exits at once, so the lease" in " ".join(text.split())
    assert not any(line.rstrip().endswith("so") for line in text.splitlines()), text


def _option_line(text: str, option: str) -> str:
    (line,) = [ln for ln in text.splitlines() if f" {option} " in ln and ln.lstrip("│ *").startswith(option)]
    return line


@pytest.mark.parametrize(
    ("path", "flags", "valued"),
    [
        ((), {"--verbose": "<int>", "--version": "<bool>", "--help": "<bool>"}, {}),
        (("echo",), {"--json": "<bool>", "--help": "<bool>"}, {"--count": "<int>", "--world": "<str>"}),
        (("own", "list"), {"--json": "<bool>", "--help": "<bool>"}, {"--world": "<str>"}),  # a command of a sub-group
    ],
)
def test_help_shows_no_type_after_a_flag_or_counter_and_the_type_of_every_valued_option(
    path, flags, valued, capsys, monkeypatch
):
    """``--json <bool>`` would read as if it took a value; ``--count <int>`` does take one."""
    monkeypatch.setenv("COLUMNS", "120")
    assert cli.main([*path, "--help"]) == 0
    text = capsys.readouterr().out
    for option, type_text in flags.items():
        assert type_text not in _option_line(text, option), (option, text)
    for option, type_text in valued.items():
        assert type_text in _option_line(text, option), (option, text)

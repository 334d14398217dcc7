"""The joining flags every world-joining command shares (fabric.cli_common.join_flags): one definition, the
same flags and help in every command, handed to the command as one Joining."""

from __future__ import annotations

from typing import Annotated

import pytest
import typer
from typer.testing import CliRunner

from fabric.cli_common import CLIENT_FLAGS, JOIN_FLAGS, Joining, UserError, join_flags


def _app(command) -> typer.Typer:
    app = typer.Typer()
    app.command()(command)
    app.command("other")(lambda: None)  # two commands: typer keeps the command's name on the line
    return app


def test_the_flags_stand_at_the_join_parameter_and_come_back_as_one_joining():
    """Typer sees the six flags where ``join`` stood (between the command's own options, so --help keeps that
    order), and the command gets what was given as one Joining."""
    got: list[tuple[str, Joining, bool]] = []

    @join_flags()
    def cmd(
        key: Annotated[str, typer.Argument()],
        join: Joining = Joining(),
        loud: Annotated[bool, typer.Option("--loud")] = False,
    ) -> None:
        got.append((key, join, loud))

    result = CliRunner().invoke(
        _app(cmd),
        [
            "cmd",
            "robot/arm1/joints",
            "-w",
            "lab",
            "-e",
            "tcp/10.0.0.5:7447",
            "-e",
            "tcp/10.0.0.6:7447",
            "--id",
            "tool-1",
            "--profile",
            "peer",
            "--loud",
        ],
    )
    assert result.exit_code == 0, result.output
    assert got == [
        (
            "robot/arm1/joints",
            Joining("lab", ["tcp/10.0.0.5:7447", "tcp/10.0.0.6:7447"], None, "peer", None, "tool-1"),
            True,
        )
    ]
    help_text = CliRunner().invoke(_app(cmd), ["cmd", "--help"], env={"COLUMNS": "200"}).output
    order = [
        help_text.index(flag)
        for flag in ("--world", "--connect", "--listen", "--profile", "--zenoh-config", "--id", "--loud")
    ]
    assert order == sorted(order), help_text


def test_a_client_command_has_no_listener_or_id_of_its_own():
    """With ``client=True`` only --world, --connect, --profile and --zenoh-config exist; --id is a usage error."""
    got: list[Joining] = []

    @join_flags(client=True)
    def cmd(join: Joining = Joining()) -> None:
        got.append(join)

    app = _app(cmd)
    assert CliRunner().invoke(app, ["cmd", "--world", "w"]).exit_code == 0
    assert got == [Joining(world="w")]
    assert CliRunner().invoke(app, ["cmd", "--id", "x"]).exit_code == 2
    assert set(CLIENT_FLAGS) < set(JOIN_FLAGS)


def test_a_command_without_join_is_refused_when_decorated():
    """A command that has no ``join`` parameter for the flags to stand in for is a programming error, at import."""
    with pytest.raises(TypeError, match="no parameter 'join'"):
        join_flags()(lambda world=None: None)


def test_the_joining_resolves_to_a_config_and_a_bad_flag_is_a_user_error():
    """``config()`` is the flags' FabricConfig (a world given wins over --world); a bad profile is a UserError."""
    join = Joining(world="lab", connect=["tcp/127.0.0.1:7447"], profile="client")
    assert join.config().world == "lab" and join.config(world="other").world == "other"
    assert list(join.config().connect) == ["tcp/127.0.0.1:7447"]
    with pytest.raises(UserError):
        Joining(profile="nonsense").config()

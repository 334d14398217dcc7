"""Entry point of the fabric's own subcommands: router, ps, echo, hz, pub, call, list, interfaces, up, demo, secure, lab, robots."""

from __future__ import annotations

import typer


def register(app: typer.Typer) -> None:
    from robofabric import introspect_cli, launch_cli, robots_cli, secure_cli, tools
    from robofabric.lab import cli as lab_cli

    tools.register(app)
    introspect_cli.register(app)
    launch_cli.register(app)
    secure_cli.register(app)
    lab_cli.register(app)
    robots_cli.register(app)

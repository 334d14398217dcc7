"""Entry point of the fabric's own subcommands: router, ps, echo, hz, pub, call, up, demo, bench transport."""

from __future__ import annotations

import typer


def register(app: typer.Typer) -> None:
    from fabric import bench_transport, launch_cli, tools_cli

    tools_cli.register(app)
    launch_cli.register(app)
    bench_transport.register()

"""The fabric's own subcommands: router, ps, echo, hz, up, demo (and the transport bench)."""

from __future__ import annotations

import typer


def register(app: typer.Typer) -> None:
    from fabric import tools_cli  # noqa: F401  (kept apart so import of this module stays cheap)

    tools_cli.register(app)

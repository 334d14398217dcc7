"""The fabric's own commands, one module each: router, ps, echo, hz, pub, call.

Introspection in the spirit of ``ros2 node/topic/service``; they stand on the ground floor
(:mod:`fabric`) and are registered with the rest of the tools by :func:`robofabric.commands.register`.
A command's module is imported only when the CLI starts (``robofabric --help`` must not load numpy).
"""

from __future__ import annotations

import typer

__all__ = ["register"]


def register(app: typer.Typer) -> None:
    """Add router, ps, echo, hz, pub and call to the root app."""
    from robofabric.tools import call, echo, hz, ps, pub, router

    app.command("router")(router.router)
    app.command("ps")(ps.ps)
    app.command("echo")(echo.echo)
    app.command("hz")(hz.hz)
    app.command("pub")(pub.pub)
    app.command("call")(call.call)

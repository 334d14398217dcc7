"""``robofabric router``: a zenoh router for the fabric, optionally counting what access control refuses."""

from __future__ import annotations

from dataclasses import replace
from typing import Annotated

import typer

from fabric.cli_common import Connect, Listen, PeerId, UserError, World, ZenohConfig, make_config


def router(
    listen: Listen = None,
    connect: Connect = None,
    world: World = None,
    zenoh_config: ZenohConfig = None,
    peer_id: PeerId = None,
    audit: Annotated[
        bool,
        typer.Option(
            "--audit",
            help="Count what access control refuses (by login, message and key) and print a summary per interval; costs CPU with traffic.",
        ),
    ] = False,
    audit_every: Annotated[float, typer.Option(help="Seconds between --audit summaries.")] = 10.0,
) -> None:
    """Run a zenoh router for the fabric (any standard zenohd works in its place)."""
    from fabric.session import Fabric, shutdown_event

    cfg = make_config(world, connect, listen, "embedded", zenoh_config)
    if not listen and not cfg.file_value("listen/endpoints"):
        cfg = replace(cfg, listen=("tcp/0.0.0.0:7447",))
    if audit and audit_every <= 0:
        raise UserError("--audit-every must be positive")
    stop = shutdown_event()
    auditor = None
    if audit:
        from robofabric.router_audit import Audit

        auditor = Audit(every=audit_every)
    try:
        fab = Fabric(cfg, kind="router", peer_id=peer_id)
    except Exception as exc:
        raise UserError(f"cannot start router on {', '.join(cfg.endpoints()[1])}: {exc}") from None
    with fab:
        print(
            f"router {fab.peer_id} listening on {', '.join(cfg.endpoints()[1])} (world {cfg.world}); Ctrl-C to stop",
            flush=True,
        )
        while not stop.wait(0.5):
            pass
    if auditor is not None:
        auditor.close()
    print("router stopped", flush=True)

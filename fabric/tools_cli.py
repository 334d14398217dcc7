"""Implementations of the fabric's introspection and process commands."""

from __future__ import annotations

import sys
import time

import typer

from fabric import keys
from fabric.cli_common import Connect, Listen, PeerId, Profile, UserError, World, ZenohConfig, make_config
from fabric.session import Fabric, shutdown_event


def router(
    listen: Listen = None,
    connect: Connect = None,
    world: World = None,
    zenoh_config: ZenohConfig = None,
    peer_id: PeerId = None,
) -> None:
    """Run a zenoh router for the fabric (any standard zenohd works in its place)."""
    cfg = make_config(world, connect, listen or ["tcp/0.0.0.0:7447"], "embedded", zenoh_config)
    stop = shutdown_event()
    try:
        fab = Fabric(cfg, kind="router", peer_id=peer_id)
    except Exception as exc:
        raise UserError(f"cannot start router on {', '.join(cfg.endpoints()[1])}: {exc}") from None
    with fab:
        print(f"router {fab.peer_id} listening on {', '.join(cfg.endpoints()[1])} (world {cfg.world}); Ctrl-C to stop", flush=True)
        while not stop.wait(0.5):
            pass
    print("router stopped", flush=True)


def register(app: typer.Typer) -> None:
    app.command("router")(router)

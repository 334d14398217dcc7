"""Fixtures of the user API's live tests: one router and one real sim peer shared by a test module."""

from __future__ import annotations

import uuid
from typing import Iterator

import pytest

from fabric.session import Fabric
from robofabric.testing import ProcessGroup, free_port, robofabric_cmd, router_config, wait_until


@pytest.fixture(scope="module")
def live(tmp_path_factory) -> Iterator[tuple[str, int, ProcessGroup]]:
    """One router (this process) and one sim peer (scene combined); yields (world, port, procs).

    The sim is ended, and the router closed, when the module's tests are done; a test may start more
    processes in ``procs`` (they end with it)."""
    world = f"t{uuid.uuid4().hex[:8]}"
    port = free_port()
    router = Fabric(router_config(world, port), kind="router", peer_id="router")
    procs = ProcessGroup(tmp_path_factory.mktemp("live"))
    sim = procs.start(
        robofabric_cmd("sim", "--scene", "combined", "--world", world, "--connect", f"tcp/127.0.0.1:{port}"), name="sim"
    )
    try:
        wait_until(
            lambda: router.live_peers("sim"), timeout=60, what="sim peer", seen=lambda: procs.output(sim)[-2000:]
        )
        yield world, port, procs
    finally:
        procs.close()
        router.close()

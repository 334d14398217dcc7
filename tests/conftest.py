"""Fixtures shared by every test package: a real router on a unique loopback port, clients, processes."""

from __future__ import annotations

import uuid
from typing import Iterator

import pytest

from fabric.session import Fabric
from robofabric.testing import ProcessGroup, client, free_port, router_config


@pytest.fixture
def world() -> str:
    """A world name unique to the test, so concurrent tests never hear each other."""
    return f"t{uuid.uuid4().hex[:8]}"


@pytest.fixture
def router(world: str) -> Iterator[tuple[Fabric, int]]:
    """An in-process router (embedded profile) on a fresh port; yields (fabric, port)."""
    port = free_port()
    fab = Fabric(router_config(world, port), kind="router", peer_id="router")
    try:
        yield fab, port
    finally:
        fab.close()


@pytest.fixture
def connect(world: str, router: tuple[Fabric, int]):
    """Factory of client peers connected to the test's router; all closed at the end."""
    made: list[Fabric] = []

    def make(kind: str = "tool", peer_id: str | None = None) -> Fabric:
        fab = client(world, router[1], kind=kind, peer_id=peer_id)
        made.append(fab)
        return fab

    yield make
    for fab in made:
        fab.close()


@pytest.fixture
def procs(tmp_path) -> Iterator[ProcessGroup]:
    """Child processes of the test, logged under tmp_path and ended by pid at teardown."""
    group = ProcessGroup(tmp_path)
    try:
        yield group
    finally:
        group.close()


@pytest.fixture(scope="session")
def lab_ok() -> None:
    """The multi-host tests (tests/lab, the soak's) need network namespaces: skipped with the reason only where
    they cannot be made, and never on CI (``CI`` set), where that is a failure."""
    import os

    from robofabric.lab import namespaces_available, sweep_stale

    ok, why = namespaces_available()
    if not ok:
        if os.environ.get("CI"):
            pytest.fail(f"multi-host tests cannot run on CI (CI={os.environ['CI']!r}): {why}", pytrace=False)
        print(f"multi-host tests skipped: {why}")
        pytest.skip(why)
    sweep_stale()  # namespaces of earlier runs that were killed before they could clean up

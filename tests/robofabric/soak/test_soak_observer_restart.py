"""The soak's observer misses no owner change across its router's restart.

Two routers (real ``robofabric router`` processes): the sim and the users on A, the observer on B, which connects to
A. B is killed: the observer hears nothing while arm1 changes hands four times (alice, released, bob, released);
B is started again on its port and the observer's link comes back. It must then have every record of arm1
(consecutive epochs, each change's) and every ownership event of those changes, caught up from the authority's
kept samples (fabric.keys.cache_size, fabric.history), so that the checker judges them all (not judged: 0)."""

from __future__ import annotations

import signal
import time

import pytest

from ownership import OwnershipClient
from robofabric.soak import history
from robofabric.soak.checker import check, not_judged
from robofabric.soak.history import Fault, OwnEvent, OwnRec
from robofabric.soak.observer import Observer
from robofabric.testing import client, free_port, robofabric_cmd, wait_until

pytestmark = pytest.mark.slow


def _router(procs, world: str, port: int, *, connect: int | None = None, name: str):
    argv = ["router", "--world", world, "--listen", f"tcp/127.0.0.1:{port}"]
    if connect is not None:
        argv += ["--connect", f"tcp/127.0.0.1:{connect}"]
    proc = procs.start(robofabric_cmd(*argv), name=name)
    wait_until(
        lambda: "listening" in procs.output(proc) or proc.poll() is not None,
        timeout=60,
        what=f"{name} listening",
        seen=lambda: procs.output(proc)[-800:],
    )
    return proc


def test_an_observer_across_its_routers_restart_misses_no_owner_change(world, procs, tmp_path):
    pa, pb = free_port(), free_port()
    _router(procs, world, pa, name="router-a")
    rb = _router(procs, world, pb, connect=pa, name="router-b")
    sim = procs.start(
        robofabric_cmd(
            "sim", "--scene", "arm_cell", "--world", world, "--connect", f"tcp/127.0.0.1:{pa}", "--id", "sim-a"
        ),
        name="sim",
    )
    path = tmp_path / "history.jsonl"
    obs = Observer(world, f"tcp/127.0.0.1:{pb}", path)
    fa, fb = client(world, pa, kind="user", peer_id="alice-s"), client(world, pa, kind="user", peer_id="bob-s")
    alice = OwnershipClient(fa, "alice", timeout=5.0).start()
    bob = OwnershipClient(fb, "bob", timeout=5.0).start()
    try:
        wait_until(
            lambda: alice.record("arm1") is not None and "arm1" in obs._records,
            timeout=90,
            what="arm1's record at alice and at the observer",
            seen=lambda: procs.output(sim)[-800:],
        )
        epoch0 = alice.record("arm1").epoch
        procs.kill(rb, signal.SIGKILL)
        wait_until(lambda: not obs.fab.connected(), timeout=30, what="the observer cut off")
        cut_at = time.monotonic()
        assert alice.request("arm1", timeout=10).granted
        assert alice.release("arm1", timeout=10).outcome == "released"
        assert bob.request("arm1", timeout=10).granted
        out = bob.release("arm1", timeout=10)
        assert out.outcome == "released"
        last = out.epoch
        assert last >= epoch0 + 3, (epoch0, last)
        assert not obs.fab.connected(), "the observer heard the changes live: the test shows nothing"
        back_at = time.monotonic()
        rb = _router(procs, world, pb, connect=pa, name="router-b2")

        def recs() -> list[OwnRec]:
            return [r for r in history.read([path])[0] if isinstance(r, OwnRec) and r.obj == "arm1"]

        wait_until(
            lambda: any(r.epoch == last for r in recs()),
            timeout=60,
            what="the observer catching up on arm1",
            seen=lambda: [(r.epoch, r.owner) for r in recs()],
        )
        wait_until(
            lambda: sum(isinstance(r, OwnEvent) and r.obj == "arm1" for r in history.read([path])[0]) >= 2,
            timeout=30,
            what="the two releases' events",
            seen=lambda: [(r.kind, r.t) for r in history.read([path])[0] if isinstance(r, OwnEvent)],
        )
    finally:
        alice.close()
        bob.close()
        obs.close()
    h, _ = history.read([path])
    epochs = sorted({r.epoch for r in h if isinstance(r, OwnRec) and r.obj == "arm1" and r.epoch >= epoch0})
    assert epochs == list(range(epoch0, last + 1)), epochs  # every record of every change, none missed
    owners = [r.owner for r in sorted((r for r in h if isinstance(r, OwnRec) and r.obj == "arm1"), key=lambda r: r.t)]
    assert "alice" in owners and "bob" in owners, owners
    kinds = [r.kind for r in h if isinstance(r, OwnEvent) and r.obj == "arm1"]
    assert kinds.count("own_released") >= 2, kinds
    # the checker, told of the restart, judges every change and finds nothing wrong
    judged = sorted([*h, Fault(cut_at, "router", "router-b", back_at)], key=lambda r: r.t)
    assert not_judged(judged) == 0
    assert [v for v in check(judged) if v.invariant in ("handover", "queue", "owners")] == []

"""``robofabric bench ownership``: handover latency among N users, recovery after the owner is SIGKILLed or frozen.

Everything runs over real Zenoh on loopback: an embedded router, the Authority, and N user
sessions in this process (each a full Fabric session with its liveliness token); the
killed owner is a child process (``python -m robofabric.bench.ownership WORLD PORT USER``:
requests the arm and holds it until killed). Times are wall clock of the observing user's replica.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
import uuid
from typing import Annotated

import typer

from fabric.session import Fabric
from robofabric.testing import client, free_port, router_config, wait_until
from ownership.authority import Authority
from ownership.client import OwnershipClient
from robofabric.bench.common import TableOut, append, pct

HOLDER = [sys.executable, "-m", "robofabric.bench.ownership"]
"""The owner that is killed: a child process that requests the arm and holds it (argv WORLD PORT USER)."""


def _pct(xs: list[float], q: float) -> float:
    return pct(xs, q, 1e3)


GRACE_S = 30.0
"""The authority's grace. It also bounds a frozen owner's recovery when the authority was itself starved past half a
lease: it then doubts every token that goes for a grace (it cannot tell her leaving from its own deafness) and holds
her until her token is back or the grace is out (ownership/hearing.py). With 0.3 s leases on a loaded box that
happens (the suite's run at load 30 waited 10.3 s and failed)."""


def run_one(n: int, *, lease_s: float, kills: int, grace_s: float = GRACE_S) -> dict:
    world = f"bench{uuid.uuid4().hex[:6]}"
    port = free_port()
    router = Fabric(router_config(world, port), kind="router", peer_id="router")
    host = client(world, port, kind="sim", peer_id="host")
    auth = Authority(host, {"arm": "exclusive"}, lease_s=lease_s, grace_s=grace_s).start()
    fabs = [client(world, port, kind="user", peer_id=f"u{i:03d}") for i in range(n)]
    users = [OwnershipClient(f, f.peer_id, renew_s=lease_s / 4).start() for f in fabs]
    try:
        auth.update_motion("arm", True)  # moving: requests queue instead of taking over
        users[0].request("arm")
        for u in users[1:]:
            u.request("arm", wait=True)
        by_user = {u.user: u for u in users}
        handovers = []
        holder = users[0]
        for _ in users[1:]:
            # the next owner is the queue's head, and the queue is in join order (ownership.state._sorted_queue): the
            # order the authority heard the users' tokens, not the order they were made. At load 4 (2026-12-04) it
            # heard u002 before u001, u002 took over, and a bench that waited for u001 timed out with "moving"
            nxt = by_user[auth.records()["arm"].queue[0]]
            t0 = time.perf_counter()
            holder.release("arm")
            wait_until(
                lambda: nxt.owns("arm"),
                timeout=15,
                interval=0.0005,
                what="handover",
                seen=lambda: (holder.record("arm"), nxt.record("arm"), auth.export_state()),
            )
            handovers.append(time.perf_counter() - t0)
            holder = nxt
        recoveries = []
        last = holder
        last.release("arm")
        for k in range(kills):
            owner_id = f"k{k}"
            proc = subprocess.Popen(
                [*HOLDER, world, str(port), owner_id],
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )
            wait_until(lambda: last.record("arm").owner == owner_id, timeout=30, what="killable owner")
            last.request("arm", wait=True)
            t0 = time.perf_counter()
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait(timeout=10)
            wait_until(lambda: last.owns("arm"), timeout=lease_s + 10, interval=0.0005, what="recovery")
            recoveries.append(time.perf_counter() - t0)
            last.release("arm")
        frozen = []
        for k in range(kills):  # SIGSTOP: the token stays (connection open), so only the lease can end it
            owner_id = f"f{k}"
            proc = subprocess.Popen(
                [*HOLDER, world, str(port), owner_id],
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )
            wait_until(lambda: last.record("arm").owner == owner_id, timeout=30, what="freezable owner")
            last.request("arm", wait=True)
            t0 = time.perf_counter()
            os.kill(proc.pid, signal.SIGSTOP)
            try:
                wait_until(
                    lambda: last.owns("arm"),
                    timeout=lease_s + grace_s + 10,  # a starved authority holds her for a grace (GRACE_S)
                    interval=0.0005,
                    what="lease recovery",
                    seen=lambda: last.record("arm"),
                )
                frozen.append(time.perf_counter() - t0)
            finally:  # a bench that fails leaves no stopped owner behind (two were found so)
                os.kill(proc.pid, signal.SIGKILL)
                proc.wait(timeout=10)
            last.release("arm")
        return {
            "n": n,
            "frozen_p50": _pct(frozen, 50),
            "frozen_max": _pct(frozen, 100),
            "handover_p50": _pct(handovers, 50),
            "handover_p99": _pct(handovers, 99),
            "recovery_p50": _pct(recoveries, 50),
            "recovery_max": _pct(recoveries, 100),
            "handovers": len(handovers),
        }
    finally:
        for u in users:
            u.close()
        auth.close()
        for f in fabs:
            f.close()
        host.close()
        router.close()


def header(lease_s: float) -> list[str]:
    """The markdown table's head (the lease is part of a column's name)."""
    return [
        f"| users | handovers | handover p50 (ms) | handover p99 (ms) | recovery after SIGKILL p50 / max (ms) | recovery after SIGSTOP (lease {lease_s * 1e3:.0f} ms) p50 / max (ms) |",
        "|---|---|---|---|---|---|",
    ]


def format_row(r: dict) -> str:
    """One row of the table from :func:`run_one`'s result."""
    return (
        f"| {r['n']} | {r['handovers']} | {r['handover_p50']:.1f} | {r['handover_p99']:.1f} | "
        f"{r['recovery_p50']:.1f} / {r['recovery_max']:.1f} | {r['frozen_p50']:.1f} / {r['frozen_max']:.1f} |"
    )


def run_bench(counts: list[int], *, lease_s: float, kills: int) -> list[dict]:
    """Run each user count in turn, printing the table a row at a time (a 100-user run takes a while)."""
    rows = []
    print("\n".join(header(lease_s)))
    for n in counts:
        r = run_one(n, lease_s=lease_s, kills=kills)
        rows.append(r)
        print(format_row(r), flush=True)
    return rows


def command(
    users: Annotated[str, typer.Option("--users", help="Comma-separated user counts.")] = "10,50,100",
    lease: Annotated[float, typer.Option("--lease", help="Lease (s).")] = 0.5,
    kills: Annotated[int, typer.Option("--kills", help="Owner kills per user count.")] = 3,
    out: TableOut = None,
) -> None:
    """N users in one world hand the arm over in turn; then the owner is SIGKILLed."""
    from fabric.cli_common import UserError

    try:
        counts = [int(x) for x in users.split(",") if x.strip()]
    except ValueError:
        raise UserError(f"--users {users!r}: expected counts like 10,50,100") from None
    if not counts or min(counts) < 2 or lease <= 0 or kills < 0:
        raise UserError("--users: each count at least 2 (a handover needs two); --lease positive; --kills >= 0")
    rows = run_bench(counts, lease_s=lease, kills=kills)
    append(out, "\n".join([*header(lease), *map(format_row, rows)]))


def _hold(world: str, port: int, user: str) -> None:
    """The killable owner: request the arm, say so, hold it (renewing) until this process is killed."""
    with client(world, port, kind="user", peer_id=user) as fab:
        own = OwnershipClient(fab, user, renew_s=0.1).start()
        print(own.request("arm"), flush=True)
        threading.Event().wait()


if __name__ == "__main__":
    _hold(sys.argv[1], int(sys.argv[2]), sys.argv[3])

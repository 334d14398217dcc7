"""``robofabric bench declflood``: a login declaring thousands of subscribers, then closing.

    robofabric bench declflood [--counts 6000,20000] [--out FILE.md]

A class world made with ``robofabric secure init`` (its router config, limits included): a router and a
sim process under their logins; alice owns arm1 and bob owns base1 (user API, this process); mallory, in a
process of her own under her login, declares N subscribers on distinct keys (``rf/W/robot/xI/joints``:
her login may subscribe to anything) and closes her session. Measured per N:

* declare: seconds her N declarations took;
* stall: the longest gap between answers to bob's ``srv/world`` queries (every 50 ms, 1 s timeout, through
  the router to the sim) from her first declaration to 10 s after the first answer that follows her close
  (at most :data:`RESUME_TIMEOUT_S`): how long the router could not route;
* router RSS before her session, after her declarations, and 5 s after her close;
* owners: whether alice and bob still own their robots afterwards, how many times either lost one
  (the user API's ``on_lost``), and how many records of their robots named another owner or epoch
  (a release then a restore is two, though each has her robot back by the end). zenoh 1.x has no limit on declarations per session: this is what a
  flood of them costs, bounded only by the router's session limit and the authority's lease rule.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import threading
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import typer

from robofabric.testing import ProcessGroup, free_port, robofabric_cmd, wait_until
from robofabric.bench.common import TableOut, append, machine, proc_rss_mb

RESUME_TIMEOUT_S = 120.0
"""How long after her close the bench waits for the router to answer again."""

_MALLORY = r"""
import sys, time, zenoh
from fabric.config import FabricConfig
cfg, world, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
s = zenoh.open(FabricConfig(world=world, config_file=cfg).zenoh_config())
t0 = time.monotonic()
# no Python callback: zenoh-python runs each on a thread of its own, and 6,000 threads of hers loaded the whole box
# (load 200-1,000, her close once hung for minutes): the router's cost is the declarations, not her threads
subs = [s.declare_subscriber(f"rf/{world}/robot/x{i}/joints") for i in range(n)]
print(f"declared {n} {time.monotonic() - t0:.3f}", flush=True)
sys.stdin.readline()  # the bench says when to close
t0 = time.monotonic()
s.close()
print(f"closed {time.monotonic() - t0:.3f}", flush=True)
"""


@dataclass(frozen=True, slots=True)
class FloodResult:
    """One flood of ``n`` declarations: times in seconds, memory in MB."""

    n: int
    declare_s: float
    close_s: float
    stall_s: float
    unanswered: int
    rss_before_mb: float
    rss_declared_mb: float
    rss_after_mb: float
    alice_owns: bool
    bob_owns: bool
    losses: int
    changes: int = 0
    """Records of arm1 and base1 that named another owner or epoch than before the flood (a release, a
    restore, a handover): what an owner sees even when she has her robot back by the end."""
    changed: tuple[str, ...] = ()
    """Those records, as "robot: owner@epoch -> owner@epoch" (the first few): which change it was."""


class _Prober:
    """Bob's ``srv/world`` queries every ``period`` s: the longest gap between answers, and the misses."""

    def __init__(self, fab, period: float = 0.05) -> None:
        from fabric import keys

        self.fab, self.key, self.period = fab, keys.srv(fab.world, "world"), period
        self.answers: list[float] = []
        self.misses = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        from fabric.interfaces import ServiceError

        while not self._stop.is_set():
            try:
                self.fab.rpc.call(self.key, timeout=1.0)
                self.answers.append(time.monotonic())
            except ServiceError:
                self.misses += 1
            self._stop.wait(self.period)

    def __enter__(self) -> "_Prober":
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(timeout=5)

    def first_answer_after(self, t: float, *, timeout: float) -> float | None:
        """When the first answer after ``t`` came, waiting up to ``timeout`` s for one (None: none came)."""
        deadline = time.monotonic() + timeout
        while True:
            later = [a for a in self.answers if a > t]
            if later:
                return later[0]
            if time.monotonic() > deadline:
                return None
            time.sleep(self.period)

    def longest_gap(self, since: float, until: float) -> float:
        """The longest time without an answer in [since, until] (the edges count as answers)."""
        times = [since, *[t for t in self.answers if since < t < until], until]
        return max(b - a for a, b in zip(times, times[1:]))


def _watch_records(fab, held: dict[str, tuple[str, int]], changes: list[str]):
    """Every ownership record of a robot in ``held`` that names another (owner, epoch) is appended to ``changes``."""
    from fabric import keys
    from fabric.interfaces import OwnershipRecord

    def on(key: str, rec: OwnershipRecord) -> None:
        was = held.get(rec.object)
        if was is not None and (rec.owner, rec.epoch) != was:
            changes.append(f"{rec.object}: {was[0]}@{was[1]} -> {rec.owner or 'free'}@{rec.epoch}")

    return fab.subscribe(keys.own_all(fab.world), on, expected=OwnershipRecord)


def run_flood(counts: list[int], tmp: Path, *, settle: float = 5.0) -> list[FloodResult]:
    """Start the class world under ``tmp``, flood it once per count (a fresh mallory each time), end it all."""
    import user_peer
    from robofabric.secure import init

    world = f"flood{uuid.uuid4().hex[:6]}"
    ep = f"tcp/127.0.0.1:{free_port()}"
    made = init(tmp / "class", users=["alice", "bob", "mallory"], listen=[ep])
    files = made.clients
    results = []
    with ProcessGroup(tmp) as procs:
        router = procs.start(robofabric_cmd("router", "--zenoh-config", str(made.router)), name="router")
        wait_until(
            lambda: "listening" in procs.output(router), timeout=30, what="router", seen=lambda: procs.output(router)
        )
        sim = procs.start(
            robofabric_cmd("sim", "--scene", "combined", "--world", world, "--zenoh-config", str(files["sim"])),
            name="sim",
        )
        alice = user_peer.connect(world=world, zenoh_config=str(files["alice"]), timeout=10.0, join_timeout=90.0)
        bob = user_peer.connect(world=world, zenoh_config=str(files["bob"]), timeout=10.0)
        losses: list[str] = []
        alice.ownership.on_lost(lambda obj, rec: losses.append(obj))
        bob.ownership.on_lost(lambda obj, rec: losses.append(obj))
        held: dict[str, tuple[str, int]] = {}  # robot -> (owner, epoch) before the flood
        changes: list[str] = []
        try:
            arm, base = alice.robot("arm1"), bob.robot("base1")
            arm.request(timeout=10)
            base.request(timeout=10)
            watch = _watch_records(bob.fabric, held, changes)
            for n in counts:
                lost_before, changed_before = len(losses), len(changes)
                held.update({r.id: (r.record.owner, r.record.epoch) for r in (arm, base)})
                rss0 = proc_rss_mb(router.pid)
                mallory = subprocess.Popen(
                    [sys.executable, "-c", _MALLORY, str(files["mallory"]), world, str(n)],
                    stdin=subprocess.PIPE,
                    stdout=subprocess.PIPE,
                    text=True,
                    start_new_session=True,
                )
                try:
                    with _Prober(bob.fabric) as probe:
                        t0 = time.monotonic()
                        declared = mallory.stdout.readline().split()
                        rss1 = proc_rss_mb(router.pid)
                        mallory.stdin.write("\n")
                        mallory.stdin.flush()
                        closed = mallory.stdout.readline().split()
                        t_close = time.monotonic()
                        # the stall may outlast any fixed window (10 s cut it short): until answers resume, then
                        # 10 s more for what the resumed router does to the owners
                        resumed = probe.first_answer_after(t_close, timeout=RESUME_TIMEOUT_S)
                        time.sleep(max(0.0, (resumed or time.monotonic()) + 10.0 - time.monotonic()))
                        stall = probe.longest_gap(t0, time.monotonic())
                        misses = probe.misses
                    mallory.wait(timeout=30)
                finally:
                    if mallory.poll() is None:
                        mallory.kill()
                        mallory.wait(timeout=10)
                time.sleep(settle)
                rss2 = proc_rss_mb(router.pid)
                results.append(
                    FloodResult(
                        n,
                        float(declared[2]) if len(declared) == 3 else float("nan"),
                        float(closed[1]) if len(closed) == 2 else float("nan"),
                        stall,
                        misses,
                        rss0,
                        rss1,
                        rss2,
                        arm.record is not None and arm.record.owner == "alice",
                        base.record is not None and base.record.owner == "bob",
                        len(losses) - lost_before,
                        len(changes) - changed_before,
                        tuple(changes[changed_before : changed_before + 8]),
                    )
                )
            watch.undeclare()
        finally:
            alice.close()
            bob.close()
            procs.kill(sim, sig=15)
    return results


def table(results: list[FloodResult]) -> str:
    head = (
        "| declarations | declare s | close s | longest srv/world gap s | queries unanswered | router RSS before / declared / "
        "after MB | alice owns | bob owns | ownership losses | records changed |\n|---|---|---|---|---|---|---|---|---|---|"
    )
    rows = [
        f"| {r.n} | {r.declare_s:.2f} | {r.close_s:.2f} | {r.stall_s:.2f} | {r.unanswered} | {r.rss_before_mb:.0f} / "
        f"{r.rss_declared_mb:.0f} / {r.rss_after_mb:.0f} | {'yes' if r.alice_owns else 'NO'} | {'yes' if r.bob_owns else 'NO'} | "
        f"{r.losses} | {r.changes} |"
        for r in results
    ]
    return "\n".join([head, *rows])


def command(
    counts: Annotated[
        str, typer.Option(help="Declarations per flood, comma-separated (one fresh mallory each).")
    ] = "6000,20000",
    out: TableOut = None,
) -> None:
    """A login declaring N subscribers and closing: router stall, router memory, whether owners keep their robots."""
    ns = [int(c) for c in counts.split(",") if c.strip()]
    with tempfile.TemporaryDirectory() as tmp:
        results = run_flood(ns, Path(tmp))
    text = f"robofabric bench declflood --counts {counts}; {machine()}\n\n{table(results)}"
    print(text)
    append(out, text)

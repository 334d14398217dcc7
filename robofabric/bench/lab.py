"""``robofabric bench lab``: recovery times measured in the lab, over repeated runs (median and max).

Three figures, each from real processes in separate network namespaces (router, sim, two users):

* **handover after a partition**: alice owns the moving arm, bob is queued; alice's cable is pulled;
  time until bob's queued request returns granted (bob's clock; the budget is lease + 0.5 s);
* **reconnect after router loss**: the router is SIGKILLed and started again; time from the new router
  listening until alice receives joints again, and until she owns the arm again (where the authority
  restored her within grace; where her lease ran out first the arm is free, and that is counted);
* **recovery from a lost sim**: the sim is SIGKILLed; time until alice is told the world is gone; a new
  sim is started; time from its start until the world serves again and alice's next move is done.

Times are on the machine's monotonic clock, which every namespace shares.
"""

from __future__ import annotations

import json
import statistics
import time
from pathlib import Path
from typing import Annotated, Any

import typer

from robofabric.lab.lab import Lab, LabProcess
from robofabric.bench.common import TableOut, append

__all__ = ["run_lab_bench", "to_markdown", "command"]

JOIN = """
import time, numpy as np, user_peer
w = user_peer.connect(world="demo", connect=["{router}"], user="{user}", timeout=5.0, join_timeout=120)
arm = w.robot("arm1"); arm.wait_for("joints", timeout=30)
gone = []
w.on_world(lambda alive, why: gone.append((time.monotonic(), alive)))
"""


def _wait(pred, timeout: float, what: str) -> Any:
    deadline = time.monotonic() + timeout
    while True:
        v = pred()
        if v:
            return v
        if time.monotonic() > deadline:
            raise TimeoutError(f"lab bench: {what} did not happen within {timeout:.0f} s")
        time.sleep(0.05)


class _Bench:
    def __init__(self, lab: Lab) -> None:
        self.lab = lab
        self.rh, self.sh = lab.add_host("router"), lab.add_host("sim")
        self.ep = self.rh.endpoint()
        self.router = self.start_router()
        self.sim = self.start_sim()
        self.alice = lab.add_host("alice").python(name="alice")
        self.bob = lab.add_host("bob").python(name="bob")
        for name, py in (("alice", self.alice), ("bob", self.bob)):
            py.call(JOIN.format(router=self.ep, user=name), timeout=240)

    def start_router(self) -> LabProcess:
        p = self.rh.start(["router", "--listen", self.ep], name="router")
        _wait(lambda: "listening" in p.output(), 120, "router listening")
        return p

    def start_sim(self) -> LabProcess:
        return self.sh.start(["sim", "--scene", "arm_cell", "--connect", self.ep], name="sim")

    def partition(self) -> float:
        a, b = self.alice, self.bob
        held = a.call("e = arm.request(); arm.move_joints(np.full(6, 0.8), wait=False, speed_scale=0.05); e")
        _wait(
            lambda: b.call("r = arm.record; r is not None and r.state == 'moving' and r.owner == 'alice'"),
            20,
            "arm moving",
        )
        granted = b.submit("arm.request(wait=True, timeout=60); time.monotonic()")
        _wait(lambda: b.call("'bob' in tuple(arm.record.queue)"), 20, "bob queued")
        t_cut = time.monotonic()
        self.lab.cut("alice")
        handover = granted(timeout=60) - t_cut
        self.lab.restore("alice")
        b.call("arm.move_joints(np.zeros(6), timeout=30); arm.release(); None", timeout=60)
        # alice's view catches up with what happened while she was cut off: a newer epoch than hers, whether the
        # arm is free (bob released it before her token came back) or hers again (she came back while bob held
        # it: queued first, as an ex-owner within grace, she owns it after his release)
        _wait(
            lambda: a.call(f"arm.record.epoch > {held}"),
            30,
            "alice's view of the arm catching up (a newer epoch than hers)",
        )
        a.call("w.wait_world(timeout=60); None", timeout=90)
        return handover

    def router_loss(self) -> tuple[float, float]:
        a = self.alice
        epoch = a.call("arm.request()")
        self.router.kill()
        self.router = self.start_router()
        t_back = time.monotonic()
        _wait(
            lambda: a.call("x = arm.age('joints'); x is not None and x < 0.2"), 60, "joints after the router's restart"
        )
        joints = time.monotonic() - t_back
        # the authority's word on the arm after the restart: alice's under the same epoch (the authority kept
        # her while its own link was down), or a newer record (passed on, restored or freed)
        _wait(
            lambda: a.call(
                f"r = w.ownership.fetch('arm1', timeout=2.0)\nr is not None and (r.owner == 'alice' or r.epoch > {epoch})"
            ),
            60,
            "the authority's record of the arm at alice",
        )
        owned = time.monotonic() - t_back
        restored = bool(a.call("arm.is_owner"))
        a.call("arm.release() if arm.is_owner else None; None")
        return joints, (owned if restored else None)

    def sim_loss(self) -> tuple[float, float, float]:
        a = self.alice
        a.call("gone.clear(); None")
        t_kill = time.monotonic()
        self.sim.kill()
        told = (
            _wait(lambda: a.call("[t for t, alive in gone if not alive][:1]"), 30, "alice told the world is gone")[0]
            - t_kill
        )
        self.sim = self.start_sim()
        t_start = time.monotonic()
        a.call("assert w.wait_world(timeout=120); None", timeout=150)
        serving = time.monotonic() - t_start
        a.call("arm.request(timeout=10); arm.move_joints(np.full(6, 0.1), timeout=30); arm.release(); None", timeout=90)
        moved = time.monotonic() - t_start
        return told, serving, moved


def run_stats(xs: list[float]) -> dict[str, float]:
    """Count, median, max and min of one figure over the runs (seconds)."""
    return {"n": len(xs), "median_s": statistics.median(xs), "max_s": max(xs), "min_s": min(xs)}


def run_lab_bench(runs: int = 5, *, log_dir: str | Path | None = None, progress=print) -> dict[str, Any]:
    """Build one lab, repeat each fault ``runs`` times, return {figure: {n, median_s, max_s, min_s}}."""
    raw: dict[str, list[float]] = {
        k: []
        for k in (
            "partition_handover",
            "router_joints_back",
            "router_owner_back",
            "sim_gone_told",
            "sim_world_serving",
            "sim_first_move_done",
        )
    }
    restored: list[bool] = []
    with Lab(log_dir=log_dir) as lab:
        bench = _Bench(lab)
        for i in range(runs):
            raw["partition_handover"].append(bench.partition())
            j, o = bench.router_loss()
            raw["router_joints_back"].append(j)
            if o is not None:
                raw["router_owner_back"].append(o)
            restored.append(o is not None)
            t, s, m = bench.sim_loss()
            raw["sim_gone_told"].append(t)
            raw["sim_world_serving"].append(s)
            raw["sim_first_move_done"].append(m)
            progress(
                f"run {i + 1}/{runs}: "
                + ", ".join(f"{k} {v[-1]:.2f} s" for k, v in raw.items() if v)
                + f", owner restored: {restored[-1]}"
            )
    return {
        "runs": runs,
        "figures": {k: run_stats(v) for k, v in raw.items() if v},
        "raw": raw,
        "router_owner_restored": f"{sum(restored)}/{len(restored)}",
    }


def to_markdown(result: dict[str, Any]) -> str:
    labels = {
        "partition_handover": "handover after the owner's link drops (bob queued → granted)",
        "router_joints_back": "router SIGKILLed and restarted: joints at a user again, after the router listens",
        "router_owner_back": "… the owner holds the arm again (kept under her epoch, or restored within grace)",
        "sim_gone_told": "sim SIGKILLed: the user is told the world is gone",
        "sim_world_serving": "new sim started: the world serves again (from the sim's start)",
        "sim_first_move_done": "… the user's next request + move done (from the sim's start)",
    }
    lines = [f"| figure ({result['runs']} runs) | median | max |", "|---|---|---|"]
    for k, s in result["figures"].items():
        lines.append(f"| {labels[k]} | {s['median_s']:.2f} s | {s['max_s']:.2f} s |")
    lines.append(
        f"\nAfter the router's restart the owner was restored in {result['router_owner_restored']} runs "
        "(otherwise the lease had expired first and the arm was free)."
    )
    return "\n".join(lines)


def command(
    runs: Annotated[int, typer.Option(help="Repetitions of each fault.")] = 5,
    as_json: Annotated[bool, typer.Option("--json")] = False,
    out: TableOut = None,
) -> None:
    """Recovery times in a lab of network namespaces (needs root): partition handover, router loss, lost sim."""
    from fabric.cli_common import UserError
    from robofabric.lab import namespaces_available

    ok, why = namespaces_available()
    if not ok:
        raise UserError(why)
    if runs < 1:
        raise UserError("--runs must be at least 1")
    result = run_lab_bench(runs)
    if as_json:
        print(json.dumps(result))
    else:
        print(to_markdown(result))
    append(out, to_markdown(result))

"""IK query round trip through a router: the budget of docs/design.md of p99 <= 2 ms on loopback.

Three processes as on a LAN, squeezed onto one host: this one hosts the router
and asks, ``robofabric compute --arm ...`` answers. Targets are FK of random
in-limit joints, so every query has an answer and the time is transport plus
solve, not refusal. FK queries run beside IK as the floor (same path, no solve).
"""

from __future__ import annotations

import subprocess
import sys
import time
import uuid

import numpy as np

from robofabric.bench.common import pct

__all__ = ["measure_query"]


def _percentiles(samples: list[float]) -> dict[str, float]:
    return {"p50_ms": pct(samples, 50, 1e3), "p99_ms": pct(samples, 99, 1e3), "max_ms": pct(samples, 100, 1e3)}


def measure_query(n: int = 1000, seed: int = 0, warmup: int = 50) -> dict[str, dict[str, float]]:
    """Median and p99 (ms) of IK (full pose and position only) and FK queries to a compute peer process."""
    from robofabric.bench.ik import reachable_targets
    from compute_peer.kinematics.model import ArmModel
    from fabric.interfaces import FKRequest, IKRequest
    from fabric import keys
    from fabric.session import Fabric
    from robofabric.testing import client, free_port, robofabric_cmd, router_config, wait_until

    world = f"bench{uuid.uuid4().hex[:6]}"
    port = free_port()
    rng = np.random.default_rng(seed)
    targets = reachable_targets(ArmModel("meca500"), n + warmup, rng)
    argv = robofabric_cmd(
        "compute", "--no-navigation", "--arm", "arm1:meca500", "--world", world, "--connect", f"tcp/127.0.0.1:{port}"
    )
    with Fabric(router_config(world, port), kind="router", peer_id="router") as router:
        proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
        try:
            wait_until(lambda: router.live_peers("compute"), timeout=60, what="compute peer")
            with client(world, port, kind="tool", peer_id="bench") as fab:
                ik_key, fk_key = keys.srv(world, "ik", "arm1"), keys.srv(world, "fk", "arm1")
                wait_until(lambda: _answers(fab, fk_key), timeout=30, what="compute peer answering")
                out: dict[str, list[float]] = {"ik_pose": [], "ik_position": [], "fk": []}
                for i, (q, p, quat) in enumerate(targets):
                    seed_q = q + rng.normal(0.0, 0.05, 6)
                    for name, key, req in (
                        ("ik_pose", ik_key, IKRequest.make(p, quat, seed_q, frame="base")),
                        ("ik_position", ik_key, IKRequest.make(p, None, seed_q, frame="base")),
                        ("fk", fk_key, FKRequest(q, frame="base")),
                    ):
                        t0 = time.perf_counter()
                        fab.rpc.call(key, req, timeout=5.0)
                        if i >= warmup:
                            out[name].append(time.perf_counter() - t0)
        finally:
            proc.terminate()
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
    return {name: _percentiles(v) for name, v in out.items()}


def _answers(fab, key: str) -> bool:
    from fabric.interfaces import FKRequest
    from fabric.interfaces import ServiceError

    try:
        fab.rpc.call(key, FKRequest(np.zeros(6)), timeout=1.0)
        return True
    except ServiceError:
        return False


if __name__ == "__main__":  # python -m robofabric.bench.ik_query [N]
    res = measure_query(int(sys.argv[1]) if len(sys.argv) > 1 else 1000)
    for name, r in res.items():
        print(f"{name:<12} p50 {r['p50_ms']:.3f} ms  p99 {r['p99_ms']:.3f} ms  max {r['max_ms']:.3f} ms")

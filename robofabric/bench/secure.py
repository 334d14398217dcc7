"""``robofabric bench secure``: what security costs: plain TCP, TCP + access control, TLS + access control, side by side.

    robofabric bench secure [--rounds 2] [--duration 5] [--queries 500] [--flood-seconds 5] [--out FILE.md]

For each mode a fresh router (``robofabric router``, with ``robofabric secure init``'s
``router.json5`` for the secure modes) and, on it:

* transport: 240-ray scans at 1 kHz from a publisher logged in as the sim to a subscriber logged in
  as the viewer, each in its own process (robofabric.bench.transport's children): delivered %, latency
  p50 / p99 (header wall time to receive, one host clock);
* IK round trip: a compute peer process (``robofabric compute --arm arm1:meca500``, logged in as the
  compute identity) answers ``srv/ik/arm1`` queries from a user (alice) for FK-reachable targets.

Modes alternate within each round so a noisy machine hurts them alike; the table holds medians
over rounds of each mode's percentiles. Then the flood row (:mod:`robofabric.bench.secure_flood`): an owner
driving, quiet and while one login floods requests and ``srv/state`` at her client's fastest
(``--flood-seconds 0`` leaves it out).
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from robofabric.testing import free_port, robofabric_cmd, wait_until
from robofabric.bench.common import TableOut, append, end_process

MODES = ("tcp", "tcp+acl", "tls+acl")


def _start(argv: list[str]) -> subprocess.Popen:
    return subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True)


def _mode_setup(mode: str, tmp: Path) -> tuple[str, list[str], dict[str, str | None]]:
    """(endpoint, router argv, identity -> client config) for one mode."""
    from robofabric.secure import init

    proto = "tls" if mode == "tls+acl" else "tcp"
    ep = f"{proto}/127.0.0.1:{free_port()}"
    if mode == "tcp":
        return (
            ep,
            robofabric_cmd("router", "--listen", ep, "--world", "bench"),
            {n: None for n in ("sim", "viewer", "compute", "alice")},
        )
    out = init(tmp / mode.replace("+", "-"), users=["alice"], tls=mode == "tls+acl", listen=[ep])
    return (
        ep,
        robofabric_cmd("router", "--zenoh-config", str(out.router), "--world", "bench"),
        {n: str(p) for n, p in out.clients.items()},
    )


def _ik_round_trips(ep: str, configs: dict[str, str | None], n: int, warmup: int = 30) -> list[float]:
    from compute_peer.kinematics.model import ArmModel
    from fabric.interfaces import IKRequest
    from fabric import keys
    from fabric.config import FabricConfig
    from fabric.interfaces import ServiceError
    from fabric.session import Fabric
    from robofabric.bench.ik import reachable_targets

    world = f"b{uuid.uuid4().hex[:6]}"
    argv = robofabric_cmd("compute", "--no-navigation", "--arm", "arm1:meca500", "--world", world, "--connect", ep)
    if configs["compute"]:
        argv += ["--zenoh-config", configs["compute"]]
    proc = _start(argv)
    try:
        cfg = FabricConfig(world=world, connect=(ep,), config_file=configs["alice"])
        with Fabric(cfg, kind="user", peer_id="alice") as fab:
            key = keys.srv(world, "ik", "arm1")
            rng = np.random.default_rng(0)
            targets = reachable_targets(ArmModel("meca500"), n + warmup, rng)

            def answers() -> bool:
                q, p, quat = targets[0]
                try:
                    fab.rpc.call(key, IKRequest.make(p, quat, q, frame="base"), timeout=1.0)
                    return True
                except ServiceError:
                    return False

            wait_until(answers, timeout=90, what="compute peer answering IK")
            out = []
            for i, (q, p, quat) in enumerate(targets):
                req = IKRequest.make(p, quat, q + rng.normal(0.0, 0.05, 6), frame="base")
                t0 = time.perf_counter()
                fab.rpc.call(key, req, timeout=5.0)
                if i >= warmup:
                    out.append((time.perf_counter() - t0) * 1e3)
            return out
    finally:
        end_process(proc)


def run(rounds: int, duration: float, queries: int) -> dict[str, list[dict]]:
    """``rounds`` rounds of every mode in turn; per mode, one row per round (delivered %, scan and IK percentiles)."""
    from robofabric.bench.transport import run_one

    results: dict[str, list[dict]] = {m: [] for m in MODES}
    with tempfile.TemporaryDirectory() as tmpdir:
        tmp = Path(tmpdir)
        for r in range(rounds):
            for mode in MODES:
                ep, router_argv, configs = _mode_setup(mode, tmp / f"r{r}")
                router = _start(router_argv)
                try:
                    assert router.stdout is not None
                    line = router.stdout.readline()
                    if "listening" not in line:
                        raise RuntimeError(f"router for {mode} did not start: {line.strip()}")
                    scans = run_one(
                        "zenoh", ep, 1000.0, duration, pub_config=configs["sim"], sub_config=configs["viewer"]
                    )
                    ik = _ik_round_trips(ep, configs, queries)
                finally:
                    end_process(router)
                row = {
                    "delivered_pct": scans["delivered_pct"],
                    "scan_p50": scans["p50"],
                    "scan_p99": scans["p99"],
                    "ik_p50": float(np.median(ik)),
                    "ik_p99": float(np.percentile(ik, 99)),
                }
                results[mode].append(row)
                print(
                    f"round {r + 1} {mode}: {json.dumps({k: round(v, 3) for k, v in row.items()})}",
                    file=sys.stderr,
                    flush=True,
                )
    return results


def table(results: dict[str, list[dict]]) -> str:
    def med(mode: str, k: str) -> float:
        return statistics.median(row[k] for row in results[mode])

    base = {k: med("tcp", k) for k in ("scan_p50", "scan_p99", "ik_p50", "ik_p99")}
    lines = [
        "| mode | scans delivered % (1 kHz) | scan p50 (ms) | scan p99 (ms) | IK round trip p50 (ms) | IK p99 (ms) | IK p50 vs tcp |",
        "|---|---|---|---|---|---|---|",
    ]
    for m in MODES:
        lines.append(
            f"| {m} | {min(r['delivered_pct'] for r in results[m]):.2f} | {med(m, 'scan_p50'):.3f} | {med(m, 'scan_p99'):.3f} | "
            f"{med(m, 'ik_p50'):.3f} | {med(m, 'ik_p99'):.3f} | {med(m, 'ik_p50') / base['ik_p50']:.2f}x |"
        )
    return "\n".join(lines)


def command(
    rounds: Annotated[int, typer.Option(help="Rounds; each runs every mode once, in turn.")] = 2,
    duration: Annotated[float, typer.Option(help="Seconds of 1 kHz scans per mode and round.")] = 5.0,
    queries: Annotated[int, typer.Option(help="IK queries per mode and round.")] = 500,
    flood_seconds: Annotated[
        float,
        typer.Option(
            help="Seconds of each phase of the flood row (quiet, then one login "
            "flooding requests and srv/state while an owner drives); 0: no flood row."
        ),
    ] = 5.0,
    out: TableOut = None,
) -> None:
    """Scans at 1 kHz and IK round trips over plain TCP, TCP + access control and TLS + access control; an owner's
    commands and lease beside one login's flood."""
    from fabric.cli_common import UserError

    if rounds < 1 or duration <= 0 or queries < 1 or flood_seconds < 0:
        raise UserError("--rounds and --queries must be at least 1, --duration positive, --flood-seconds at least 0")
    t = table(run(rounds, duration, queries))
    if flood_seconds > 0:
        from robofabric.bench import secure_flood

        t += "\n\n" + secure_flood.table(secure_flood.run(flood_seconds), flood_seconds)
    print(t)
    append(out, t)

"""``robofabric bench secure``'s flood row: one login's flood beside an owner who drives, with and without it.

A class world from ``robofabric secure init`` (alice, bob, mallory; TCP + access control), a router and a sim
as processes. alice owns arm1 and sends a coded joint target every 50 ms (:class:`robofabric.bench.flood`'s
owner: the latency is from her send to the sim's publish stamp of the first joint state showing it applied)
and renews arm1 herself every 100 ms on top of her client's renewals (each renewal's round trip timed); bob
asks ``srv/world`` every 50 ms. Two phases of ``seconds`` each: quiet, then mallory flooding from two
processes of her own (:mod:`robofabric.bench.login_flood`: ownership requests on ``own/arm1/by/mallory``
and ``srv/state`` queries, as fast as her client sends). Each phase's row: what mallory sent and how much
was refused as ``rate_limited``, alice's command latency and renewal round trip, her lease lapses (a record
of arm1 naming someone else), bob's ``srv/world`` latency and the queries he got no answer to.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from pathlib import Path
from typing import Any

from fabric import keys
from fabric.budget import RATE_LIMITED
from fabric.config import FabricConfig
from fabric.interfaces import OwnReply, OwnRequest, ServiceError, WorldInfo
from fabric.session import Fabric
from robofabric.bench.common import end_process, pct
from robofabric.bench.flood import JOINT, FloodResult, _Owner
from robofabric.testing import free_port, robofabric_cmd, wait_until

__all__ = ["run", "table"]


class _Timed:
    """``ask()`` every ``period`` s on a thread: round trips in s, and how many got no answer."""

    def __init__(self, ask, period: float) -> None:
        self.times: list[float] = []
        self.missed = 0
        self._ask, self._period = ask, period
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            t0 = time.perf_counter()
            try:
                self._ask()
                self.times.append(time.perf_counter() - t0)
            except ServiceError:
                self.missed += 1
            self._stop.wait(self._period)

    def take(self) -> tuple[list[float], int]:
        """What was measured since the last take."""
        out, missed = self.times, self.missed
        self.times, self.missed = [], 0
        return out, missed

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(10.0)


def _flooders(world: str, config: Path, seconds: float) -> list[subprocess.Popen]:
    base = [sys.executable, "-m", "robofabric.bench.login_flood", world, str(config), "mallory"]
    return [
        subprocess.Popen(base + what + [str(seconds)], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        for what in (["request", "arm1"], ["state"])
    ]


def _phase(
    owner: _Owner, renewals: _Timed, bob: _Timed, world: str, config: Path, seconds: float, flood: bool
) -> dict[str, Any]:
    since = time.monotonic()
    renewals.take(), bob.take()
    sent: dict[str, Any] = {}
    if flood:
        procs = _flooders(world, config, seconds)
        for name, proc in zip(("requests", "state"), procs):
            out, _ = proc.communicate(timeout=seconds + 60)
            sent[name] = json.loads(out.strip().splitlines()[-1])
    else:
        time.sleep(seconds)
    time.sleep(1.5)  # the last commands' effects are published (score leaves out the last second's)
    result = FloodResult(flooded=flood)
    owner.score(result, since=since, t0=since)
    renew, renew_missed = renewals.take()
    world_times, world_missed = bob.take()
    return {
        "mallory_sent": sum(s["sent"] for s in sent.values()),
        "rate_limited": sum(s["answers"].get(RATE_LIMITED, 0) for s in sent.values()),
        "cmd_p50": result.pct(50) * 1e3,
        "cmd_p99": result.pct(99) * 1e3,
        "commands": result.commands,
        "not_seen": result.not_applied,
        "renew_p99": pct(renew, 99) * 1e3,
        "renew_missed": renew_missed,
        "lapses": len(owner.lapses),
        "lapse_texts": list(owner.lapses[:4]),
        "world_p50": pct(world_times, 50) * 1e3,
        "world_p99": pct(world_times, 99) * 1e3,
        "world_max": pct(world_times, 100) * 1e3,
        "world_missed": world_missed,
        "flooder": sent,
    }


def run(seconds: float) -> dict[str, dict[str, Any]]:
    """The quiet and the flood phase, ``seconds`` each, in one fresh class world."""
    from robofabric.secure import init

    with tempfile.TemporaryDirectory() as tmpdir:
        tmp = Path(tmpdir)
        world, ep = f"f{uuid.uuid4().hex[:6]}", f"tcp/127.0.0.1:{free_port()}"
        files = init(tmp / "class", users=["alice", "bob", "mallory"], listen=[ep]).clients
        procs = [
            subprocess.Popen(
                robofabric_cmd("router", "--zenoh-config", str(tmp / "class" / "router.json5")),
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
                start_new_session=True,
            )
        ]
        fabs: list[Fabric] = []
        try:

            def login(name: str) -> Fabric:
                fab = Fabric(FabricConfig(world=world, config_file=str(files[name])), kind="user", peer_id=name)
                fabs.append(fab)
                return fab

            alice = wait_until(
                lambda: _try(login, "alice"), timeout=60, interval=0.5, what="the router to accept alice"
            )
            sim_log = open(tmp / "sim.log", "wb")
            procs.append(
                subprocess.Popen(
                    robofabric_cmd("sim", "--scene", "combined", "--world", world, "--zenoh-config", str(files["sim"])),
                    stdout=sim_log,
                    stderr=subprocess.STDOUT,
                    start_new_session=True,
                )
            )
            sim_log.close()
            info = wait_until(lambda: _world(alice), timeout=90, interval=0.5, what="the sim's srv/world")
            arm = next(r for r in info.robots if r.id == "arm1")
            owner = _Owner(alice, world, float(arm.max_speed[JOINT]), len(arm.joint_names))
            owner.take()
            owner.start(0.05)
            bob = login("bob")
            renew_key = keys.own_request(world, "arm1", "alice")
            renewals = _Timed(
                lambda: alice.rpc.call(
                    renew_key,
                    OwnRequest("renew", "alice", header=alice.header("own-req")),
                    timeout=2.0,
                    expected=OwnReply,
                ),
                0.1,
            )
            asks = _Timed(lambda: bob.rpc.call(keys.srv(world, "world"), timeout=5.0, expected=WorldInfo), 0.05)
            time.sleep(2.0)  # warm
            rows = {
                "quiet": _phase(owner, renewals, asks, world, files["mallory"], seconds, False),
                "flood": _phase(owner, renewals, asks, world, files["mallory"], seconds, True),
            }
            renewals.stop(), asks.stop()
            owner.close()
            # why arm1 changed hands, if it did: the authority's own words (its take-overs and expiries are warnings)
            said = [
                line
                for line in (tmp / "sim.log").read_text(errors="replace").splitlines()
                if "own_" in line and "arm1" in line
            ]
            rows["flood"]["sim_said"] = said[:6]
            return rows
        finally:
            for fab in fabs:
                fab.close()
            for proc in reversed(procs):
                end_process(proc)


def _try(login, name: str) -> Fabric | None:
    try:
        return login(name)
    except Exception:  # the router is not listening yet
        return None


def _world(fab: Fabric) -> WorldInfo | None:
    try:
        return fab.rpc.call(keys.srv(fab.world, "world"), timeout=2.0, expected=WorldInfo)
    except ServiceError:
        return None


def table(rows: dict[str, dict[str, Any]], seconds: float) -> str:
    lines = [
        f"| {seconds:g} s, secure class world (tcp+acl) | mallory's asks (rate_limited) | alice's commands p50 / p99 (ms) | "
        "not seen | alice's renewal p99 (ms, unanswered) | lease lapses | bob's srv/world p50 / p99 / max (ms, unanswered) |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, r in rows.items():
        lines.append(
            f"| {'quiet' if name == 'quiet' else 'mallory floods requests + srv/state'} | {r['mallory_sent']} ({r['rate_limited']}) | "
            f"{r['cmd_p50']:.1f} / {r['cmd_p99']:.1f} | {r['not_seen']} of {r['commands']} | {r['renew_p99']:.1f} ({r['renew_missed']}) | "
            f"{r['lapses']} | {r['world_p50']:.1f} / {r['world_p99']:.1f} / {r['world_max']:.1f} ({r['world_missed']}) |"
        )
    return "\n".join(lines)

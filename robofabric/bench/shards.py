"""``robofabric bench shards``: one world of N mobile robots with LIDAR, served by 1, 2 or 4 sim processes.

Per sim count S, a fresh world: a router and S ``robofabric sim --scene warehouse --no-scene-robots`` processes,
each with N/S Reeman bases at the spots one sim would give all N (so shards never overlap) and enough mirror
slots for every other sim's robots (``--mirrors``). Then, over ``--seconds``:

* each sim's **real-time factor**, from the sim time in its robots' pose headers against this machine's clock;
* **CPU per robot**: each sim's CPU seconds per robot per second of sim time (ms);
* **mirror lag**: how old another sim's pose is when a sim receives it (each sim's own figure, from its
  mirror feed's summary line on leaving; a mirror is this plus up to one pose period behind);
* a user's **command-to-motion latency**: a twist sent to one robot of each sim, until a pose of it that
  arrived after the command shows it moving (the user API's clock only): transport both ways, the sim's
  command queue, and up to one pose period (50 Hz).

Figures are medians over the sims where several; one machine, so every process shares the CPU.
"""

from __future__ import annotations

import re
import statistics
import threading
import time
import uuid
from pathlib import Path
from typing import Annotated, Any, Optional

import typer

from robofabric.bench.common import append, end_process, machine, pct, proc_cpu_s

__all__ = ["command", "run_one", "spots"]

MOVING_MS = 1e-3
"""A pose showing the base faster than this (m/s) shows it moving: low enough that the base's acceleration limit
adds about a millisecond, not the figure."""

MIRROR_LINE = re.compile(r"mirrors: (\d+) shown.*?p50 ([\d.]+|nan) ms, p99 ([\d.]+|nan) ms over (\d+) poses")


def spots(n: int) -> list[str]:
    """``reeman:baseI@X,Y,YAW`` for N bases, at the free spots one sim would choose for all of them."""
    from sim_peer.world import SimWorld

    w = SimWorld("warehouse", [f"reeman:base{i}" for i in range(n)], scene_robots=False)
    out = []
    for i in range(n):
        x, y, _, yaw = w.placements[f"base{i}"].pose
        out.append(f"reeman:base{i}@{x:.3f},{y:.3f},{yaw * 57.29577951308232:.1f}")
    return out


class _Poses:
    """Every robot's pose arrivals: (sim time, local monotonic time) per sim, for real-time factors."""

    def __init__(self, fab: Any, world: str) -> None:
        from fabric import keys
        from fabric.interfaces import Pose

        self.by_sim: dict[str, list[tuple[float, float]]] = {}
        self._lock = threading.Lock()
        self.sub = fab.subscribe(keys.robot_stream_all(world, "pose"), self._on, expected=Pose)

    def _on(self, key: str, pose: Any) -> None:
        with self._lock:
            self.by_sim.setdefault(pose.header.source, []).append((pose.header.stamp, time.monotonic()))

    def rtf(self, since: float, until: float) -> dict[str, float]:
        out = {}
        with self._lock:
            for sim, xs in self.by_sim.items():
                w = [x for x in xs if since <= x[1] <= until]
                if len(w) > 10 and w[-1][1] > w[0][1]:
                    out[sim] = (w[-1][0] - w[0][0]) / (w[-1][1] - w[0][1])
        return out


def _command_to_motion(world: str, endpoint: str, robots: list[str], rounds: int) -> list[float]:
    """Seconds from a twist to the first pose (arrived after it) showing the base moving, ``rounds`` per robot."""
    import math

    from fabric import keys
    from user_peer.api import connect

    out: list[float] = []
    with connect(world, endpoint, user="bench", timeout=10.0, join_timeout=120.0) as w:
        for rid in robots:
            base = w.robot(rid)
            base.wait_for("pose", timeout=30.0)
            base.request(timeout=30.0)
            key = keys.robot_pose(w.name, rid)
            for k in range(rounds):
                mark = w.latest.mark()
                t0 = time.monotonic()
                base.twist(0.3 if k % 2 == 0 else -0.3, 0.0)
                moving = w.latest.wait_for(lambda: (p := w.latest.get_after(key, mark)) is not None
                                           and math.hypot(p.linear[0], p.linear[1]) > MOVING_MS, 10.0)
                if moving:
                    out.append(time.monotonic() - t0)
                base.stop(timeout=10.0)
            base.release()
    return out


def run_one(robots: int, sims: int, seconds: float, tmp: Path) -> dict[str, Any]:
    """``robots`` bases over ``sims`` sim processes on a fresh world; the row's figures."""
    from fabric.testing import ProcessGroup, client, free_port, robofabric_cmd, wait_until

    world = f"shards{uuid.uuid4().hex[:6]}"
    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    logs = tmp / f"s{sims}"
    logs.mkdir(parents=True, exist_ok=True)
    every = spots(robots)
    mine = [every[i::sims] for i in range(sims)]
    with ProcessGroup(logs) as procs:
        router = procs.start(robofabric_cmd("router", "--world", world, "--listen", ep), name="router")
        wait_until(lambda: "listening" in procs.output(router), timeout=60, what="the router", seen=lambda: procs.output(router))
        started = []
        for i, specs in enumerate(mine):
            args = [x for s in specs for x in ("--robot", s)]
            p = procs.start(robofabric_cmd("-v", "sim", "--scene", "warehouse", "--no-scene-robots", *args, "--mirrors",
                                           str(robots - len(specs)), "--world", world, "--connect", ep, "--id", f"sim-{i}"),
                            name=f"sim-{i}")
            started.append(p)
            wait_until(lambda: "Ctrl-C to stop" in procs.output(p), timeout=180, what=f"sim-{i}", seen=lambda: procs.output(p)[-1500:])
        with client(world, port, kind="tool", peer_id="probe") as fab:
            poses = _Poses(fab, world)
            wait_until(lambda: len(poses.by_sim) == sims, timeout=60, what="poses from every sim", seen=lambda: list(poses.by_sim))
            cpu0 = {p.pid: proc_cpu_s(p.pid) for p in started}
            t0 = time.monotonic()
            firsts = [specs[0].split(":")[1].split("@")[0] for specs in mine]
            latencies = _command_to_motion(world, ep, firsts, rounds=4)
            left = seconds - (time.monotonic() - t0)
            if left > 0:
                time.sleep(left)  # the world runs on for the rest of the window: the figures are of its steady state
            t1 = time.monotonic()
            cpu = {p.pid: (proc_cpu_s(p.pid) - cpu0[p.pid]) for p in started}
            rtf = poses.rtf(t0 + 1.0, t1)
        for p in started:
            end_process(p)
        end_process(router)
        mirror = [MIRROR_LINE.search(procs.output(p)) for p in started]
    rtfs = [rtf.get(f"sim-{i}", float("nan")) for i in range(sims)]
    cpu_per_robot_ms = [1e3 * cpu[p.pid] / (len(specs) * max(1e-9, (t1 - t0) * r))
                        for p, specs, r in zip(started, mine, rtfs) if r == r]
    lag50 = [float(m.group(2)) for m in mirror if m and m.group(2) != "nan"]
    lag99 = [float(m.group(3)) for m in mirror if m and m.group(3) != "nan"]
    return {
        "robots": robots, "sims": sims, "rtf": rtfs, "rtf_min": min(rtfs), "cpu_per_robot_ms": cpu_per_robot_ms,
        "sim_cores": [cpu[p.pid] / (t1 - t0) for p in started],
        "mirrored": [int(m.group(1)) if m else 0 for m in mirror],
        "mirror_p50": statistics.median(lag50) if lag50 else float("nan"),
        "mirror_p99": max(lag99) if lag99 else float("nan"),
        "cmd_p50": pct(latencies, 50, 1e3), "cmd_p99": pct(latencies, 99, 1e3), "cmd_n": len(latencies),
    }


def header() -> list[str]:
    return ["| sims | robots per sim | real-time factor per sim | sim CPU, cores per sim | CPU per robot per sim-second (ms) | "
            "robots mirrored per sim | mirror lag p50 / p99 (ms) | command to motion p50 / p99 (ms) |",
            "|---|---|---|---|---|---|---|---|"]


def row(r: dict[str, Any]) -> str:
    def nums(xs: list[float], f: str = ".2f") -> str:
        return " / ".join(format(x, f) for x in xs)

    cpr = statistics.median(r["cpu_per_robot_ms"]) if r["cpu_per_robot_ms"] else float("nan")
    lag = "-" if r["mirror_p50"] != r["mirror_p50"] else f"{r['mirror_p50']:.1f} / {r['mirror_p99']:.1f}"
    return (f"| {r['sims']} | {r['robots'] // r['sims']} | {nums(r['rtf'])} | {nums(r['sim_cores'])} | {cpr:.1f} | "
            f"{' / '.join(map(str, r['mirrored']))} | {lag} | "
            f"{r['cmd_p50']:.0f} / {r['cmd_p99']:.0f} ({r['cmd_n']}) |")


def command(
    robots: Annotated[int, typer.Option("--robots", help="Mobile robots with LIDAR in the world.")] = 32,
    sims: Annotated[str, typer.Option("--sims", help="Comma-separated sim process counts to compare.")] = "1,2,4",
    seconds: Annotated[float, typer.Option("--seconds", help="Measured window per sim count.")] = 20.0,
    out: Annotated[Optional[Path], typer.Option("--out", help="Append the markdown table to this file.")] = None,
) -> None:
    """One world of N mobile robots served by 1, 2 and 4 sim processes: each sim's real-time factor and CPU per
    robot, how late the mirrors of other sims' robots are, and a user's command-to-motion latency."""
    import tempfile

    counts = [int(x) for x in sims.split(",") if x.strip()]
    if any(c < 1 or robots % c for c in counts):
        raise typer.BadParameter(f"every sim count must divide --robots {robots}: {counts}")
    lines = [f"`robofabric bench shards --robots {robots} --sims {sims} --seconds {seconds:g}` on {machine()}", "", *header()]
    with tempfile.TemporaryDirectory(prefix="rf-shards-") as tmp:
        for c in counts:
            r = run_one(robots, c, seconds, Path(tmp))
            lines.append(row(r))
            print(lines[-1], flush=True)
    text = "\n".join(lines) + "\n"
    print(text)
    append(out, text)

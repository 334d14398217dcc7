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
from typing import Annotated, Any

import typer

from robofabric.bench.common import TableOut, append, end_process, machine, pct, proc_cpu_s

__all__ = ["command", "run_one", "run_lab", "spots"]

MOVING_MS = 1e-3
"""A pose showing the base faster than this (m/s) shows it moving: low enough that the base's acceleration limit
adds about a millisecond, not the figure."""

MIRROR_LINE = re.compile(r"mirrors: (\d+) shown.*?p50 ([\d.]+|nan) ms, p99 ([\d.]+|nan) ms over (\d+) poses")


def spots(n: int) -> list[str]:
    """``reeman:baseI@X,Y,YAW`` for N bases, at the free spots one sim would choose for all of them."""
    from sim_peer.physics.world import SimWorld

    w = SimWorld("warehouse", [f"reeman:base{i}" for i in range(n)], scene_robots=False)
    out = []
    for i in range(n):
        x, y, _, yaw = w.placements[f"base{i}"].pose
        out.append(f"reeman:base{i}@{x:.3f},{y:.3f},{yaw * 57.29577951308232:.1f}")
    return out


class Poses:
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


def command_to_motion(world: str, endpoint: str, robots: list[str], rounds: int) -> list[float]:
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
                moving = w.latest.wait_for(
                    lambda: (
                        (p := w.latest.get_after(key, mark)) is not None
                        and math.hypot(p.linear[0], p.linear[1]) > MOVING_MS
                    ),
                    10.0,
                )
                if moving:
                    out.append(time.monotonic() - t0)
                base.stop(timeout=10.0)
            base.release()
    return out


def _shares(robots: int, sims: int) -> list[list[str]]:
    """Each sim's ``--robot`` specs: the spots one sim would give all ``robots``, dealt out in turn."""
    every = spots(robots)
    return [every[i::sims] for i in range(sims)]


def _sim_args(specs: list[str], robots: int, world: str, ep: str, i: int) -> list[str]:
    args = [x for s in specs for x in ("--robot", s)]
    return [
        "-v",
        "sim",
        "--scene",
        "warehouse",
        "--no-scene-robots",
        *args,
        "--mirrors",
        str(robots - len(specs)),
        "--world",
        world,
        "--connect",
        ep,
        "--id",
        f"sim-{i}",
    ]


def _figures(
    robots: int,
    mine: list[list[str]],
    rtf: dict[str, float],
    cpu_s: list[float],
    window_s: float,
    outputs: list[str],
    latencies: list[float],
) -> dict[str, Any]:
    """The row: per sim its real-time factor, cores and CPU per robot, its mirror summary; the command latencies."""
    sims = len(mine)
    rtfs = [rtf.get(f"sim-{i}", float("nan")) for i in range(sims)]
    mirror = [MIRROR_LINE.search(out) for out in outputs]
    lag50 = [float(m.group(2)) for m in mirror if m and m.group(2) != "nan"]
    lag99 = [float(m.group(3)) for m in mirror if m and m.group(3) != "nan"]
    return {
        "robots": robots,
        "sims": sims,
        "rtf": rtfs,
        "rtf_min": min(rtfs),
        "cpu_per_robot_ms": [
            1e3 * c / (len(specs) * max(1e-9, window_s * r)) for c, specs, r in zip(cpu_s, mine, rtfs) if r == r
        ],
        "sim_cores": [c / window_s for c in cpu_s],
        "mirrored": [int(m.group(1)) if m else 0 for m in mirror],
        "mirror_p50": statistics.median(lag50) if lag50 else float("nan"),
        "mirror_p99": max(lag99) if lag99 else float("nan"),
        "cmd_p50": pct(latencies, 50, 1e3),
        "cmd_p99": pct(latencies, 99, 1e3),
        "cmd_n": len(latencies),
    }


def _firsts(mine: list[list[str]]) -> list[str]:
    """One robot of each sim: the one a user commands for the latency figure."""
    return [specs[0].split(":")[1].split("@")[0] for specs in mine]


def run_one(robots: int, sims: int, seconds: float, tmp: Path) -> dict[str, Any]:
    """``robots`` bases over ``sims`` sim processes on this machine, a fresh world; the row's figures."""
    from robofabric.testing import ProcessGroup, client, free_port, robofabric_cmd, wait_until

    world = f"shards{uuid.uuid4().hex[:6]}"
    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    logs = tmp / f"s{sims}"
    logs.mkdir(parents=True, exist_ok=True)
    mine = _shares(robots, sims)
    with ProcessGroup(logs) as procs:
        router = procs.start(robofabric_cmd("router", "--world", world, "--listen", ep), name="router")
        wait_until(
            lambda: "listening" in procs.output(router),
            timeout=60,
            what="the router",
            seen=lambda: procs.output(router),
        )
        started = []
        for i, specs in enumerate(mine):
            p = procs.start(robofabric_cmd(*_sim_args(specs, robots, world, ep, i)), name=f"sim-{i}")
            started.append(p)
            wait_until(
                lambda: "Ctrl-C to stop" in procs.output(p),
                timeout=180,
                what=f"sim-{i}",
                seen=lambda: procs.output(p)[-1500:],
            )
        with client(world, port, kind="tool", peer_id="probe") as fab:
            poses = Poses(fab, world)
            wait_until(
                lambda: len(poses.by_sim) == sims,
                timeout=60,
                what="poses from every sim",
                seen=lambda: list(poses.by_sim),
            )
            cpu0 = [proc_cpu_s(p.pid) for p in started]
            t0 = time.monotonic()
            latencies = command_to_motion(world, ep, _firsts(mine), rounds=4)
            left = seconds - (time.monotonic() - t0)
            if left > 0:
                time.sleep(left)  # the world runs on for the rest of the window: the figures are of its steady state
            t1 = time.monotonic()
            cpu = [proc_cpu_s(p.pid) - c0 for p, c0 in zip(started, cpu0)]
            rtf = poses.rtf(t0 + 1.0, t1)
        for p in started:
            end_process(p)
        end_process(router)
        outputs = [procs.output(p) for p in started]
    return _figures(robots, mine, rtf, cpu, t1 - t0, outputs, latencies)


def run_lab(robots: int, sims: int, seconds: float, log_dir: Path) -> dict[str, Any]:
    """The same over the lab's network namespaces: a router host, one host per sim, and a probe host whose
    Python process watches the poses and drives the robots (the lab's hosts share this machine's clock and CPU)."""
    from robofabric.lab.lab import Lab
    from robofabric.testing import wait_until

    world = f"shards{uuid.uuid4().hex[:6]}"
    mine = _shares(robots, sims)
    with Lab(log_dir=log_dir) as lab:
        rh = lab.add_host("router")
        ep = rh.endpoint()
        router = rh.start(["router", "--world", world, "--listen", ep], name="router")
        wait_until(
            lambda: "listening" in router.output(),
            timeout=120,
            what="the lab's router",
            seen=lambda: router.output()[-1500:],
        )
        started = []
        for i, specs in enumerate(mine):
            p = lab.add_host(f"sim{i}").start(_sim_args(specs, robots, world, ep, i), name=f"sim-{i}")
            started.append(p)
            wait_until(
                lambda: "Ctrl-C to stop" in p.output(), timeout=180, what=f"sim-{i}", seen=lambda: p.output()[-1500:]
            )
        py = lab.add_host("probe").python(name="probe")
        py.call(
            "from fabric.config import FabricConfig\nfrom fabric.session import Fabric\n"
            "from robofabric.bench.shards import Poses, command_to_motion\n"
            f"fab = Fabric(FabricConfig.resolve(world={world!r}, connect=[{ep!r}]), kind='tool', peer_id='probe')\n"
            f"poses = Poses(fab, {world!r}); None",
            timeout=120,
        )
        wait_until(
            lambda: py.call("len(poses.by_sim)") == sims, timeout=60, what="poses from every sim at the probe host"
        )
        cpu0 = [proc_cpu_s(p.pid) for p in started]
        t0 = time.monotonic()  # one machine: every namespace reads the same monotonic clock
        latencies = py.call(f"command_to_motion({world!r}, {ep!r}, {_firsts(mine)!r}, rounds=4)", timeout=300)
        left = seconds - (time.monotonic() - t0)
        if left > 0:
            time.sleep(left)
        t1 = time.monotonic()
        cpu = [proc_cpu_s(p.pid) - c0 for p, c0 in zip(started, cpu0)]
        rtf = py.call(f"poses.rtf({t0 + 1.0}, {t1})")
        py.call("fab.close(); None")
        for p in started:
            p.stop()  # a clean exit: each sim logs its mirrors' summary on leaving
        outputs = [p.output() for p in started]
        router.stop()
    return _figures(robots, mine, rtf, cpu, t1 - t0, outputs, latencies)


def header() -> list[str]:
    return [
        "| sims | robots per sim | real-time factor per sim | sim CPU, cores per sim | CPU per robot per sim-second (ms) | "
        "robots mirrored per sim | mirror lag p50 / p99 (ms) | command to motion p50 / p99 (ms) |",
        "|---|---|---|---|---|---|---|---|",
    ]


def row(r: dict[str, Any]) -> str:
    def nums(xs: list[float], f: str = ".2f") -> str:
        return " / ".join(format(x, f) for x in xs)

    cpr = statistics.median(r["cpu_per_robot_ms"]) if r["cpu_per_robot_ms"] else float("nan")
    lag = "-" if r["mirror_p50"] != r["mirror_p50"] else f"{r['mirror_p50']:.1f} / {r['mirror_p99']:.1f}"
    return (
        f"| {r['sims']} | {r['robots'] // r['sims']} | {nums(r['rtf'])} | {nums(r['sim_cores'])} | {cpr:.1f} | "
        f"{' / '.join(map(str, r['mirrored']))} | {lag} | "
        f"{r['cmd_p50']:.0f} / {r['cmd_p99']:.0f} ({r['cmd_n']}) |"
    )


def command(
    robots: Annotated[int, typer.Option("--robots", help="Mobile robots with LIDAR in the world.")] = 32,
    sims: Annotated[str, typer.Option("--sims", help="Comma-separated sim process counts to compare.")] = "1,2,4",
    seconds: Annotated[float, typer.Option("--seconds", help="Measured window per sim count.")] = 20.0,
    lab: Annotated[
        bool, typer.Option("--lab", help="Over the lab's network namespaces: one host per sim (root, Linux).")
    ] = False,
    out: TableOut = None,
) -> None:
    """One world of N mobile robots served by 1, 2 and 4 sim processes: each sim's real-time factor and CPU per
    robot, how late the mirrors of other sims' robots are, and a user's command-to-motion latency."""
    import tempfile

    counts = [int(x) for x in sims.split(",") if x.strip()]
    if any(c < 1 or robots % c for c in counts):
        raise typer.BadParameter(f"every sim count must divide --robots {robots}: {counts}")
    where = " --lab" if lab else ""
    lines = [
        f"`robofabric bench shards --robots {robots} --sims {sims} --seconds {seconds:g}{where}` on {machine()}",
        "",
        *header(),
    ]
    with tempfile.TemporaryDirectory(prefix="rf-shards-") as tmp:
        for c in counts:
            r = run_lab(robots, c, seconds, Path(tmp) / f"lab{c}") if lab else run_one(robots, c, seconds, Path(tmp))
            lines.append(row(r))
            print(lines[-1], flush=True)
    text = "\n".join(lines) + "\n"
    print(text)
    append(out, text)

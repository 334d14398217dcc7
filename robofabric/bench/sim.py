"""``robofabric bench sim``: real-time factor and ray-cast cost of the headless simulation.

Measured without any network: the world stepped as fast as it goes, LIDAR (and the
ultrasonic ring) read at a fixed rate of sim time, as the peer's scan stream would.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated, Optional

import numpy as np
import typer

from robofabric.bench.common import machine, write
from robots.kinds import facts


def rtf(world, seconds: float, scan_hz: float = 20.0) -> float:
    """Sim seconds per wall second over ``seconds`` of sim time, scanning every robot at ``scan_hz``."""
    from sim_peer.physics.robot_kinds import MobileRobot

    mobiles = [rid for rid, r in world.robots.items() if isinstance(r, MobileRobot) and r.lidar is not None]
    for rid in mobiles:  # keep them driving in 1 m circles so the scans see a changing world
        world.robot(rid).twist(0.3, 0.3)
    arms = [rid for rid, r in world.robots.items() if facts(r.kind).chain]
    poses = [np.array([0.8, 0.4, -0.6, 0.5, 0.6, 1.0]), np.array([-0.8, -0.2, 0.3, -0.5, -0.6, -1.0])]
    flips = dict.fromkeys(arms, 0)
    per_scan = max(1, int(round(1.0 / (scan_hz * world.dt))))
    total = int(round(seconds / world.dt))
    t0 = time.perf_counter()
    done = 0
    while done < total:
        n = min(per_scan, total - done)
        world.step(n)
        done += n
        for rid in arms:  # and the arms sweeping back and forth between two poses
            arm = world.robot(rid)
            if not arm.moving:
                flips[rid] += 1
                arm.joints(poses[flips[rid] % 2][: arm.ctrl.dof])
        for rid in mobiles:
            world.readings.scan(rid)
            if world.robot(rid).sonar is not None:
                world.readings.sonar(rid)
    return seconds / (time.perf_counter() - t0)


def scan_cost(world, robot_id: str, n: int = 2000) -> tuple[float, float]:
    """Median and p99 wall time (us) of one LIDAR scan."""
    world.sync()
    lidar = world.robot(robot_id).lidar
    samples = np.empty(n)
    for i in range(n):
        t = time.perf_counter()
        lidar.read(world.data)
        samples[i] = time.perf_counter() - t
    return float(np.median(samples) * 1e6), float(np.percentile(samples, 99) * 1e6)


def arm_mirror_cost(n: int = 2000) -> tuple[float, float]:
    """Median and p99 wall time (us) of one arm mirror update: the forward kinematics of another sim's Meca500 at
    new joint angles, and its seven link geoms placed in this sim's world (what each joint message costs)."""
    from sim_peer.physics.arm_mirror import arm_shape
    from sim_peer.physics.world import SimWorld

    other = SimWorld("warehouse", ["meca500:arm9@1,0,0,0"], scene_robots=False)
    shape = arm_shape(other.robot("arm9").describe())
    here = SimWorld("warehouse", ["reeman:base0@0,0"], scene_robots=False, mirrors=8)
    rng = np.random.default_rng(1)
    qs = rng.uniform(-1.0, 1.0, size=(n, 6))
    samples = np.empty(n)
    for i in range(n):
        t = time.perf_counter()
        here.mirror_shapes("arm9", shape.shapes, shape.poses(qs[i]), source="other")
        samples[i] = time.perf_counter() - t
    return float(np.median(samples) * 1e6), float(np.percentile(samples, 99) * 1e6)


def command(
    seconds: Annotated[float, typer.Option(help="Sim seconds per real-time-factor run.")] = 10.0,
    counts: Annotated[str, typer.Option(help="Mobile robot counts for the scaling runs.")] = "1,10,50",
    out: Annotated[Optional[Path], typer.Option(help="Write the markdown table to this file.")] = None,
) -> None:
    """Real-time factor of `combined` with LIDAR at 20 Hz, one 240-ray scan's cost, RTF with N mobile robots."""
    from sim_peer.physics.world import SimWorld

    rows = []
    w = SimWorld("combined", seed=1)
    r = rtf(w, seconds)
    label = "combined (Meca500 sweeping + Reeman driving), LIDAR 240 rays @ 20 Hz + ultrasonic, bumper on"
    if w.notes.collisions:
        label += f" ({len(w.notes.collisions)} bumper stops!)"
    rows.append((label, f"{r:.0f}x", ">= 50x", "ok" if r >= 50 else "MISSED"))
    med, p99 = scan_cost(w, "base1")
    rows.append(
        (
            "one 240-ray LIDAR scan (combined), median / p99",
            f"{med:.1f} / {p99:.1f} us",
            "<= 50 us",
            "ok" if med <= 50 else "MISSED",
        )
    )
    med, p99 = arm_mirror_cost()
    rows.append(
        (
            "one arm mirror update (another sim's Meca500: FK, 7 link geoms placed), median / p99",
            f"{med:.1f} / {p99:.1f} us",
            "",
            "",
        )
    )
    for n in [int(c) for c in counts.split(",") if c.strip()]:
        extra = [f"reeman:m{i}" for i in range(n)]
        wn = SimWorld(
            "warehouse", extra, scene_robots=False, seed=1, bumper=False
        )  # 0.8 m apart, 1 m circles: they cross
        secs = max(1.0, seconds / max(1, n / 5))
        r = rtf(wn, secs)
        rows.append((f"warehouse, {n} mobile robots, each LIDAR @ 20 Hz + ultrasonic, bumper off", f"{r:.1f}x", "", ""))
    lines = [
        f"Command: `robofabric bench sim --seconds {seconds:g} --counts {counts}`",
        f"Machine: {machine()}, MuJoCo {_mujoco()}",
        "",
        "| measurement | result | target | |",
        "|---|---|---|---|",
        *[f"| {a} | {b} | {c} | {d} |" for a, b, c, d in rows],
    ]
    text = "\n".join(lines)
    print(text)
    write(out, text)


def _mujoco() -> str:
    import mujoco

    return mujoco.__version__


__all__ = ["arm_mirror_cost", "command", "rtf", "scan_cost"]

"""``robofabric bench viewer``: what drawing one message costs the Rerun viewer, per message type.

In this process, no network: :class:`user_peer.rerun_log.WorldLogger` (the code behind ``robofabric view``
and ``export``) logs synthetic messages of the ``combined`` scene's robots to a Rerun recording that
streams into an ``.rrd`` file, with no thinning (``max_hz=0``), so every message is drawn. Per type, the
wall time of each ``WorldLogger.log`` call: a Meca500 JointState (plots, Pinocchio FK, link transforms,
skeleton), a mobile base's Pose, a 240-ray Scan (hits and rays in the world frame) and a 400 x 400
OccupancyGrid (an image). The messages change every call (joints sweep, the base drives, ranges vary), so
nothing is served from a cache that a live stream would miss.
"""

from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path
from typing import Annotated, Any, Callable, Optional

import numpy as np
import typer

from robofabric.bench.common import append

__all__ = ["measure", "format_table", "command"]

WORLD = "benchview"


def _messages(n: int, grids: int, seed: int) -> dict[str, list[tuple[str, Any]]]:
    """``n`` messages per stream type (``grids`` grids), as (key, message), built before any timing."""
    import robots
    from fabric import keys
    from fabric.interfaces import Header, JointState, OccupancyGrid, Pose, Scan

    rng = np.random.default_rng(seed)
    arm = robots.load("meca500")
    lo, hi = np.asarray(arm.lower), np.asarray(arm.upper)
    out: dict[str, list[tuple[str, Any]]] = {"JointState": [], "Pose": [], "Scan": [], "OccupancyGrid": []}
    for i in range(n):
        h = Header(stamp=i * 0.01, wall_ns=time.time_ns(), seq=i, source="bench")
        s = 0.5 + 0.5 * math.sin(i / 50)
        q = lo + (hi - lo) * s * 0.8 + 0.1 * (hi - lo)
        out["JointState"].append((keys.robot_joints(WORLD, "arm1"), JointState(arm.joint_names, q, np.full(arm.dof, 0.1), h)))
        yaw = i * 0.01
        pose = Pose(np.array([math.cos(yaw), math.sin(yaw), 0.0]), np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]),
                    np.array([0.3, 0.0, 0.0]), np.array([0.0, 0.0, 0.3]), header=h)
        out["Pose"].append((keys.robot_pose(WORLD, "base1"), pose))
        ranges = rng.uniform(0.2, 14.0, 240)  # some beyond 12 m: misses, as in a real room
        out["Scan"].append((keys.robot_scan(WORLD, "base1"),
                            Scan.from_ranges(ranges, angle_min=-1.178, angle_increment=2.356 / 239, range_max=12.0, header=h)))
    for i in range(grids):
        cells = np.full((400, 400), 255, np.uint8)
        cells[: 40 + i % 300, :] = 0
        cells[rng.integers(0, 400, 2000), rng.integers(0, 400, 2000)] = 100
        out["OccupancyGrid"].append((keys.map_key(WORLD, "map"), OccupancyGrid(0.05, np.array([-10.0, -10.0, 0.0]), cells)))
    return out


def measure(n: int = 2000, grids: int = 200, seed: int = 0, clock: Callable[[], float] = time.perf_counter) -> dict[str, dict]:
    """Per message type: messages drawn, median and p99 cost (us) of one ``WorldLogger.log``, messages/s."""
    import rerun as rr

    from user_peer.catalog import RobotCatalog
    from user_peer.rerun_log import WorldLogger

    msgs = _messages(n, grids, seed)
    result: dict[str, dict] = {}
    with tempfile.TemporaryDirectory(prefix="bench-viewer-") as tmp:
        rec = rr.RecordingStream("robofabric-bench-viewer")
        rec.save(str(Path(tmp) / "bench.rrd"))
        logger = WorldLogger(rec, drawing=RobotCatalog(scene="combined").drawing, max_hz=0)
        t_ns = 0
        for kind in ("Pose", "JointState", "Scan", "OccupancyGrid"):  # a pose first: scans are drawn from it
            key, first = msgs[kind][0]
            logger.log(key, first, t_ns)  # the first of each type sets up static geometry: not timed
            times = []
            for key, msg in msgs[kind][1:]:
                t_ns += 1_000_000
                t0 = clock()
                drawn = logger.log(key, msg, t_ns)
                times.append(clock() - t0)
                if not drawn:
                    raise RuntimeError(f"the viewer did not draw a {kind} on {key}")
            us = np.asarray(times) * 1e6
            result[kind] = {"n": len(times), "median_us": float(np.median(us)), "p99_us": float(np.percentile(us, 99)),
                            "per_s": float(len(us) / (us.sum() / 1e6))}
        rec.flush()
    return result


LABELS = {
    "JointState": "JointState (Meca500: 6+6 plots, Pinocchio FK, link transforms, skeleton)",
    "Pose": "Pose (mobile base: transform, plots, label)",
    "Scan": "Scan (240 rays: hits as points + rays as lines, world frame)",
    "OccupancyGrid": "OccupancyGrid 400x400 (image)",
}


def format_table(result: dict[str, dict]) -> str:
    lines = ["| message | drawn | median (us) | p99 (us) | throughput (msg/s) |", "|---|---|---|---|---|"]
    for kind, r in result.items():
        lines.append(f"| {LABELS[kind]} | {r['n']} | {r['median_us']:.0f} | {r['p99_us']:.0f} | {r['per_s']:.0f} |")
    return "\n".join(lines)


def command(
    n: Annotated[int, typer.Option("--n", help="Messages per type (JointState, Pose, Scan).")] = 2000,
    grids: Annotated[int, typer.Option(help="Occupancy grids (400x400) to draw.")] = 200,
    seed: Annotated[int, typer.Option(help="Seed of the synthetic scans and grids.")] = 0,
    out: Annotated[Optional[Path], typer.Option(help="Append the markdown table to this file.")] = None,
) -> None:
    """Cost of drawing one message in the Rerun viewer (WorldLogger.log to an .rrd file), per message type."""
    from fabric.cli_common import UserError

    if n < 2 or grids < 2:
        raise UserError("--n and --grids must be at least 2 (the first of each type is not timed)")
    table = format_table(measure(n, grids, seed))
    print(table)
    append(out, table)

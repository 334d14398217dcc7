"""``robofabric bench nav``: map update per scan, and Hybrid A* beside OMPL on a 20 m x 20 m map at 5 cm.

Everything runs in this process on synthetic data with known geometry
(:func:`compute_peer.navigation.scenes.office`): scans are ray-cast exactly
and quantised to millimetres like the sim's, start/goal pairs are drawn with a
seed among poses where the robot fits. Each planner gets the same pairs; a
refused or failed query counts against its success rate, not its times.
"""

from __future__ import annotations

import json
import math
import time
from typing import Annotated

import numpy as np
import typer

from compute_peer.navigation.costmap import build_costmap
from compute_peer.navigation.errors import NavigationError
from compute_peer.navigation.hybrid_astar import HybridAStarConfig
from compute_peer.navigation.mapping import MapperConfig, OccupancyMapper
from compute_peer.navigation.model import VehicleModel
from compute_peer.navigation.ompl_planner import OmplConfig
from compute_peer.navigation.planner import PlannerSettings, plan_path
from compute_peer.navigation.scenes import office, scan_angles
from fabric.interfaces import Header, Pose, Scan, quaternion_from_yaw
from robofabric.bench.common import TablesOut, append, pct

RES = 0.05
SIZE = 20.0


def bench_mapping(
    scans: int = 200, rays: int = 240, fov_deg: float = 135.0, range_max: float = 12.0, seed: int = 1
) -> dict:
    """Time ``integrate_scan`` of ``rays``-ray scans on a 400 x 400 grid."""
    scene = office(SIZE)
    cells = int(round(SIZE / RES))
    mapper = OccupancyMapper(MapperConfig(resolution=RES, width=cells, height=cells, origin_x=0.0, origin_y=0.0))
    cm = build_costmap(scene.rasterize(RES), 0.3)
    poses = _free_poses(cm, scans, np.random.default_rng(seed))
    amin, ainc = scan_angles(rays, fov_deg)
    rel = amin + ainc * np.arange(rays)
    data = []
    for x, y, th in poses:
        r = scene.raycast(x, y, rel + th, range_max)
        data.append(
            (
                Scan.from_ranges(r, angle_min=amin, angle_increment=ainc, range_max=range_max),
                Pose(np.array([x, y, 0.0]), quaternion_from_yaw(th), header=Header()),
            )
        )
    times = []
    for scan, pose in data:
        t0 = time.perf_counter()
        mapper.integrate_scan(scan, pose)
        times.append(time.perf_counter() - t0)
    ms = [t * 1e3 for t in times]
    return {
        "what": f"map update, {rays} rays over {fov_deg:.0f} deg, {range_max:.0f} m, {cells}x{cells} grid",
        "n": len(ms),
        "p50_ms": pct(ms, 50),
        "p90_ms": pct(ms, 90),
        "p99_ms": pct(ms, 99),
        "max_ms": max(ms),
    }


def _free_poses(cm, n: int, rng: np.random.Generator) -> list[tuple[float, float, float]]:
    x0, y0, x1, y1 = cm.bounds
    out: list[tuple[float, float, float]] = []
    while len(out) < n:
        x, y = rng.uniform(x0, x1), rng.uniform(y0, y1)
        if cm.free_xy(x, y):
            out.append((float(x), float(y), float(rng.uniform(-math.pi, math.pi))))
    return out


def bench_planning(
    queries: int = 20,
    seed: int = 2,
    robot_radius: float = 0.25,
    turning_radius: float = 0.6,
    planners: tuple[str, ...] = ("hybrid_astar", "ompl:rrtstar", "ompl:bitstar"),
    directions: tuple[bool, ...] = (False, True),
) -> list[dict]:
    """Plan the same ``queries`` random start/goal pairs with each planner, forward-only and with reversing."""
    scene = office(SIZE)
    grid = scene.rasterize(RES)
    t0 = time.perf_counter()
    cm = build_costmap(grid, robot_radius)
    inflate_ms = (time.perf_counter() - t0) * 1e3
    # starts and goals with room for a turning circle around them, so that every pair is drivable
    # forwards only too (a pose facing a wall at arm's length is a test of refusals, not of speed)
    roomy = build_costmap(grid, robot_radius + turning_radius)
    rng = np.random.default_rng(seed)
    pairs = []
    while len(pairs) < queries:
        s, g = _free_poses(roomy, 2, rng)
        if math.hypot(g[0] - s[0], g[1] - s[1]) >= 5.0:  # no trivial hops
            pairs.append((s, g))
    results = []
    for reverse in directions:
        vehicle = VehicleModel(robot_radius=robot_radius, turning_radius=turning_radius, allow_reverse=reverse)
        for name in planners:
            settings = PlannerSettings(vehicle=vehicle, hybrid=HybridAStarConfig(), ompl=OmplConfig(time_limit=5.0))
            times, lengths, failures = [], [], []
            for s, g in pairs:
                t = time.perf_counter()
                try:
                    res = plan_path(cm, s, g, planner=name, settings=settings)
                except NavigationError as exc:
                    failures.append(str(exc))
                    continue
                times.append((time.perf_counter() - t) * 1e3)
                lengths.append(res.length)
            results.append(
                {
                    "planner": name,
                    "motion": "reeds-shepp" if reverse else "dubins",
                    "queries": len(pairs),
                    "solved": len(times),
                    "p50_ms": pct(times, 50),
                    "p90_ms": pct(times, 90),
                    "max_ms": max(times) if times else math.nan,
                    "mean_length_m": float(np.mean(lengths)) if lengths else math.nan,
                    "inflate_ms": inflate_ms,
                    "failures": failures[:3],
                }
            )
    return results


def format_tables(mapping: dict | list[dict], planning: list[dict]) -> str:
    rows = mapping if isinstance(mapping, list) else [mapping]
    lines = [
        "| map update | scans | p50 (ms) | p90 (ms) | p99 (ms) | max (ms) |",
        "|---|---|---|---|---|---|",
        *(
            f"| {m['what']} | {m['n']} | {m['p50_ms']:.3f} | {m['p90_ms']:.3f} | {m['p99_ms']:.3f} | {m['max_ms']:.3f} |"
            for m in rows
        ),
        "",
        "| planner | motion | solved | p50 (ms) | p90 (ms) | max (ms) | mean length (m) |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in planning:
        lines.append(
            f"| {r['planner']} | {r['motion']} | {r['solved']}/{r['queries']} | {r['p50_ms']:.1f} | {r['p90_ms']:.1f} | "
            f"{r['max_ms']:.1f} | {r['mean_length_m']:.2f} |"
        )
    if planning:
        lines.append("")
        lines.append(
            f"Costmap inflation (400x400, robot radius + margin): {planning[0]['inflate_ms']:.2f} ms, once per map."
        )
    return "\n".join(lines)


def command(
    scans: Annotated[int, typer.Option(help="Scans to integrate for the map-update timing.")] = 200,
    queries: Annotated[int, typer.Option(help="Random start/goal pairs per planner and motion model.")] = 20,
    turning_radius: Annotated[float, typer.Option(help="Minimum turning radius (m).")] = 0.6,
    robot_radius: Annotated[float, typer.Option(help="Robot radius for inflation (m).")] = 0.25,
    planners: Annotated[
        str, typer.Option(help="Comma-separated: hybrid_astar, ompl:rrtstar, ompl:bitstar.")
    ] = "hybrid_astar,ompl:rrtstar,ompl:bitstar",
    fovs: Annotated[
        str, typer.Option(help="Comma-separated LIDAR fields of view (deg) for the map update; 240 rays each.")
    ] = "135,360",
    seed: Annotated[int, typer.Option(help="Seed of the start/goal pairs and scan poses.")] = 2,
    as_json: Annotated[bool, typer.Option("--json", help="Print the results as JSON.")] = False,
    out: TablesOut = None,
) -> None:
    """Map update per 240-ray scan on a 400x400 grid; Hybrid A* beside OMPL on a 20 m x 20 m map at 5 cm."""
    from fabric.cli_common import UserError

    names = tuple(p.strip() for p in planners.split(",") if p.strip())
    bad = [p for p in names if p not in ("hybrid_astar", "ompl", "ompl:rrtstar", "ompl:bitstar")]
    if bad or not names:
        raise UserError(
            f"--planners: unknown planner(s) {', '.join(bad) or '(none)'}; use hybrid_astar, ompl:rrtstar, ompl:bitstar"
        )
    if scans < 1 or queries < 1 or turning_radius <= 0 or robot_radius < 0:
        raise UserError("--scans and --queries must be >= 1, --turning-radius > 0, --robot-radius >= 0")
    try:
        fov_list = [float(f) for f in fovs.split(",") if f.strip()]
    except ValueError:
        raise UserError(f"--fovs {fovs!r}: expected degrees like 135,360") from None
    if not fov_list or not all(0 < f <= 360 for f in fov_list):
        raise UserError("--fovs: each field of view must be in (0, 360] degrees")
    mapping = [bench_mapping(scans, fov_deg=f, seed=seed) for f in fov_list]
    planning = bench_planning(queries, seed, robot_radius, turning_radius, names)
    if as_json:
        print(json.dumps({"mapping": mapping, "planning": planning}))
        return
    table = format_tables(mapping, planning)
    print(table)
    append(out, table)

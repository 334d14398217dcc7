"""Hybrid A*: A* over (x, y, heading) bins whose edges are drivable arcs.

Search state is continuous (each node holds the exact pose it was reached at);
only the closed set is discretised into ``xy_resolution`` x ``2 pi /
heading_bins`` bins (Dolgov et al., 2008). Edges are arcs of length ``step`` at
a few curvatures between -1/R and 1/R, forward and, if allowed, backward;
each is checked for collision at every map cell length against the inflated
costmap, all arcs of a node in one numpy batch. The cost is arc length with
penalties for reversing, switching direction and steering.

Two things make it fast in Python:

* the heuristic is the obstacle-aware distance to the goal
  (:class:`~compute_peer.navigation.heuristic.DistanceField`), which also
  refuses an unreachable goal before searching;
* the analytic expansion: from promising nodes a Dubins path straight to the
  goal (and, with reverse allowed, a backwards one) is tried; the first that is
  collision-free ends the search with the exact goal pose.
"""

from __future__ import annotations

import heapq
import math
import time
from dataclasses import dataclass

import numpy as np

from .costmap import Costmap
from .dubins import dubins_paths
from .errors import NavigationError
from .geometry import TWO_PI, arc, wrap_angle
from .heuristic import DistanceField
from .model import PlanResult, Pose2, Tight, VehicleModel, check_endpoints, finish


@dataclass(frozen=True, slots=True)
class HybridAStarConfig:
    xy_resolution: float = 0.2
    heading_bins: int = 72
    step: float | None = None  # arc length per edge; default 1.5 * xy_resolution
    steering_levels: int = 5  # odd: curvatures evenly from -1/R to 1/R
    reverse_penalty: float = 2.0  # multiplies the length of backward arcs
    switch_penalty: float = 1.0  # metres added per change of direction
    steer_penalty: float = 0.05  # per metre, times |curvature| * R
    steer_change_penalty: float = 0.1  # per change of curvature
    heuristic_weight: float = 1.5
    analytic_every: int = 5  # try the analytic shot every N expansions (every one when near the goal)
    max_expansions: int = 50_000
    time_limit: float = 5.0  # seconds

    def __post_init__(self) -> None:
        if self.xy_resolution <= 0 or self.heading_bins < 8 or self.steering_levels < 1 or self.steering_levels % 2 == 0:
            raise NavigationError("Hybrid A* needs xy_resolution > 0, heading_bins >= 8 and an odd number of steering levels")
        if self.heuristic_weight < 1.0 or self.max_expansions < 1 or self.time_limit <= 0:
            raise NavigationError("Hybrid A* needs heuristic_weight >= 1, max_expansions >= 1 and time_limit > 0")


@dataclass(frozen=True, slots=True)
class _Primitives:
    """Edges in the frame of the node they start from: samples (P, K) and end poses (P,)."""

    dx: np.ndarray
    dy: np.ndarray
    dth: np.ndarray
    kappa: np.ndarray
    direction: np.ndarray  # +1 forward, -1 backward
    cost: np.ndarray


def _primitives(vehicle: VehicleModel, cfg: HybridAStarConfig, check_step: float) -> _Primitives:
    step = cfg.step if cfg.step is not None else 1.5 * cfg.xy_resolution
    kmax = 1.0 / vehicle.turning_radius
    kappas = np.linspace(-kmax, kmax, cfg.steering_levels) if cfg.steering_levels > 1 else np.zeros(1)
    dirs = (1.0, -1.0) if vehicle.allow_reverse else (1.0,)
    k = max(2, math.ceil(step / check_step))
    s = np.linspace(step / k, step, k)
    dx, dy, dth, kap, dirn, cost = [], [], [], [], [], []
    for d in dirs:
        for kappa in kappas:
            x, y, th = arc(0.0, 0.0, 0.0, float(kappa), d * s)
            dx.append(x)
            dy.append(y)
            dth.append(th)
            kap.append(kappa)
            dirn.append(d)
            c = step * (cfg.reverse_penalty if d < 0 else 1.0) + cfg.steer_penalty * step * abs(kappa) / kmax
            cost.append(c)
    return _Primitives(np.array(dx), np.array(dy), np.array(dth), np.array(kap), np.array(dirn), np.array(cost))


class HybridAStar:
    """A planner bound to one costmap and vehicle; ``plan(start, goal)`` may be called many times."""

    name = "hybrid_astar"

    def __init__(self, costmap: Costmap, vehicle: VehicleModel, config: HybridAStarConfig | None = None) -> None:
        self.costmap = costmap
        self.vehicle = vehicle
        self.config = config or HybridAStarConfig()
        self.check_step = 0.9 * costmap.resolution
        self.prims = _primitives(vehicle, self.config, self.check_step)
        self.factor = max(1, round(self.config.xy_resolution / costmap.resolution))

    # ------------------------------------------------------------------ helpers

    def _key(self, x: float, y: float, th: float) -> tuple[int, int, int]:
        cfg = self.config
        hb = int(round((th % TWO_PI) / (TWO_PI / cfg.heading_bins))) % cfg.heading_bins
        return (int(math.floor(x / cfg.xy_resolution)), int(math.floor(y / cfg.xy_resolution)), hb)

    def _shot(self, pose: Pose2, goal: Pose2, tight: Tight) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """A collision-free Dubins path (forward, or backward if allowed) from ``pose`` to ``goal``, or None."""
        R = self.vehicle.turning_radius
        cands = [(p, 1.0) for p in dubins_paths(pose, goal, R)]
        if self.vehicle.allow_reverse:
            # driving backwards from A to B is driving forwards from B to A, both turned around
            rev_a = (pose[0], pose[1], pose[2] + math.pi)
            rev_b = (goal[0], goal[1], goal[2] + math.pi)
            cands += [(p, -1.0) for p in dubins_paths(rev_a, rev_b, R)]
            cands.sort(key=lambda c: c[0].length * (self.config.reverse_penalty if c[1] < 0 else 1.0))
        for path, d in cands:
            start = pose if d > 0 else (pose[0], pose[1], pose[2] + math.pi)
            xs, ys, ts = path.sample(*start, self.check_step)
            if self.costmap.free(xs, ys).all() or (tight and tight.motion_ok(xs, ys)):
                return xs, ys, (ts if d > 0 else ts - math.pi)
        return None

    # ------------------------------------------------------------------ search

    def plan(self, start: Pose2, goal: Pose2) -> PlanResult:
        t0 = time.perf_counter()
        cfg, cm, pr = self.config, self.costmap, self.prims
        tight = check_endpoints(cm, start, goal)
        field = DistanceField(cm.collision, cm.resolution, (cm.origin_x, cm.origin_y), self.factor, (goal[0], goal[1]))
        h0 = float(field.lookup(np.array([start[0]]), np.array([start[1]]))[0])
        if not math.isfinite(h0):
            raise NavigationError(
                f"goal ({goal[0]:.2f}, {goal[1]:.2f}) cannot be reached from start ({start[0]:.2f}, {start[1]:.2f}): "
                f"no corridor wide enough for a robot of radius {self.vehicle.robot_radius:.2f} m"
            )
        w = cfg.heuristic_weight
        near = 2.0 * self.vehicle.turning_radius + 2.0 * cfg.xy_resolution
        sight_slack = 2.0 * math.pi * self.vehicle.turning_radius + 2.0 * field.cell
        field_at = field.at
        # node storage: parallel lists; parent -1 for the root, prim -1 for the root
        nx, ny, nth, ng, nparent, nprim, ndir = [start[0]], [start[1]], [start[2]], [0.0], [-1], [-1], [1.0]
        best_g: dict[tuple[int, int, int], float] = {self._key(*start): 0.0}
        closed: set[tuple[int, int, int]] = set()
        heap: list[tuple[float, int]] = [(w * max(h0, math.hypot(goal[0] - start[0], goal[1] - start[1])), 0)]
        expansions = 0
        gx, gy = goal[0], goal[1]
        while heap:
            _, i = heapq.heappop(heap)
            x, y, th = nx[i], ny[i], nth[i]
            key = self._key(x, y, th)
            if key in closed:
                continue
            closed.add(key)
            expansions += 1
            if expansions > cfg.max_expansions or (expansions & 63 == 0 and time.perf_counter() - t0 > cfg.time_limit):
                raise NavigationError(
                    f"hybrid A* found no path within {expansions - 1} expansions / {time.perf_counter() - t0:.2f} s "
                    f"(turning radius {self.vehicle.turning_radius:.2f} m may be too large for this map)"
                )
            dist_goal = math.hypot(gx - x, gy - y)
            # shoot only with a line of sight, more or less: where the distance around obstacles exceeds
            # the straight distance by more than a turning circle, a Dubins path would hit something
            if (dist_goal < near or expansions % cfg.analytic_every == 1) and (
                field_at(x, y) <= dist_goal + sight_slack
            ):
                shot = self._shot((x, y, th), goal, tight)
                if shot is not None:
                    xs, ys, ts = self._reconstruct(i, nx, ny, nth, nparent, nprim)
                    return finish(
                        cm,
                        np.concatenate([xs, shot[0][1:]]),
                        np.concatenate([ys, shot[1][1:]]),
                        np.concatenate([ts, shot[2][1:]]),
                        planner=self.name,
                        seconds=time.perf_counter() - t0,
                        expansions=expansions,
                    )
            c, s = math.cos(th), math.sin(th)
            wx = x + c * pr.dx - s * pr.dy
            wy = y + s * pr.dx + c * pr.dy
            ok = cm.free(wx, wy).all(axis=1)
            if tight and not ok.all() and tight.near(x, y):
                for p in np.flatnonzero(~ok).tolist():
                    ok[p] = tight.motion_ok(np.append(x, wx[p]), np.append(y, wy[p]))
            if not ok.any():
                continue
            idx = np.flatnonzero(ok)
            ex, ey = wx[idx, -1], wy[idx, -1]
            eth = wrap_angle(th + pr.dth[idx, -1])
            h = np.maximum(field.lookup(ex, ey) - field.cell, np.hypot(gx - ex, gy - ey))
            g_here, d_here = ng[i], ndir[i]
            k_here = pr.kappa[nprim[i]] if nprim[i] >= 0 else 0.0
            for j, p in enumerate(idx.tolist()):
                hj = float(h[j])
                if not math.isfinite(hj):
                    continue
                exj, eyj, ethj = float(ex[j]), float(ey[j]), float(eth[j])
                kj = self._key(exj, eyj, ethj)
                if kj in closed:
                    continue
                g = g_here + float(pr.cost[p])
                if pr.direction[p] != d_here and nprim[i] >= 0:
                    g += cfg.switch_penalty
                if pr.kappa[p] != k_here:
                    g += cfg.steer_change_penalty
                if g >= best_g.get(kj, math.inf):
                    continue
                best_g[kj] = g
                nx.append(exj)
                ny.append(eyj)
                nth.append(ethj)
                ng.append(g)
                nparent.append(i)
                nprim.append(p)
                ndir.append(float(pr.direction[p]))
                heapq.heappush(heap, (g + w * hj, len(nx) - 1))
        if expansions <= 1:
            raise NavigationError(
                f"the robot cannot drive away from its start ({start[0]:.2f}, {start[1]:.2f}, {start[2]:.2f} rad) "
                f"without touching an obstacle" + ("" if self.vehicle.allow_reverse else " (forwards only: allow reversing?)")
            )
        raise NavigationError(
            f"no path from ({start[0]:.2f}, {start[1]:.2f}) to ({goal[0]:.2f}, {goal[1]:.2f}): the search space is exhausted "
            f"after {expansions} expansions (turning radius {self.vehicle.turning_radius:.2f} m)"
        )

    def _reconstruct(self, i: int, nx, ny, nth, nparent, nprim) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        chain = []
        while i >= 0:
            chain.append(i)
            i = nparent[i]
        chain.reverse()
        pr = self.prims
        xs, ys, ts = [np.array([nx[chain[0]]])], [np.array([ny[chain[0]]])], [np.array([nth[chain[0]]])]
        for parent, child in zip(chain[:-1], chain[1:]):
            p = nprim[child]
            x, y, th = nx[parent], ny[parent], nth[parent]
            c, s = math.cos(th), math.sin(th)
            xs.append(x + c * pr.dx[p] - s * pr.dy[p])
            ys.append(y + s * pr.dx[p] + c * pr.dy[p])
            ts.append(th + pr.dth[p])
        return np.concatenate(xs), np.concatenate(ys), np.concatenate(ts)


def plan_hybrid_astar(
    costmap: Costmap, start: Pose2, goal: Pose2, vehicle: VehicleModel | None = None, config: HybridAStarConfig | None = None
) -> PlanResult:
    return HybridAStar(costmap, vehicle or VehicleModel(), config).plan(start, goal)

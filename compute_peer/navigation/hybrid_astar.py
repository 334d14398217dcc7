"""Hybrid A*: A* over (x, y, heading) bins whose edges are drivable arcs.

Search state is continuous (each node holds the exact pose it was reached at);
only the closed set is discretised into ``xy_resolution`` x ``2 pi /
heading_bins`` bins (Dolgov et al., 2008). Edges are arcs of length ``step`` at
a few curvatures between -1/R and 1/R, forward and, if allowed, backward;
each is checked for collision at every map cell length against the inflated
costmap, all arcs of a node in one numpy batch. The cost is arc length with
penalties for reversing, switching direction and steering, and for running near the obstacles (within
``costmap.NEAR`` of the inflation: the path keeps clear of corners where it costs little).

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
from .errors import NavigationError, StuckAtStart
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
    near_penalty: float = 1.0  # multiplies the cost of an edge ending within costmap.NEAR of the inflated obstacles
    heuristic_weight: float = 1.5
    analytic_every: int = 5  # try the analytic shot every N expansions (every one when near the goal)
    max_expansions: int = 50_000
    time_limit: float = 5.0  # seconds

    def __post_init__(self) -> None:
        if (
            self.xy_resolution <= 0
            or self.heading_bins < 8
            or self.steering_levels < 1
            or self.steering_levels % 2 == 0
        ):
            raise NavigationError(
                "Hybrid A* needs xy_resolution > 0, heading_bins >= 8 and an odd number of steering levels"
            )
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
        """The path from ``start`` to ``goal``; :class:`NavigationError` saying why when there is none."""
        search = _Search(self, start, goal)
        while (i := search.pop()) is not None:
            result = search.shoot(i)
            if result is not None:
                return result
            search.expand(i)
        raise search.exhausted()

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


class _Search:
    """One search of a :class:`HybridAStar`: its nodes, open heap, closed bins and budget.

    Nodes are parallel lists (``parent`` and ``prim`` are -1 for the root); a node holds the exact pose it
    was reached at, and only its bin (:meth:`HybridAStar._key`) is closed."""

    def __init__(self, planner: HybridAStar, start: Pose2, goal: Pose2) -> None:
        self.t0 = time.perf_counter()
        self.planner, self.start, self.goal = planner, start, goal
        cm, cfg, vehicle = planner.costmap, planner.config, planner.vehicle
        self.tight = check_endpoints(cm, start, goal)
        self.field = DistanceField(
            cm.collision, cm.resolution, (cm.origin_x, cm.origin_y), planner.factor, (goal[0], goal[1])
        )
        h0 = float(self.field.lookup(np.array([start[0]]), np.array([start[1]]))[0])
        if not math.isfinite(h0):
            raise NavigationError(
                f"goal ({goal[0]:.2f}, {goal[1]:.2f}) cannot be reached from start ({start[0]:.2f}, {start[1]:.2f}): "
                f"no corridor wide enough for a robot of radius {vehicle.robot_radius:.2f} m"
            )
        self.near = 2.0 * vehicle.turning_radius + 2.0 * cfg.xy_resolution
        self.sight_slack = 2.0 * math.pi * vehicle.turning_radius + 2.0 * self.field.cell
        self.nx, self.ny, self.nth = [start[0]], [start[1]], [start[2]]
        self.ng, self.nparent, self.nprim, self.ndir = [0.0], [-1], [-1], [1.0]
        self.best_g: dict[tuple[int, int, int], float] = {planner._key(*start): 0.0}
        self.closed: set[tuple[int, int, int]] = set()
        self.heap: list[tuple[float, int]] = [
            (cfg.heuristic_weight * max(h0, math.hypot(goal[0] - start[0], goal[1] - start[1])), 0)
        ]
        self.expansions = 0

    def pop(self) -> int | None:
        """The next node to expand (its bin now closed), None when none is left; NavigationError past the budget."""
        cfg, key, closed = self.planner.config, self.planner._key, self.closed
        while self.heap:
            _, i = heapq.heappop(self.heap)
            k = key(self.nx[i], self.ny[i], self.nth[i])
            if k in closed:
                continue
            closed.add(k)
            self.expansions += 1
            e = self.expansions
            if e > cfg.max_expansions or (e & 63 == 0 and time.perf_counter() - self.t0 > cfg.time_limit):
                raise NavigationError(
                    f"hybrid A* found no path within {e - 1} expansions / {time.perf_counter() - self.t0:.2f} s "
                    f"(turning radius {self.planner.vehicle.turning_radius:.2f} m may be too large for this map)"
                )
            return i
        return None

    def shoot(self, i: int) -> PlanResult | None:
        """The analytic expansion from node ``i``: the whole path when a Dubins shot to the goal is free.

        Tried near the goal, and every ``analytic_every`` expansions elsewhere, only with a line of sight more
        or less: where the distance around obstacles exceeds the straight one by more than a turning circle,
        a Dubins path would hit something."""
        x, y, th = self.nx[i], self.ny[i], self.nth[i]
        gx, gy = self.goal[0], self.goal[1]
        dist_goal = math.hypot(gx - x, gy - y)
        if not (dist_goal < self.near or self.expansions % self.planner.config.analytic_every == 1):
            return None
        if self.field.at(x, y) > dist_goal + self.sight_slack:
            return None
        shot = self.planner._shot((x, y, th), self.goal, self.tight)
        if shot is None:
            return None
        xs, ys, ts = self.planner._reconstruct(i, self.nx, self.ny, self.nth, self.nparent, self.nprim)
        return finish(
            self.planner.costmap,
            np.concatenate([xs, shot[0][1:]]),
            np.concatenate([ys, shot[1][1:]]),
            np.concatenate([ts, shot[2][1:]]),
            planner=self.planner.name,
            seconds=time.perf_counter() - self.t0,
            expansions=self.expansions,
        )

    def _free_edges(self, x: float, y: float, th: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The primitives from (x, y, th) clear of obstacles: their indices and sample points (world frame)."""
        pr, cm, tight = self.planner.prims, self.planner.costmap, self.tight
        c, s = math.cos(th), math.sin(th)
        wx = x + c * pr.dx - s * pr.dy
        wy = y + s * pr.dx + c * pr.dy
        ok = cm.free(wx, wy).all(axis=1)
        if tight and not ok.all() and tight.near(x, y):
            for p in np.flatnonzero(~ok).tolist():
                ok[p] = tight.motion_ok(np.append(x, wx[p]), np.append(y, wy[p]))
        return np.flatnonzero(ok), wx, wy

    def expand(self, i: int) -> None:
        """Push the children of node ``i`` that reach a bin not closed, cheaper than it was reached before."""
        planner = self.planner
        cfg, pr, key = planner.config, planner.prims, planner._key
        x, y, th = self.nx[i], self.ny[i], self.nth[i]
        idx, wx, wy = self._free_edges(x, y, th)
        if not idx.size:
            return
        gx, gy = self.goal[0], self.goal[1]
        ex, ey = wx[idx, -1], wy[idx, -1]
        eth = wrap_angle(th + pr.dth[idx, -1])
        h = np.maximum(self.field.lookup(ex, ey) - self.field.cell, np.hypot(gx - ex, gy - ey))
        near = planner.costmap.near_xy(ex, ey) if cfg.near_penalty else np.zeros(idx.size, dtype=bool)
        w = cfg.heuristic_weight
        closed, best_g, heap = self.closed, self.best_g, self.heap
        prim_here = self.nprim[i]
        g_here, d_here = self.ng[i], self.ndir[i]
        k_here = pr.kappa[prim_here] if prim_here >= 0 else 0.0
        for j, p in enumerate(idx.tolist()):
            hj = float(h[j])
            if not math.isfinite(hj):
                continue
            exj, eyj, ethj = float(ex[j]), float(ey[j]), float(eth[j])
            kj = key(exj, eyj, ethj)
            if kj in closed:
                continue
            g = g_here + float(pr.cost[p]) * (1.0 + cfg.near_penalty * bool(near[j]))
            if pr.direction[p] != d_here and prim_here >= 0:
                g += cfg.switch_penalty
            if pr.kappa[p] != k_here:
                g += cfg.steer_change_penalty
            if g >= best_g.get(kj, math.inf):
                continue
            best_g[kj] = g
            self._add(exj, eyj, ethj, g, i, p)
            heapq.heappush(heap, (g + w * hj, len(self.nx) - 1))

    def _add(self, x: float, y: float, th: float, g: float, parent: int, prim: int) -> None:
        self.nx.append(x)
        self.ny.append(y)
        self.nth.append(th)
        self.ng.append(g)
        self.nparent.append(parent)
        self.nprim.append(prim)
        self.ndir.append(float(self.planner.prims.direction[prim]))

    def exhausted(self) -> NavigationError:
        """Why the search ended with no path: stuck at the start, or every reachable bin tried."""
        start, goal, vehicle = self.start, self.goal, self.planner.vehicle
        if self.expansions <= 1:
            return StuckAtStart(
                f"the robot cannot drive away from its start ({start[0]:.2f}, {start[1]:.2f}, {start[2]:.2f} rad) "
                f"without touching an obstacle"
                + ("" if vehicle.allow_reverse else " (forwards only: allow reversing?)")
            )
        return NavigationError(
            f"no path from ({start[0]:.2f}, {start[1]:.2f}) to ({goal[0]:.2f}, {goal[1]:.2f}): the search space is exhausted "
            f"after {self.expansions} expansions (turning radius {vehicle.turning_radius:.2f} m)"
        )


def plan_hybrid_astar(
    costmap: Costmap,
    start: Pose2,
    goal: Pose2,
    vehicle: VehicleModel | None = None,
    config: HybridAStarConfig | None = None,
) -> PlanResult:
    return HybridAStar(costmap, vehicle or VehicleModel(), config).plan(start, goal)

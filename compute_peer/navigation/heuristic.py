"""Obstacle-aware distance-to-goal on a coarse grid: the heuristic that makes Hybrid A* fast.

An 8-connected Dijkstra from the goal over a grid coarser than the map (one
coarse cell per Hybrid A* position bin). A coarse cell is blocked only when
every map cell in it is blocked, so the distances stay optimistic around
narrow gaps; where the goal is unreachable the distance is infinite, which
also lets the planner refuse at once instead of exhausting its search.
"""

from __future__ import annotations

import heapq
import math

import numpy as np

_NEIGHBOURS = [(dr, dc, math.hypot(dr, dc)) for dr in (-1, 0, 1) for dc in (-1, 0, 1) if dr or dc]


class DistanceField:
    """Distances (m) from every coarse cell's centre to the goal's coarse cell, around obstacles."""

    def __init__(
        self,
        blocked: np.ndarray,
        resolution: float,
        origin: tuple[float, float],
        factor: int,
        goal_xy: tuple[float, float],
    ) -> None:
        h, w = blocked.shape
        self.factor = max(1, int(factor))
        self.cell = resolution * self.factor
        self.origin = origin
        k = self.factor
        hc, wc = -(-h // k), -(-w // k)
        padded = np.ones((hc * k, wc * k), dtype=bool)
        padded[:h, :w] = blocked
        coarse_blocked = padded.reshape(hc, k, wc, k).all(axis=(1, 3))
        self.shape = (hc, wc)
        gr, gc = self.cell_of(*goal_xy)
        self.dist = self._dijkstra(coarse_blocked, gr, gc)

    def cell_of(self, x: float, y: float) -> tuple[int, int]:
        hc, wc = self.shape
        r = min(max(int(math.floor((y - self.origin[1]) / self.cell)), 0), hc - 1)
        c = min(max(int(math.floor((x - self.origin[0]) / self.cell)), 0), wc - 1)
        return r, c

    def _dijkstra(self, blocked: np.ndarray, gr: int, gc: int) -> np.ndarray:
        hc, wc = blocked.shape
        # pad with a blocked border so that neighbours need no bounds checks: flat index offsets only
        w = wc + 2
        free = np.zeros((hc + 2, w), dtype=bool)
        free[1:-1, 1:-1] = ~blocked
        g = (gr + 1) * w + (gc + 1)
        free[gr + 1, gc + 1] = True  # the goal itself was checked by the caller
        ok = free.ravel().tolist()
        inf = math.inf
        dist = [inf] * len(ok)
        dist[g] = 0.0
        steps = [(dr * w + dc, cost) for dr, dc, cost in _NEIGHBOURS]
        pq = [(0.0, g)]
        pop, push = heapq.heappop, heapq.heappush
        while pq:
            d, i = pop(pq)
            if d > dist[i]:
                continue
            for off, cost in steps:
                j = i + off
                if ok[j]:
                    nd = d + cost
                    if nd < dist[j]:
                        dist[j] = nd
                        push(pq, (nd, j))
        return np.array(dist).reshape(hc + 2, w)[1:-1, 1:-1] * self.cell

    def at(self, x: float, y: float) -> float:
        """Distance for one world point (scalar)."""
        r, c = self.cell_of(x, y)
        return float(self.dist[r, c])

    def lookup(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Distance for world points (vectorised); inf where the goal cannot be reached."""
        hc, wc = self.shape
        r = np.clip(np.floor((y - self.origin[1]) / self.cell), 0, hc - 1).astype(np.intp)
        c = np.clip(np.floor((x - self.origin[0]) / self.cell), 0, wc - 1).astype(np.intp)
        return self.dist[r, c]

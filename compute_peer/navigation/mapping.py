"""Log-odds occupancy mapping from planar scans taken at known poses.

Each ray marks the cells it crosses as seen free and the cell of its end point
as seen occupied (a ray that reads ``range_max`` hit nothing and marks only
free cells). Ray traversal is vectorised: all rays of a scan are sampled at
once at one-cell steps in one flat array (clipped at the map's edge, so no
sample needs a bounds check), the samples become flat cell indices, and
``logodds[idx] += l_free`` applies at most one update per cell per scan however
many samples fell in it (numpy's buffered fancy assignment) - the same rule as
a per-ray DDA with a visited set, at array speed.
Hits win over free marks from other rays of the same scan.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from fabric.interfaces import Header, OccupancyGrid, Pose, Scan, yaw_from_quaternion

from .errors import NavigationError
from .grid import UNKNOWN
from .robot_cells import ROBOT_MARGIN, Footprint, footprint_indices


@dataclass(frozen=True, slots=True)
class MapperConfig:
    """Grid geometry and the sensor model (log-odds increments and clamps)."""

    resolution: float = 0.05
    width: int = 400
    height: int = 400
    origin_x: float = -10.0
    origin_y: float = -10.0
    l_occ: float = 0.85
    l_free: float = -0.4
    l_min: float = -2.0
    l_max: float = 3.5
    step: float = 1.0  # ray sampling step along a ray, in cells (a cell a ray only clips at a corner may be missed)

    def __post_init__(self) -> None:
        if not (self.resolution > 0 and self.width > 0 and self.height > 0):
            raise NavigationError(
                f"map geometry must be positive, got {self.width}x{self.height} at {self.resolution} m"
            )
        if not (self.l_occ > 0 > self.l_free and self.l_min < 0 < self.l_max and 0 < self.step <= 1):
            raise NavigationError("sensor model needs l_occ > 0 > l_free, l_min < 0 < l_max and 0 < step <= 1")


class OccupancyMapper:
    """Accumulates scans into a log-odds grid. Not thread-safe: the service holds a lock around it."""

    def __init__(self, config: MapperConfig | None = None) -> None:
        self.config = config or MapperConfig()
        c = self.config
        self.logodds = np.zeros((c.height, c.width), dtype=np.float32)
        self.observed = np.zeros((c.height, c.width), dtype=bool)
        self.scans = 0

    def reset(self) -> None:
        self.logodds.fill(0.0)
        self.observed.fill(False)
        self.scans = 0

    # ------------------------------------------------------------------ updates

    def integrate(
        self,
        ranges: np.ndarray,
        angles: np.ndarray,
        range_max: float,
        x: float,
        y: float,
        yaw: float,
        *,
        robots: np.ndarray | None = None,
    ) -> None:
        """Add one scan taken by a sensor at (x, y) facing ``yaw``; ``angles`` are relative to the sensor.

        ``robots``: flat indices of the cells under the robots when the scan was taken (:mod:`.robot_cells`):
        no end point there marks a cell occupied, and they end the scan seen free.
        """
        c = self.config
        ranges = np.asarray(ranges, dtype=np.float64)
        angles = np.asarray(angles, dtype=np.float64)
        if ranges.shape != angles.shape or ranges.ndim != 1:
            raise NavigationError(f"scan has {ranges.shape} ranges for {angles.shape} angles")
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(yaw)):
            raise NavigationError("scan pose must be finite")
        inv = 1.0 / c.resolution
        # everything below is in cell units: sensor position and ray lengths
        sx = (x - c.origin_x) * inv
        sy = (y - c.origin_y) * inv
        r = np.nan_to_num(ranges, nan=range_max, posinf=range_max) * inv
        rmax = range_max * inv
        hit = r < rmax - 1e-6
        a = angles + yaw
        ca, sa = np.cos(a), np.sin(a)
        ex = sx + r * ca
        ey = sy + r * sa
        sensor_inside = 0 <= sx < c.width and 0 <= sy < c.height
        # free samples: strictly before each ray's end point (and, from a sensor inside the map, before the
        # map's edge, so no sample needs a bounds check), ``step`` cells apart, all rays in one flat array
        free_len = np.clip(r - 0.5, 0.0, None)
        if sensor_inside:
            with np.errstate(divide="ignore"):
                tx = np.where(ca > 0, (c.width - 1e-3 - sx) / ca, np.where(ca < 0, -sx / ca, np.inf))
                ty = np.where(sa > 0, (c.height - 1e-3 - sy) / sa, np.where(sa < 0, -sy / sa, np.inf))
            free_len = np.minimum(free_len, np.minimum(tx, ty))
        counts = np.ceil(free_len / c.step).astype(np.intp)
        total = int(counts.sum())
        # sample k of a ray is at sensor + k * step * (cos, sin): the per-ray terms are repeated, not gathered
        # float32 halves the memory traffic; it holds every sample index exactly below 2**24 samples
        ft = np.float32 if total < 2**24 else np.float64
        k = np.arange(total, dtype=ft) - np.repeat((np.cumsum(counts) - counts).astype(ft), counts)
        fx = ft(sx) + k * np.repeat((ca * c.step).astype(ft), counts)
        fy = ft(sy) + k * np.repeat((sa * c.step).astype(ft), counts)
        free_idx = self._flat(fx, fy, sensor_inside)
        hit_idx = self._flat(ex[hit], ey[hit], False)
        if robots is not None and robots.size:
            hit_idx = hit_idx[~np.isin(hit_idx, robots)]  # a robot seen is no wall
        lo = self.logodds.reshape(-1)
        ob = self.observed.reshape(-1)
        before_hits = lo[hit_idx]
        lo[free_idx] = np.maximum(lo[free_idx] + c.l_free, c.l_min)
        lo[hit_idx] = np.minimum(before_hits + c.l_occ, c.l_max)
        ob[free_idx] = True
        ob[hit_idx] = True
        if robots is not None and robots.size:
            self.clear_cells(robots)
        self.scans += 1

    def clear_cells(self, idx: np.ndarray) -> None:
        """Mark cells (flat indices) seen free, whatever earlier scans said: the floor under a robot is floor."""
        c = self.config
        lo = self.logodds.reshape(-1)
        lo[idx] = np.minimum(lo[idx], c.l_free)
        self.observed.reshape(-1)[idx] = True

    def _flat(self, cx: np.ndarray, cy: np.ndarray, inside_known: bool) -> np.ndarray:
        """Flat cell indices of points in cell units; points outside the grid are dropped unless known inside."""
        c = self.config
        if not inside_known:
            inside = (cx >= 0) & (cx < c.width) & (cy >= 0) & (cy < c.height)
            cx, cy = cx[inside], cy[inside]
        return cy.astype(np.int32) * np.int32(c.width) + cx.astype(np.int32)

    def clear_footprint(self, x: float, y: float, radius: float) -> None:
        """Mark the disk the robot stands on as seen free (once): no sensor sees the floor under the robot."""
        c = self.config
        if radius <= 0:
            return
        cx, cy = (x - c.origin_x) / c.resolution, (y - c.origin_y) / c.resolution
        rc = radius / c.resolution
        r0, r1 = max(int(cy - rc), 0), min(int(cy + rc) + 1, c.height)
        c0, c1 = max(int(cx - rc), 0), min(int(cx + rc) + 1, c.width)
        if r0 >= r1 or c0 >= c1:
            return
        rr, cc = np.mgrid[r0:r1, c0:c1]
        inside = (rr + 0.5 - cy) ** 2 + (cc + 0.5 - cx) ** 2 <= rc * rc
        lo = self.logodds[r0:r1, c0:c1]
        lo[inside] = np.maximum(lo[inside] + c.l_free, c.l_min)
        self.observed[r0:r1, c0:c1] |= inside

    def integrate_scan(
        self,
        scan: Scan,
        pose: Pose,
        *,
        sensor_offset: tuple[float, float, float] = (0.0, 0.0, 0.0),
        footprint: float = 0.0,
        robots: Sequence[Footprint] = (),
        margin: float = ROBOT_MARGIN,
    ) -> None:
        """Add a fabric Scan taken at a fabric Pose; ``sensor_offset`` is (x, y, yaw) of the sensor on the robot.

        ``footprint`` > 0 also marks the robot's own disk of that radius free (the robot stands there).
        ``robots``: where every robot of the world stood when the scan was taken: their cells (radius +
        ``margin``) are never marked occupied by this scan, and are cleared (:mod:`.robot_cells`).
        """
        yaw = yaw_from_quaternion(pose.quaternion)
        if footprint > 0:
            self.clear_footprint(float(pose.position[0]), float(pose.position[1]), footprint)
        c = self.config
        under = (
            footprint_indices((c.height, c.width), c.resolution, (c.origin_x, c.origin_y), robots, margin)
            if robots
            else None
        )
        ox, oy, oyaw = sensor_offset
        cy, sy = math.cos(yaw), math.sin(yaw)
        x = float(pose.position[0]) + cy * ox - sy * oy
        y = float(pose.position[1]) + sy * ox + cy * oy
        self.integrate(scan.ranges, scan.angles, scan.range_max, x, y, yaw + oyaw, robots=under)

    # ------------------------------------------------------------------ reading

    def probabilities(self) -> np.ndarray:
        """Occupancy probability per cell (0.5 where never observed)."""
        return 1.0 / (1.0 + np.exp(-self.logodds.astype(np.float64)))

    def grid(self, *, threshold: float | None = None, header: Header | None = None) -> OccupancyGrid:
        """The map as an OccupancyGrid: percent occupancy, or 0/100 with ``threshold`` (a probability).

        Cells never observed stay 255 (unknown) in both forms.
        """
        c = self.config
        p = self.probabilities()
        if threshold is None:
            cells = np.rint(p * 100.0).astype(np.uint8)
        else:
            if not (0.0 < threshold < 1.0):
                raise NavigationError(f"threshold must be a probability in (0, 1), got {threshold}")
            cells = np.where(p > threshold, 100, 0).astype(np.uint8)
        cells[~self.observed] = UNKNOWN
        return OccupancyGrid(c.resolution, np.array([c.origin_x, c.origin_y, 0.0]), cells, header or Header())

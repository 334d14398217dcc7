"""A mobile base: its body where its pose puts it (moved on by velocity x age in a live view: paper Eq. 8), its
speed and pose-age plots, its dot on every map, and its LIDAR scan and sonar ring in the world frame."""

from __future__ import annotations

from typing import Callable

import numpy as np
import rerun as rr

from fabric.interfaces import OccupancyGrid, Pose, Scan
from robots.kinds import facts
from user_peer.drawing.canvas import Canvas, Rows
from user_peer.drawing.labels import OwnershipDrawer
from user_peer.drawing.robots import RobotDrawing
from user_peer.geometry import EXTRAPOLATION_CAP_S, scan_world_points, world_to_map_pixels
from user_peer.rerun_columns import (
    POSITIONS2,
    POSITIONS3,
    SCALARS,
    STRIPS3,
    column,
    scalars,
    send,
    strips,
    transforms,
    vectors,
)

__all__ = ["BaseDrawer"]

DEFAULT_SONAR = (0.0, 0.0, 0.12, 0.26)
"""A sonar ring's centre x, y, height and radius where the robot's description gives none."""


class BaseDrawer:
    """Files poses and scans of the bases, draws them at a flush.

    ``clock``: the clock that stamped the arrival times (a live view); None (an export from a recording): no
    extrapolation, nothing is "now". ``grids``: the maps a base's dot is drawn on (the map drawer's, shared)."""

    def __init__(
        self, canvas: Canvas, labels: OwnershipDrawer, grids: dict[str, OccupancyGrid], clock: Callable[[], int] | None
    ) -> None:
        self.canvas = canvas
        self.labels = labels
        self.grids = grids
        self.clock = clock
        self.poses: dict[str, Pose] = {}  # each base's latest: scans are put in the world frame from it
        self._bases: dict[str, Rows] = {}
        self._scans: dict[tuple[str, str], Rows] = {}

    def static(self, rid: str, info: RobotDrawing) -> None:
        """What never moves: the body, its heading, the scans' styles, the speed plot's names, the label."""
        if not facts(info.kind).base or not self.canvas.once(f"{rid}/base"):
            return
        rec, root = self.canvas.rec, f"world/robots/{rid}"
        path = f"{root}/base"
        r, h = info.radius, info.height
        rec.log(
            f"{path}/body",
            rr.Cylinders3D(lengths=[h], radii=[r], centers=[[0, 0, h / 2]], colors=[info.color], fill_mode="solid"),
            static=True,
        )
        rec.log(
            f"{path}/heading",
            rr.Arrows3D(vectors=[[r * 1.4, 0, 0]], origins=[[0, 0, h + 0.02]], colors=[(20, 20, 20)]),
            static=True,
        )
        rec.log(
            f"{root}/scan",
            rr.Points3D.from_fields(radii=0.02, colors=[(230, 40, 40)]),
            rr.LineStrips3D.from_fields(radii=0.002, colors=[(240, 150, 150)]),
            static=True,
        )
        rec.log(
            f"{root}/sonar",
            rr.Points3D.from_fields(radii=0.03, colors=[(40, 170, 230)]),
            rr.LineStrips3D.from_fields(radii=0.003, colors=[(120, 200, 240)]),
            static=True,
        )
        rec.log(f"plots/speed/{rid}", rr.SeriesLines(names=["v (m/s)", "omega (rad/s)"]), static=True)
        self.labels.place(rid, f"{path}/label", np.array([0.0, 0.0, h + 0.25]))

    def file_pose(self, rid: str, pose: Pose, received_ns: int, *, due: bool = True) -> None:
        """Keep the base's latest pose; file it for drawing when ``due`` (not thinned out)."""
        self.poses[rid] = pose
        if due:
            self.canvas.file(self._bases, rid, (pose, received_ns))

    def file_scan(self, rid: str, info: RobotDrawing, scan: Scan, *, sonar: bool = False) -> None:
        """File a LIDAR scan (or the ultrasonic ring's): its hits and rays in the world frame, from the base's
        latest pose."""
        if sonar:
            cx, cy, h, radius = info.sonar or DEFAULT_SONAR
            # ranges are measured from the rim: from the ring's centre they are `radius` longer
            ranges = np.where(np.isfinite(scan.ranges), scan.ranges + radius, np.inf)
            centred = Scan.from_ranges(
                ranges,
                angle_min=scan.angle_min,
                angle_increment=scan.angle_increment,
                range_max=scan.range_max + radius,
                header=scan.header,
            )
            origin, pts, hit = scan_world_points(centred, self.poses.get(rid), (cx, cy, h))
            ends = pts[hit]
        else:
            origin, pts, hit = scan_world_points(scan, self.poses.get(rid), info.lidar_offset)
            ends = pts[:: max(1, len(pts) // 60)]
        rays = np.empty((len(ends), 2, 3))
        rays[:, 0] = origin
        rays[:, 1] = ends
        self.canvas.file(self._scans, (rid, "sonar" if sonar else "scan"), (pts[hit], rays))

    def flush(self, robots: dict[str, RobotDrawing]) -> None:
        """Draw the poses, then the scans, filed since the last flush."""
        for rid, rows in self._bases.items():
            if rows.items:
                self._draw_poses(rid, robots[rid], rows)
        for (rid, name), rows in self._scans.items():
            if rows.items:
                # hits as points and rays as lines, one entity
                hits = [it[0] for it in rows.items]
                rays = [it[1] for it in rows.items]
                send(
                    self.canvas.rec,
                    f"world/robots/{rid}/{name}",
                    rows.times(),
                    [
                        column(POSITIONS3, vectors(np.concatenate(hits).reshape(-1, 3), 3), [len(h) for h in hits]),
                        column(STRIPS3, strips(np.concatenate(rays).reshape(-1, 2, 3)), [len(r) for r in rays]),
                    ],
                )
                rows.clear()

    def _draw_poses(self, rid: str, info: RobotDrawing, rows: Rows) -> None:
        rec = self.canvas.rec
        poses = [it[0] for it in rows.items]
        pos = np.array([p.position for p in poses], dtype=float)
        lin = np.array([p.linear for p in poses], dtype=float)
        quat = np.array([p.quaternion for p in poses], dtype=float)[:, [1, 2, 3, 0]]  # w, x, y, z -> x, y, z, w
        received = np.array([it[1] for it in rows.items], dtype=np.int64)
        times = rows.times()
        shown = pos
        if self.clock is not None and (received > 0).all():
            # Eq. 8: moved on by velocity x the time since arrival (capped), as of this drawing
            age = np.clip((self.clock() - received) * 1e-9, 0.0, EXTRAPOLATION_CAP_S)
            shown = pos + lin * age[:, None]
            send(rec, f"plots/age/{rid}", times, [scalars(SCALARS, age * 1e3)])
        send(rec, f"world/robots/{rid}/base", times, transforms(shown, quat))
        speed = np.stack([np.hypot(lin[:, 0], lin[:, 1]), np.array([p.angular[2] for p in poses], dtype=float)], axis=1)
        send(rec, f"plots/speed/{rid}", times, [scalars(SCALARS, speed)])
        for name, grid in self.grids.items():
            entity = f"map/{name}/robots/{rid}"
            if self.canvas.once(entity):
                rec.log(
                    entity,
                    rr.Points2D.from_fields(
                        radii=max(2.0, info.radius / grid.resolution), colors=[info.color], labels=[rid]
                    ),
                    static=True,
                )
            send(rec, entity, times, [column(POSITIONS2, vectors(world_to_map_pixels(grid, pos[:, :2]), 2))])
        rows.clear()

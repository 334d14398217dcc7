"""Map fabric messages to Rerun log calls: one function per kind of data, shared by live view and export.

:class:`WorldLogger` takes ``(key, message, log_time_ns)`` in the order they
arrived (live from Zenoh, or from an MCAP recording) and logs them to a
``rerun.RecordingStream``. It keeps only what drawing needs (the latest base
pose to put scans in the world frame, stream rates, the latest map for the map
view's overlay). The geometry it needs (:func:`scan_world_points`, :func:`grid_rgb`,
:func:`world_to_map_pixels`, ...) is pure and lives in :mod:`user_peer.geometry`, re-exported here.

Entity layout::

    world/robots/{id}/base          Transform3D of a mobile base (from its pose) + body
    world/robots/{id}/links/{n}     arm shapes, placed by FK from the joints
    world/robots/{id}/skeleton      arm joint origins as a line strip
    world/robots/{id}/scan          LIDAR hits (Points3D) and  .../scan/rays (LineStrips3D), world frame
    world/robots/{id}/path          planned path (LineStrips3D)
    world/robots/{id}/label         ownership label at the robot
    world/objects/{id}              scene objects (target sphere, goal pointer)
    map/{name}                      occupancy grid image; map/{name}/paths/{id}, map/{name}/robots/{id}
    plots/joints/{id}/{joint}       joint angles (deg);  plots/joint_speed/..., plots/speed/{id}/{v,omega}
    plots/rates/{label}             stream rates (Hz) over a 1 s window
    events                          TextLog of events and ownership changes
"""

from __future__ import annotations

import math
from collections import defaultdict, deque
from dataclasses import dataclass
from typing import Any, Callable, Iterable

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from fabric import keys
from fabric.interfaces import Event, JointState, OccupancyGrid, OwnershipRecord, Path, Pose, Scan
from user_peer.arm_geometry import ArmGeometry, Placement
from user_peer.geometry import EXTRAPOLATION_CAP_S, grid_rgb, scan_world_points, shown_position, world_to_map_pixels, yaw_of
from user_peer.geometry import compose as _compose
from user_peer.geometry import quat_xyzw as _quat_xyzw

__all__ = [
    "RobotDrawing",
    "WorldLogger",
    "blueprint",
    "scan_world_points",
    "grid_rgb",
    "world_to_map_pixels",
    "yaw_of",
    "shown_position",
    "EXTRAPOLATION_CAP_S",
    "TIMELINE_SIM",
    "TIMELINE_WALL",
]

TIMELINE_SIM = "sim_time"
TIMELINE_WALL = "wall_time"

ROBOT_COLORS = [(230, 120, 40), (40, 140, 230), (90, 200, 90), (200, 80, 200), (230, 200, 40)]


@dataclass
class RobotDrawing:
    """What the viewer knows about one robot: its kind and how to draw it.

    Built on the user's side from the robot descriptions (:class:`user_peer.catalog.RobotCatalog`); not the sim's
    ``RobotInfo`` message, which describes a robot of the world over the wire.
    """

    id: str
    type: str = ""
    kind: str = ""  # "arm" or "mobile"; "" until known
    arm: ArmGeometry | None = None
    base: Placement | None = None  # an arm's base in the world (fixed)
    radius: float = 0.25  # mobile footprint radius
    height: float = 0.3
    lidar_offset: tuple[float, float, float] = (0.0, 0.0, 0.3)
    sonar: tuple[float, float, float, float] | None = None  # ring centre x, y, height, radius (robot frame)
    color: tuple[int, int, int] = (230, 120, 40)


# --------------------------------------------------------------------------- blueprint


def blueprint() -> rrb.Blueprint:
    """3D world on the left; map view, plots and events on the right."""
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(name="world", origin="world"),
            rrb.Vertical(
                rrb.Spatial2DView(name="map", origin="map"),
                rrb.Tabs(
                    rrb.TimeSeriesView(name="joint angles (deg)", origin="plots/joints"),
                    rrb.TimeSeriesView(name="joint speeds (deg/s)", origin="plots/joint_speed"),
                    rrb.TimeSeriesView(name="base speed", origin="plots/speed"),
                    rrb.TimeSeriesView(name="stream rates (Hz)", origin="plots/rates"),
                ),
                rrb.TextLogView(name="events", origin="events"),
                row_shares=[3, 3, 1],
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=False,
    )


# --------------------------------------------------------------------------- the logger


class _Rates:
    """Messages per second per label over a sliding window, from log times (ns)."""

    def __init__(self, window_s: float = 1.0) -> None:
        self.window = int(window_s * 1e9)
        self.times: dict[str, deque[int]] = defaultdict(deque)

    def add(self, label: str, t_ns: int) -> float:
        d = self.times[label]
        d.append(t_ns)
        while d and d[0] < t_ns - self.window:
            d.popleft()
        return len(d) * 1e9 / self.window


class WorldLogger:
    """Logs a world's messages to one Rerun recording; the same code serves ``view`` and ``export``.

    ``drawing(id, hint)`` is asked once per robot the first time it appears, with a hint dict
    (``joint_names`` for arms, ``mobile`` for robots with a pose/scan) and returns a :class:`RobotDrawing`.
    ``max_hz`` thins out 3D and plot updates per key (0: log everything).
    """

    def __init__(
        self,
        rec: rr.RecordingStream,
        *,
        drawing: Callable[[str, dict], RobotDrawing] | None = None,
        max_hz: float = 30.0,
        rate_period_s: float = 0.5,
        clock: Callable[[], int] | None = None,
    ) -> None:
        self.rec = rec
        # live views: the clock that stamped log_time_ns when a message arrived (Eq. 8 ages are now - arrival);
        # None (export from a recording): no extrapolation, nothing is "now"
        self.clock = clock
        self.drawing = drawing or (lambda rid, hint: RobotDrawing(rid))
        self.robots: dict[str, RobotDrawing] = {}
        self.poses: dict[str, Pose] = {}
        self.grids: dict[str, OccupancyGrid] = {}
        self.paths: dict[str, Path] = {}
        self.owners: dict[str, OwnershipRecord] = {}
        self.min_dt = int(1e9 / max_hz) if max_hz > 0 else 0
        self._last: dict[str, int] = {}
        self._rates = _Rates()
        self._rate_logged: dict[str, int] = {}
        self.rate_period = int(rate_period_s * 1e9)
        self._static_done: set[str] = set()
        self.counts: dict[str, int] = defaultdict(int)
        self.skipped = 0

    # ------------------------------------------------------------------ entry point

    def log(self, key: str, msg: Any, log_time_ns: int) -> bool:
        """Log one message; returns False when the key is not something the viewer draws."""
        try:
            p = keys.parse(key)
        except ValueError:
            return False
        label = self._rate_label(p)
        rate = self._rates.add(label, log_time_ns)
        self._set_time(msg, log_time_ns)
        if log_time_ns - self._rate_logged.get(label, -(10**19)) >= self.rate_period:
            self._rate_logged[label] = log_time_ns
            self.rec.log(f"plots/rates/{label}", rr.Scalars(rate))
        handled = self._dispatch(p, msg, key, log_time_ns)
        if handled:
            self.counts[type(msg).__name__] += 1
        return handled

    def _rate_label(self, p: keys.ParsedKey) -> str:
        if p.category == "robot":
            return f"{p.subject}/{p.leaf}"
        if p.category == "cmd":
            return f"{p.subject}/cmd_{p.leaf}"
        return f"{p.category}/{p.subject}" if p.subject else p.category

    def _set_time(self, msg: Any, log_time_ns: int) -> None:
        header = getattr(msg, "header", None)
        wall = header.wall_ns if header is not None and header.wall_ns > 0 else log_time_ns
        self.rec.set_time(TIMELINE_WALL, timestamp=np.datetime64(int(wall), "ns"))
        if header is not None and header.stamp > 0:
            self.rec.set_time(TIMELINE_SIM, duration=float(header.stamp))

    def _due(self, key: str, t_ns: int) -> bool:
        if self.min_dt <= 0:
            return True
        last = self._last.get(key)
        if last is not None and t_ns - last < self.min_dt:
            self.skipped += 1
            return False
        self._last[key] = t_ns
        return True

    def _dispatch(self, p: keys.ParsedKey, msg: Any, key: str, t: int) -> bool:
        if p.category == "robot":
            if isinstance(msg, JointState):
                return self.log_joints(p.subject, msg, due=self._due(key, t))
            if isinstance(msg, Pose):
                return self.log_pose(p.subject, msg, due=self._due(key, t), received_ns=t)
            if isinstance(msg, Scan) and p.leaf == "sonar":
                return self.log_sonar(p.subject, msg) if self._due(key, t) else True
            if isinstance(msg, Scan):
                return self.log_scan(p.subject, msg) if self._due(key, t) else True
            if isinstance(msg, Path):
                return self.log_path(p.subject, msg)
        elif p.category == "cmd" and p.leaf == "path":
            body = getattr(msg, "body", None)
            if isinstance(body, Path):
                return self.log_path(p.subject, body)
        elif p.category == "object" and isinstance(msg, Pose):
            return self.log_object(p.subject, msg) if self._due(key, t) else True
        elif p.category == "map" and isinstance(msg, OccupancyGrid):
            return self.log_map(p.subject, msg)
        elif p.category == "own" and isinstance(msg, OwnershipRecord):
            return self.log_ownership(msg)
        elif p.category == "event" and isinstance(msg, Event):
            return self.log_event("/".join((p.subject, *p.rest[1:])) if p.rest else p.subject, msg, any_login=p.subject == keys.DECODE)
        return False

    # ------------------------------------------------------------------ robots

    def _robot(self, rid: str, hint: dict) -> RobotDrawing:
        info = self.robots.get(rid)
        if info is None or (not info.kind and hint):
            info = self.drawing(rid, hint)
            if not info.color or info.color == RobotDrawing.color:
                info.color = ROBOT_COLORS[len(self.robots) % len(ROBOT_COLORS)]
            self.robots[rid] = info
        return info

    def log_joints(self, rid: str, js: JointState, *, due: bool = True) -> bool:
        info = self._robot(rid, {"joint_names": js.names})
        if not due:
            return True
        for name, q, dq in zip(js.names, js.q, js.dq):
            self.rec.log(f"plots/joints/{rid}/{name}", rr.Scalars(math.degrees(float(q))))
            self.rec.log(f"plots/joint_speed/{rid}/{name}", rr.Scalars(math.degrees(float(dq))))
        arm = info.arm
        if arm is None or len(js.q) != len(arm.joint_names):
            return True
        q = np.asarray(js.q, dtype=float)
        origins = [(_compose(info.base, pl))[0] for pl in arm.fk(q)]
        self.rec.log(f"world/robots/{rid}/skeleton", rr.LineStrips3D([origins], radii=0.006, colors=[info.color]))
        self.rec.log(f"world/robots/{rid}/joints", rr.Points3D(origins, radii=0.012, colors=[(60, 60, 60)]))
        for shape, placement in arm.shape_placements(q):
            path = f"world/robots/{rid}/links/{rr.escape_entity_path_part(shape.name)}"
            t, quat = _compose(info.base, placement)
            self.rec.log(path, rr.Transform3D(translation=t, quaternion=rr.Quaternion(xyzw=quat)))
            if path not in self._static_done:
                self._static_done.add(path)
                self._log_shape(path, shape)
        self._label(rid, origins[0])
        return True

    def _log_shape(self, path: str, shape) -> None:
        color = [shape.color]
        if shape.kind == "box":
            arch = rr.Boxes3D(half_sizes=[shape.size], colors=color, fill_mode="solid")
        elif shape.kind == "sphere":
            arch = rr.Ellipsoids3D(half_sizes=[[shape.size[0]] * 3], colors=color, fill_mode="solid")
        elif shape.kind == "cylinder":
            arch = rr.Cylinders3D(lengths=[shape.size[1]], radii=[shape.size[0]], colors=color, fill_mode="solid")
        elif shape.kind == "capsule":
            # Rerun's capsules run along +z from the origin; URDF's are centred.
            arch = rr.Capsules3D(lengths=[shape.size[1]], radii=[shape.size[0]], translations=[[0, 0, -shape.size[1] / 2]], colors=color)
        elif shape.kind == "mesh" and shape.mesh_path:
            try:
                arch = rr.Asset3D(path=shape.mesh_path)
            except Exception:
                return
        else:
            return
        self.rec.log(f"{path}/shape", arch, static=True)

    def log_pose(self, rid: str, pose: Pose, *, due: bool = True, received_ns: int = 0) -> bool:
        """A base's pose is drawn where it is by now: moved on by velocity x the time since it arrived
        (paper Eq. 8, capped; local clock only)."""
        info = self._robot(rid, {"mobile": True} if not self.robots.get(rid) or not self.robots[rid].arm else {})
        if info.arm is not None:
            # An arm's pose key carries its flange pose: draw it as a frame marker.
            if due:
                self.rec.log(
                    f"world/robots/{rid}/flange",
                    rr.Transform3D(translation=pose.position, quaternion=rr.Quaternion(xyzw=_quat_xyzw(pose.quaternion))),
                )
                if f"{rid}/flange" not in self._static_done:
                    self._static_done.add(f"{rid}/flange")
                    self.rec.log(f"world/robots/{rid}/flange/axes", rr.TransformAxes3D(0.05), static=True)
            return True
        self.poses[rid] = pose
        if not due:
            return True
        path = f"world/robots/{rid}/base"
        now_ns = self.clock() if self.clock is not None and received_ns > 0 else 0
        shown, age = shown_position(pose, received_ns, now_ns)
        if age is not None:
            self.rec.log(f"plots/age/{rid}", rr.Scalars(age * 1e3))
        self.rec.log(path, rr.Transform3D(translation=shown, quaternion=rr.Quaternion(xyzw=_quat_xyzw(pose.quaternion))))
        if path not in self._static_done:
            self._static_done.add(path)
            r, h = info.radius, info.height
            self.rec.log(
                f"{path}/body",
                rr.Cylinders3D(lengths=[h], radii=[r], centers=[[0, 0, h / 2]], colors=[info.color], fill_mode="solid"),
                static=True,
            )
            self.rec.log(f"{path}/heading", rr.Arrows3D(vectors=[[r * 1.4, 0, 0]], origins=[[0, 0, h + 0.02]], colors=[(20, 20, 20)]), static=True)
        self.rec.log(f"plots/speed/{rid}/v", rr.Scalars(float(np.hypot(pose.linear[0], pose.linear[1]))))
        self.rec.log(f"plots/speed/{rid}/omega", rr.Scalars(float(pose.angular[2])))
        for name, grid in self.grids.items():
            uv = world_to_map_pixels(grid, pose.position[:2])
            self.rec.log(f"map/{name}/robots/{rid}", rr.Points2D(uv, radii=max(2.0, info.radius / grid.resolution), colors=[info.color], labels=[rid]))
        self._label(rid, np.array([pose.position[0], pose.position[1], info.height + 0.25]))
        return True

    def log_scan(self, rid: str, scan: Scan) -> bool:
        info = self._robot(rid, {"mobile": True})
        origin, pts, hit = scan_world_points(scan, self.poses.get(rid), info.lidar_offset)
        self.rec.log(f"world/robots/{rid}/scan", rr.Points3D(pts[hit], radii=0.02, colors=[(230, 40, 40)]))
        step = max(1, len(pts) // 60)
        rays = [[origin, p] for p in pts[::step]]
        self.rec.log(f"world/robots/{rid}/scan/rays", rr.LineStrips3D(rays, radii=0.002, colors=[(240, 150, 150)]))
        return True

    def log_sonar(self, rid: str, scan: Scan) -> bool:
        """The ultrasonic ring: each sensor's echo as a point, rays from the ring's rim."""
        info = self._robot(rid, {"mobile": True})
        cx, cy, h, radius = info.sonar or (0.0, 0.0, 0.12, 0.26)
        # ranges are measured from the rim: from the ring's centre they are `radius` longer
        ranges = np.where(np.isfinite(scan.ranges), scan.ranges + radius, np.inf)
        centred = Scan.from_ranges(ranges, angle_min=scan.angle_min, angle_increment=scan.angle_increment,
                                   range_max=scan.range_max + radius, header=scan.header)
        origin, pts, hit = scan_world_points(centred, self.poses.get(rid), (cx, cy, h))
        self.rec.log(f"world/robots/{rid}/sonar", rr.Points3D(pts[hit], radii=0.03, colors=[(40, 170, 230)]))
        self.rec.log(f"world/robots/{rid}/sonar/rays", rr.LineStrips3D([[origin, q] for q in pts[hit]], radii=0.003, colors=[(120, 200, 240)]))
        return True

    def log_path(self, rid: str, path: Path) -> bool:
        info = self._robot(rid, {})
        self.paths[rid] = path
        if len(path) == 0:
            self.rec.log(f"world/robots/{rid}/path", rr.Clear(recursive=False))
            return True
        pts = np.stack([path.x, path.y, np.full(len(path), 0.02)], axis=1)
        self.rec.log(f"world/robots/{rid}/path", rr.LineStrips3D([pts], radii=0.015, colors=[info.color]))
        for name, grid in self.grids.items():
            self.rec.log(f"map/{name}/paths/{rid}", rr.LineStrips2D([world_to_map_pixels(grid, pts[:, :2])], colors=[info.color]))
        return True

    def log_object(self, oid: str, pose: Pose) -> bool:
        path = f"world/objects/{oid}"
        self.rec.log(path, rr.Transform3D(translation=pose.position, quaternion=rr.Quaternion(xyzw=_quat_xyzw(pose.quaternion))))
        if path not in self._static_done:
            self._static_done.add(path)
            if "goal" in oid:
                self.rec.log(f"{path}/shape", rr.Arrows3D(vectors=[[0.5, 0, 0]], colors=[(40, 200, 80)], labels=[oid]), static=True)
            else:
                self.rec.log(f"{path}/shape", rr.Ellipsoids3D(half_sizes=[[0.02, 0.02, 0.02]], colors=[(40, 200, 80)], fill_mode="solid", labels=[oid]), static=True)
        for name, grid in self.grids.items():
            if "goal" in oid:
                self.rec.log(f"map/{name}/objects/{oid}", rr.Points2D(world_to_map_pixels(grid, pose.position[:2]), radii=4.0, colors=[(40, 200, 80)], labels=[oid]))
        return True

    def log_map(self, name: str, grid: OccupancyGrid) -> bool:
        self.grids[name] = grid
        self.rec.log(f"map/{name}", rr.Image(grid_rgb(grid)))
        for rid, path in self.paths.items():
            if len(path):
                xy = np.stack([path.x, path.y], axis=1)
                self.rec.log(f"map/{name}/paths/{rid}", rr.LineStrips2D([world_to_map_pixels(grid, xy)], colors=[self._robot(rid, {}).color]))
        return True

    # ------------------------------------------------------------------ ownership and events

    def _label(self, rid: str, at: np.ndarray) -> None:
        rec = self.owners.get(rid)
        text = f"{rid}: " + (f"{rec.owner} (epoch {rec.epoch})" if rec and rec.owner else "free")
        if rec and rec.queue:
            text += f", waiting {', '.join(rec.queue)}"
        self.rec.log(f"world/robots/{rid}/label", rr.Points3D([at], radii=0.005, labels=[text], colors=[(0, 0, 0)]))

    def log_ownership(self, rec: OwnershipRecord) -> bool:
        before = self.owners.get(rec.object)
        self.owners[rec.object] = rec
        if before is None or before.owner != rec.owner or before.epoch != rec.epoch:
            who = rec.owner or "nobody"
            self.rec.log("events", rr.TextLog(f"{rec.object}: owned by {who} (epoch {rec.epoch}, {rec.state})", level="INFO"))
        self.rec.log(f"ownership/{rec.object}", rr.TextDocument(f"owner: {rec.owner or '-'}\nepoch: {rec.epoch}\nqueue: {', '.join(rec.queue) or '-'}\nstate: {rec.state}"))
        return True

    def log_event(self, where: str, ev: Event, *, any_login: bool = False) -> bool:
        """One line of the event log; ``any_login``: it came on a key any login may write (a decode report),
        so it is marked as such: its kind, user and object are the writer's say-so (docs/security.md)."""
        level = {"debug": "DEBUG", "info": "INFO", "warning": "WARN", "error": "ERROR"}.get(ev.severity, "INFO")
        who = f" [{ev.user}]" if ev.user else ""
        obj = f" {ev.object}:" if ev.object else ""
        mark = f"(unverified: {where}, any login may write it) " if any_login else ""
        self.rec.log("events", rr.TextLog(f"{mark}{ev.kind}{who}{obj} {ev.reason}".strip(), level=level))
        return True

    def log_scene(self, boxes: Iterable[Any], name: str = "scene") -> None:
        """The static scene (walls, shelves, tables) once, as boxes: see :mod:`user_peer.scene_geometry`."""
        boxes = list(boxes)
        if not boxes:
            return
        self.rec.log(
            f"world/{name}",
            rr.Boxes3D(
                centers=[b.center for b in boxes],
                half_sizes=[b.half_size for b in boxes],
                quaternions=[rr.Quaternion(xyzw=b.quat_xyzw) for b in boxes],
                colors=[b.rgba for b in boxes],
                labels=[b.name for b in boxes],
                fill_mode="solid",
                show_labels=False,
            ),
            static=True,
        )

    def log_all(self, items: Iterable[tuple[str, Any, int]]) -> int:
        """Log a sequence of (key, message, log_time_ns); returns how many were drawn."""
        return sum(1 for key, msg, t in items if self.log(key, msg, t))

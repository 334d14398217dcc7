"""Map fabric messages to Rerun log calls, shared by the live view and export: :class:`WorldLogger`.

:class:`WorldLogger` takes ``(key, message, log_time_ns)`` in the order they arrived (live from Zenoh, or from
an MCAP recording) and hands each to the drawer for its kind (:mod:`user_peer.drawing`: one module each for
the layout, the intake, arms, joint plots, bases, maps and paths, scene objects, ownership labels and events).
Frequent streams (joints, poses, scans, rates) are filed per stream and drawn at :meth:`WorldLogger.flush` as
columns, one ``send_columns`` per entity (:mod:`user_peer.rerun_columns`); what never moves (link shapes,
bodies, styles, plot names) is logged once, static. It keeps only what drawing needs (the latest base pose to
put scans in the world frame, the latest map for the map view's overlay). The entity layout is in
:mod:`user_peer.drawing.layout`. The geometry it needs (:func:`scan_world_points`, :func:`grid_rgb`,
:func:`world_to_map_pixels`, ...) is pure and lives in :mod:`user_peer.geometry`, re-exported here, as are the
layout's names.
"""

from __future__ import annotations

from collections import defaultdict
from typing import Any, Callable, Iterable

import rerun as rr

from fabric import keys
from fabric.interfaces import Event, JointState, OccupancyGrid, OwnershipRecord, Path, Pose, Scan
from user_peer.drawing.arm import ArmDrawer
from user_peer.drawing.base import BaseDrawer
from user_peer.drawing.canvas import Canvas
from user_peer.drawing.intake import Intake, RateMeter, message_times
from user_peer.drawing.joints import JointDrawer
from user_peer.drawing.labels import OwnershipDrawer
from user_peer.drawing.layout import PLOT_WINDOW_S, TIMELINE_SIM, TIMELINE_WALL, blueprint, framing
from user_peer.drawing.maps import MapDrawer
from user_peer.drawing.objects import ObjectDrawer
from user_peer.drawing.robots import ROBOT_COLORS, RobotDrawing
from user_peer.geometry import (
    EXTRAPOLATION_CAP_S,
    grid_rgb,
    scan_world_points,
    shown_position,
    world_to_map_pixels,
    yaw_of,
)

__all__ = [
    "RobotDrawing",
    "WorldLogger",
    "blueprint",
    "framing",
    "scan_world_points",
    "grid_rgb",
    "world_to_map_pixels",
    "yaw_of",
    "shown_position",
    "EXTRAPOLATION_CAP_S",
    "PLOT_WINDOW_S",
    "ROBOT_COLORS",
    "TIMELINE_SIM",
    "TIMELINE_WALL",
]


class WorldLogger:
    """Logs a world's messages to one Rerun recording; the same code serves ``view`` and ``export``.

    ``drawing(id, hint)`` is asked once per robot the first time it appears, with a hint dict
    (``joint_names`` for arms, ``mobile`` for robots with a pose/scan) and returns a :class:`RobotDrawing`.
    ``max_hz`` thins out 3D and plot updates per key (0: log everything). ``clock``: the clock that stamped
    ``log_time_ns`` when a message arrived (live views: Eq. 8 ages are now - arrival); None (an export from a
    recording): no extrapolation, nothing is "now".

    :meth:`log` only files what a message brings under its stream; :meth:`flush` draws everything filed
    since the last flush, one ``send_columns`` per entity (:mod:`user_peer.rerun_columns`). The live viewer
    flushes once per window (0.1 s); a caller that never flushes still gets a flush every ``max_pending``
    messages. Rare messages (maps, paths, objects, ownership, events) are logged at once, row by row.
    """

    def __init__(
        self,
        rec: rr.RecordingStream,
        *,
        drawing: Callable[[str, dict], RobotDrawing] | None = None,
        max_hz: float = 30.0,
        rate_period_s: float = 0.5,
        clock: Callable[[], int] | None = None,
        max_pending: int = 4000,
    ) -> None:
        self.rec = rec
        self.drawing = drawing or (lambda rid, hint: RobotDrawing(rid))
        self.max_pending = max_pending
        self.robots: dict[str, RobotDrawing] = {}
        self.counts: dict[str, int] = defaultdict(int)  # messages drawn, per type
        self.canvas = Canvas(rec)
        self.intake = Intake(max_hz)
        self.rates = RateMeter(rate_period_s)
        self.labels = OwnershipDrawer(self.canvas)
        self.maps = MapDrawer(self.canvas)
        self.objects = ObjectDrawer(self.canvas, self.maps.grids)
        self.arm = ArmDrawer(self.canvas, self.labels)
        self.joints = JointDrawer(self.canvas, self.arm)
        self.bases = BaseDrawer(self.canvas, self.labels, self.maps.grids, clock)
        # what drawing keeps, by name: the latest base poses, maps, paths and ownership records
        self.poses, self.grids, self.paths, self.owners = (
            self.bases.poses,
            self.maps.grids,
            self.maps.paths,
            self.labels.owners,
        )

    @property
    def skipped(self) -> int:
        """Messages thinned out by ``max_hz``."""
        return self.intake.skipped

    @property
    def pending(self) -> int:
        """Rows filed since the last flush."""
        return self.canvas.pending

    def log(self, key: str, msg: Any, log_time_ns: int) -> bool:
        """File one message for drawing; returns False when the key is not something the viewer draws."""
        parsed = self.intake.parse(key)
        if parsed is None:
            return False
        p, label = parsed
        self.canvas.now = message_times(msg, log_time_ns)
        if self.rates.count(label, log_time_ns):
            self.canvas.pending += 1
        if p.category == "robot":
            handled = self._robot_message(p, msg, key, log_time_ns)
        else:
            handled = self._world_message(p, msg, key, log_time_ns)
        if handled:
            self.counts[type(msg).__name__] += 1
        if self.canvas.pending >= self.max_pending:
            self.flush()
        return handled

    def _robot_message(self, p: keys.ParsedKey, msg: Any, key: str, t: int) -> bool:
        if isinstance(msg, JointState):
            return self.log_joints(p.subject, msg, due=self.intake.due(key, t))
        if isinstance(msg, Pose):
            return self.log_pose(p.subject, msg, due=self.intake.due(key, t), received_ns=t)
        if isinstance(msg, Scan):
            return self.log_scan(p.subject, msg, sonar=p.leaf == "sonar") if self.intake.due(key, t) else True
        if isinstance(msg, Path):
            self.canvas.set_time()
            return self.log_path(p.subject, msg)
        return False

    def _world_message(self, p: keys.ParsedKey, msg: Any, key: str, t: int) -> bool:
        if p.category == "cmd" and p.leaf == "path":
            body = getattr(msg, "body", None)
            if isinstance(body, Path):
                self.canvas.set_time()
                return self.log_path(p.subject, body)
        elif p.category == "object" and isinstance(msg, Pose):
            if not self.intake.due(key, t):
                return True
            self.canvas.set_time()
            return self.log_object(p.subject, msg)
        elif p.category == "map" and isinstance(msg, OccupancyGrid):
            self.canvas.set_time()
            return self.log_map(p.subject, msg)
        elif p.category == "own" and isinstance(msg, OwnershipRecord):
            self.canvas.set_time()
            return self.log_ownership(msg)
        elif p.category == "event" and isinstance(msg, Event):
            self.canvas.set_time()
            return self.log_event(
                "/".join((p.subject, *p.rest[1:])) if p.rest else p.subject, msg, any_login=p.subject == keys.DECODE
            )
        return False

    def _robot(self, rid: str, hint: dict) -> RobotDrawing:
        """The robot's drawing, made the first time it is seen (or again once its kind is learnt), and its
        static parts logged then."""
        info = self.robots.get(rid)
        if info is None or (not info.kind and hint):
            info = self.drawing(rid, hint)
            if not info.color or info.color == RobotDrawing.color:
                info.color = ROBOT_COLORS[len(self.robots) % len(ROBOT_COLORS)]
            self.robots[rid] = info
            self.arm.static(rid, info)
            self.bases.static(rid, info)
        return info

    def log_joints(self, rid: str, js: JointState, *, due: bool = True) -> bool:
        """File a JointState: an arm's joint plots and 3D pose, or a base's wheel angles (their own plot)."""
        info = self._robot(rid, {"joint_names": js.names})
        if due:
            self.joints.file(rid, info, js)
        return True

    def log_pose(self, rid: str, pose: Pose, *, due: bool = True, received_ns: int = 0) -> bool:
        """File a pose: an arm's flange frame, or a mobile base (drawn where it is by now: paper Eq. 8)."""
        known = self.robots.get(rid)
        info = self._robot(rid, {"mobile": True} if not known or not known.arm else {})
        if info.arm is None:
            self.bases.file_pose(rid, pose, received_ns, due=due)
        elif due:
            self.arm.file_flange(rid, pose)
        return True

    def log_scan(self, rid: str, scan: Scan, *, sonar: bool = False) -> bool:
        """File a LIDAR scan (or the ultrasonic ring's): its hits and rays in the world frame."""
        self.bases.file_scan(rid, self._robot(rid, {"mobile": True}), scan, sonar=sonar)
        return True

    def log_path(self, rid: str, path: Path) -> bool:
        return self.maps.log_path(rid, path, self._robot(rid, {}).color)

    def log_object(self, oid: str, pose: Pose) -> bool:
        return self.objects.log_object(oid, pose)

    def log_map(self, name: str, grid: OccupancyGrid) -> bool:
        return self.maps.log_map(name, grid, lambda rid: self._robot(rid, {}).color)

    def log_ownership(self, rec: OwnershipRecord) -> bool:
        return self.labels.log_ownership(rec)

    def log_event(self, where: str, ev: Event, *, any_login: bool = False) -> bool:
        """One line of the event log (see :meth:`OwnershipDrawer.log_event`)."""
        return self.labels.log_event(where, ev, any_login=any_login)

    def log_scene(self, boxes: Iterable[Any], name: str = "scene") -> None:
        """The static scene (walls, shelves, tables) once, as boxes: see :mod:`user_peer.scene_geometry`."""
        self.objects.log_scene(boxes, name)

    def flush(self) -> int:
        """Draw everything filed since the last flush; returns how many rows went out."""
        n = self.canvas.pending
        if not n:
            return 0
        self.joints.flush(self.robots)
        self.bases.flush(self.robots)
        self.arm.flush()
        self.rates.flush(self.rec)
        self.canvas.pending = 0
        return n

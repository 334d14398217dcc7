"""Mapping and navigation served over Zenoh: the paper's Test B.

:func:`register_navigation` attaches a :class:`NavigationService` to a peer's
:class:`~fabric.session.Fabric`:

* mapping mode: it listens to the robots' ``scan`` and ``pose`` keys and, while
  mapping is on, folds every scan (taken at the pose nearest in sim time, from
  where the LIDAR sits on the robot) into a log-odds grid as the user drives;
  each robot's LIDAR mounting and radius are learnt from the sim's world
  description (``srv/world``) unless given;
* ``rf/{world}/srv/map/{name}`` (and ``.../{name}/{peer_id}`` for this peer only; :class:`MapRequest`): start/stop mapping, build the binary
  map with a threshold and publish it on ``rf/{world}/map/{name}``, get, reset,
  save/load (only inside ``maps_dir``), set a map, status;
* ``rf/{world}/srv/plan/{robot}`` (:class:`PlanRequest`): plan from the robot's current
  pose (or a given start) to the ``goal`` object's pose (or a given goal) with
  Hybrid A* or OMPL, publish the path on ``rf/{world}/robot/{robot}/path`` and
  return it. Following it is the user's decision: they send it on ``cmd/path``.

Every refusal (unknown robot, no pose yet, no map, goal outside the map or in an
obstacle, no path) is a :class:`~fabric.session.ServiceError` reply with the
reason; nothing here can make a query time out or take the peer down. This is
the only module of the package that touches the session.
"""

from __future__ import annotations

import logging
import math
import threading
from collections import deque
from dataclasses import replace
from pathlib import Path as FsPath
from typing import Any


from fabric import keys
from fabric.messages import OccupancyGrid, Path, Pose, Scan
from fabric.rate import Clock, MonotonicClock
from fabric.session import Fabric, ServiceError, undeclare_all

from .costmap import Costmap, build_costmap
from .errors import NavigationError
from .geometry import yaw_from_quaternion
from .grid import check_grid, is_empty
from .mapio import load_map, save_map
from .mapping import MapperConfig, OccupancyMapper
from .messages import MapReply, MapRequest, PlanReply, PlanRequest, empty_grid
from .model import VehicleModel
from .planner import PlannerSettings, plan_path

log = logging.getLogger("robofabric.navigation")

__all__ = ["NavigationService", "register_navigation"]

POSE_HISTORY = 64
MAX_ROBOTS = 64
"""Robots whose poses are kept when no world description says which exist (a flood of made-up ids stops here)."""


class NavigationService:
    """Mapping + planning for one world. A context manager; ``close()`` is idempotent.

    ``robots``: the robot ids to map and plan for; None means every robot seen on the world.
    ``mapper_config``: the grid (default 20 m x 20 m at 5 cm around the origin). ``settings``: vehicle and
    planner defaults. ``map_name``: the map built from scans. ``goal_object``: the scene object whose pose is
    the default goal. ``maps_dir``: the only folder ``save``/``load`` may touch (None: disabled).
    ``mapping``: accumulate scans from the start. ``sensor_offset`` (all robots) / ``sensor_offsets`` (per
    robot): LIDAR mounting (x, y, yaw) in the robot frame; otherwise learnt from ``srv/world`` when
    ``discover``, else (0, 0, 0). ``clock``: for the discovery's rate limit.
    """

    def __init__(
        self,
        fabric: Fabric,
        *,
        robots: list[str] | None = None,
        mapper_config: MapperConfig | None = None,
        settings: PlannerSettings | None = None,
        map_name: str = "map",
        goal_object: str = "goal",
        maps_dir: str | FsPath | None = None,
        mapping: bool = True,
        sensor_offset: tuple[float, float, float] | None = None,
        sensor_offsets: dict[str, tuple[float, float, float]] | None = None,
        discover: bool = True,
        clock: Clock | None = None,
    ) -> None:
        self.fabric = fabric
        self.world = fabric.world
        self.robots = None if robots is None else [keys.validate_id(r, what="robot id") for r in robots]
        self.settings = settings or PlannerSettings()
        self.map_name = keys.validate_id(map_name, what="map name")
        self.goal_object = keys.validate_id(goal_object, what="object id")
        self.maps_dir = FsPath(maps_dir) if maps_dir is not None else None
        # where each robot's LIDAR sits on it, (x, y, yaw) in the robot frame: given per robot, given for all,
        # or learnt from the sim's world description (srv/world); (0, 0, 0) when nobody tells
        self.sensor_offset = sensor_offset
        self._offsets: dict[str, tuple[float, float, float]] = dict(sensor_offsets or {})
        self._radii: dict[str, float] = {}  # robot radius per robot, from the world description
        self._discover = bool(discover)
        self._clock = clock or MonotonicClock()
        self._first_seen: dict[str, float] = {}
        self._described: set[str] | None = None  # mobile robots of the world, once a sim described them
        self._discovery_started = -math.inf
        self._discovery_ended = -math.inf
        self._discovering = False
        self.mapper = OccupancyMapper(mapper_config)
        self.mapping = bool(mapping)
        self.maps: dict[str, OccupancyGrid] = {}
        self.counters: dict[str, int] = {
            "scans": 0,  # folded into the map
            "scans_ignored": 0,  # arrived while mapping was off
            "scans_without_pose": 0,
            "scans_waiting_for_sensor": 0,  # dropped while the sensor's mounting is being looked up
            "scans_rejected": 0,
            "plans": 0,
            "refusals": 0,
        }
        self._versions: dict[str, int] = {}
        self._costmaps: dict[tuple, Costmap] = {}
        self._poses: dict[str, deque[Pose]] = {}
        self._goal: Pose | None = None
        self._lock = threading.RLock()  # map and pose state
        self._plan_lock = threading.Lock()  # one plan at a time: planning is CPU-bound
        self._closed = False
        self._resources: list[Any] = []
        self._declare()

    # ------------------------------------------------------------------ lifecycle

    def _declare(self) -> None:
        f = self.fabric
        if self.robots is None:
            self._resources.append(f.subscribe(keys.robot_all(self.world), self._on_robot))
        else:
            for r in self.robots:
                self._resources.append(f.subscribe(keys.robot_pose(self.world, r), self._on_robot, expected=Pose))
                self._resources.append(f.subscribe(keys.robot_scan(self.world, r), self._on_robot, expected=Scan))
        self._resources.append(f.subscribe(keys.object_pose_all(self.world, self.goal_object), self._on_goal, expected=Pose, history=True))
        # srv/{map,plan}/{name}: the nearest compute peer; srv/{map,plan}/{name}/{peer_id}: this one (docs/compute.md)
        for peer in (None, f.peer_id):
            self._resources.append(f.serve(keys.srv_per_subject(self.world, "map", peer), self._on_map, expected=MapRequest))
            self._resources.append(f.serve(keys.srv_per_subject(self.world, "plan", peer), self._on_plan, expected=PlanRequest))

    def __enter__(self) -> "NavigationService":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Undeclare this service's subscribers and queryables (the session stays open); safe twice."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        undeclare_all(self._resources)

    # ------------------------------------------------------------------ inputs

    def _on_robot(self, key: str, msg: Any) -> None:
        parsed = keys.parse(key)
        robot = parsed.subject
        if parsed.category != "robot" or (self.robots is not None and robot not in self.robots):
            return
        if robot not in self._poses:  # nothing is kept for robots the world does not have
            known = self._described
            if (known is not None and robot not in known) or len(self._poses) >= MAX_ROBOTS:
                self.counters["unknown_robot"] = self.counters.get("unknown_robot", 0) + 1
                return
        if isinstance(msg, Pose) and parsed.leaf == "pose":
            with self._lock:
                if robot not in self._poses:
                    self._sensor_offset(robot)  # a new robot: look its sensor up before its scans come
                self._poses.setdefault(robot, deque(maxlen=POSE_HISTORY)).append(msg)
        elif isinstance(msg, Scan) and parsed.leaf == "scan":
            self._on_scan(robot, msg)

    def _pose_at(self, robot: str, stamp: float) -> Pose | None:
        """The pose nearest in sim time to ``stamp`` (the latest one when stamps are not set)."""
        hist = self._poses.get(robot)
        if not hist:
            return None
        if stamp <= 0.0:
            return hist[-1]
        return min(hist, key=lambda p: abs(p.header.stamp - stamp))

    def _on_scan(self, robot: str, scan: Scan) -> None:
        with self._lock:
            if not self.mapping or self._closed:
                self.counters["scans_ignored"] += 1
                return
            pose = self._pose_at(robot, scan.header.stamp)
            if pose is None:
                self.counters["scans_without_pose"] += 1
                return
            offset = self._sensor_offset(robot)
            if offset is None:
                self.counters["scans_waiting_for_sensor"] += 1
                return
            try:
                footprint = self._radii.get(robot, self.settings.vehicle.robot_radius)
                self.mapper.integrate_scan(scan, pose, sensor_offset=offset, footprint=footprint)
            except NavigationError as exc:
                self.counters["scans_rejected"] += 1
                log.warning("scan from %s rejected: %s", robot, exc)
                return
            self.counters["scans"] += 1

    # ------------------------------------------------------------------ robot descriptions

    def _sensor_offset(self, robot: str) -> tuple[float, float, float] | None:
        """The LIDAR mounting of ``robot``, or None while it is being looked up (call with the lock held)."""
        if robot in self._offsets:
            return self._offsets[robot]
        if self.sensor_offset is not None:
            return self.sensor_offset
        if not self._discover:
            return (0.0, 0.0, 0.0)
        now = self._clock.now()
        first = self._first_seen.setdefault(robot, now)
        if self._discovery_ended >= first:  # asked after this robot appeared, and nobody described it
            return (0.0, 0.0, 0.0)
        if not self._discovering and now - self._discovery_started >= 1.0:
            self._discovering = True
            self._discovery_started = now
            threading.Thread(target=self._run_discovery, name="nav-discovery", daemon=True).start()
        return None

    def _run_discovery(self) -> None:
        try:
            if not self._closed:
                self.discover_robots()
        except Exception as exc:  # a session closing under us: nothing learnt, nothing to report
            log.debug("robot discovery failed: %s", exc)
        finally:
            with self._lock:
                self._discovering = False
                self._discovery_ended = self._clock.now()

    def discover_robots(self, timeout: float = 2.0) -> int:
        """Learn each mobile robot's LIDAR mounting and radius from the sim peers' ``srv/world``; returns how many.

        The world description's message types belong to the sim peer; without it installed nothing is learnt.
        Explicit ``sensor_offsets`` are never overridden.
        """
        try:
            import sim_peer.messages  # noqa: F401  (registers WorldInfo with the codec)
        except ImportError:
            return 0
        try:
            replies = self.fabric.query(keys.srv(self.world, "world"), timeout=timeout, all_replies=True)
        except ServiceError:
            return 0
        found = 0
        with self._lock:
            known = set(self._described or ())
            for rep in replies:
                for r in getattr(rep.message, "robots", ()):
                    if getattr(r, "kind", "") != "mobile":
                        continue
                    known.add(r.id)
                    off = r.sensors.get("lidar_offset")
                    if isinstance(off, list) and len(off) >= 2 and r.id not in self._offsets:
                        self._offsets[r.id] = (float(off[0]), float(off[1]), 0.0)
                    radius = float(r.base_radius or r.base.get("radius", 0.0) or 0.0)
                    if radius > 0:
                        self._radii[r.id] = radius
                    found += 1
            if replies:
                self._described = known | set(self._poses)  # robots already followed stay
        return found

    def _on_goal(self, key: str, msg: Pose) -> None:
        with self._lock:
            self._goal = msg

    # ------------------------------------------------------------------ map service

    def _store(self, name: str, grid: OccupancyGrid) -> OccupancyGrid:
        """Keep ``grid`` as map ``name`` (stamped by this peer), drop stale costmaps, publish it."""
        key = keys.map_key(self.world, name)
        grid = replace(grid, header=self.fabric.header(key))
        with self._lock:
            self.maps[name] = grid
            self._versions[name] = self._versions.get(name, 0) + 1
            self._costmaps = {k: v for k, v in self._costmaps.items() if k[0] != name}
        self.fabric.publish(key, grid)
        return grid

    def _file(self, name: str) -> FsPath:
        if self.maps_dir is None:
            raise NavigationError("this compute peer has no maps folder: saving and loading are disabled")
        if not name or "/" in name or "\\" in name or name.startswith("."):
            raise NavigationError(f"map file name {name!r} must be a plain file name inside the maps folder")
        return self.maps_dir / name

    def build_map(self, name: str | None = None, threshold: float = 0.65) -> OccupancyGrid:
        """Threshold the accumulated scans into a binary map, keep it as ``name`` and publish it."""
        name = name or self.map_name
        with self._lock:
            if self.mapper.scans == 0:
                raise NavigationError(
                    "no scans accumulated yet: is mapping on and are the robots publishing scan and pose?"
                )
            grid = self.mapper.grid(threshold=threshold)
        return self._store(name, grid)

    def map_request(self, req: MapRequest) -> MapReply:
        """Handle one map request (also usable in-process, without Zenoh)."""
        name = keys.validate_id(req.name, what="map name")
        grid = empty_grid()
        file = ""
        a = req.action
        if a == "start":
            self.mapping = True
        elif a == "stop":
            self.mapping = False
        elif a == "reset":
            with self._lock:
                self.mapper.reset()
                self.maps.pop(name, None)
                self._costmaps = {k: v for k, v in self._costmaps.items() if k[0] != name}
        elif a == "build":
            grid = self.build_map(name, req.threshold)
        elif a == "get":
            with self._lock:
                stored = self.maps.get(name)
                if stored is not None:
                    grid = stored
                elif name == self.map_name and self.mapper.scans > 0:
                    grid = self.mapper.grid(header=self.fabric.header(keys.map_key(self.world, name)))
                else:
                    raise NavigationError(f"no map named {name!r} (build, load or set one first)")
        elif a == "save":
            with self._lock:
                stored = self.maps.get(name)
            if stored is None:
                raise NavigationError(f"no map named {name!r} to save (build, load or set one first)")
            path = save_map(stored, self._file(req.file or f"{name}.yaml"))
            file = path.name
        elif a == "load":
            path = self._file(req.file or f"{name}.yaml")
            grid = self._store(name, load_map(path))
            file = path.name
        elif a == "set":
            if req.grid.cells.size == 0:
                raise NavigationError("action 'set' needs a grid with cells")
            check_grid(req.grid)
            grid = self._store(name, req.grid)
        elif a != "status":
            raise NavigationError(f"unknown map action {a!r}")
        with self._lock:
            scans = self.mapper.scans
        return MapReply(a, name, grid, scans, int(self.mapping), file, self.fabric.header(keys.srv(self.world, "map", name)))

    def _on_map(self, key: str, req: MapRequest | None) -> MapReply:
        if req is None:
            rest = keys.parse(key).rest
            req = MapRequest("get", name=rest[0] if rest else self.map_name)
        try:
            return self.map_request(req)
        except (NavigationError, OSError) as exc:
            self.counters["refusals"] += 1
            raise ServiceError(str(exc), key=key) from None

    # ------------------------------------------------------------------ plan service

    def _known(self, robot: str) -> bool:
        if self.robots is not None:
            return robot in self.robots
        return robot in self._poses

    def _costmap(self, name: str, robot_radius: float) -> Costmap:
        with self._lock:
            grid = self.maps.get(name)
            version = self._versions.get(name, 0)
            can_build = name == self.map_name and self.mapper.scans > 0
        if grid is None:
            if can_build:  # navigation before an explicit build: build with the default threshold
                grid = self.build_map(name)
                version = self._versions[name]
            else:
                raise NavigationError(
                    f"no map named {name!r}: drive with mapping on and build it (map service, action 'build'), or load/set one"
                )
        if is_empty(grid):
            raise NavigationError(f"map {name!r} is empty: no cell is known to be free")
        s = self.settings
        ck = (name, version, robot_radius, s.threshold, s.unknown_is_occupied)
        with self._lock:
            cm = self._costmaps.get(ck)
        if cm is None:
            cm = build_costmap(grid, robot_radius, threshold=s.threshold, unknown_is_occupied=s.unknown_is_occupied)
            with self._lock:
                while len(self._costmaps) >= 8:  # requests may vary the radius: keep the cache bounded
                    self._costmaps.pop(next(iter(self._costmaps)))
                self._costmaps[ck] = cm
        return cm

    def plan_request(self, req: PlanRequest) -> PlanReply:
        """Handle one plan request (also usable in-process, without Zenoh)."""
        robot = keys.validate_id(req.robot, what="robot id")
        if not self._known(robot):
            which = "configured for this peer" if self.robots is not None else "seen on this world (no pose received)"
            raise NavigationError(f"unknown robot {robot!r}: not {which}")
        with self._lock:
            if req.start.shape[0] == 3:
                start = tuple(float(v) for v in req.start)
            else:
                pose = self._pose_at(robot, 0.0)
                if pose is None:
                    raise NavigationError(f"no pose received for robot {robot!r} yet; give a start or wait for its pose")
                start = (float(pose.position[0]), float(pose.position[1]), yaw_from_quaternion(pose.quaternion))
            if req.goal.shape[0] == 3:
                goal = tuple(float(v) for v in req.goal)
            elif self._goal is not None:
                g = self._goal
                goal = (float(g.position[0]), float(g.position[1]), yaw_from_quaternion(g.quaternion))
            else:
                raise NavigationError(
                    f"no goal given and no pose received on {keys.object_pose_all(self.world, self.goal_object)} yet"
                )
        s = self.settings
        v = s.vehicle
        vehicle = VehicleModel(
            robot_radius=req.robot_radius or self._radii.get(robot, v.robot_radius),
            turning_radius=req.turning_radius or v.turning_radius,
            allow_reverse=v.allow_reverse if req.direction == "default" else req.direction == "both",
        )
        costmap = self._costmap(req.map, vehicle.robot_radius)
        with self._plan_lock:
            result = plan_path(costmap, start, goal, planner=req.planner, settings=replace(s, vehicle=vehicle))
        key = keys.robot_path(self.world, robot)
        path = Path(result.x, result.y, result.theta, "world", self.fabric.header(key))
        self.fabric.publish(key, path)
        self.counters["plans"] += 1
        return PlanReply(
            path, robot, result.planner, result.seconds, result.length, result.expansions, req.map,
            self.fabric.header(keys.srv(self.world, "plan", robot)),
        )

    def _on_plan(self, key: str, req: PlanRequest | None) -> PlanReply:
        if req is None:
            self.counters["refusals"] += 1
            raise ServiceError("a plan query needs a PlanRequest payload (robot, goal, planner...)", key=key)
        rest = keys.parse(key).rest
        tail = rest[0] if rest else ""
        if tail and tail != req.robot:
            self.counters["refusals"] += 1
            raise ServiceError(f"query on {key} names robot {tail!r} but the request is for {req.robot!r}", key=key)
        try:
            return self.plan_request(req)
        except NavigationError as exc:
            self.counters["refusals"] += 1
            raise ServiceError(str(exc), key=key) from None


def register_navigation(fabric: Fabric, *, robots: list[str] | None = None, **options: Any) -> NavigationService:
    """Serve mapping and navigation for ``fabric``'s world; ``options`` go to :class:`NavigationService`."""
    return NavigationService(fabric, robots=robots, **options)

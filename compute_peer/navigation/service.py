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

Who asks (docs/security.md): a user asks on ``.../by/{user}`` (:func:`fabric.keys.srv_asked`; a class's
router lets each login ask in its own name only). Such an asker gets every plan in the reply, but it is
published on the robot's ``path`` key only when the trusted ownership replica says she owns the robot,
and map ``set``/``reset``/``stop``/``save``/``load`` (:data:`STAFF_MAP_ACTIONS`), which change the map
the whole class plans on, are refused to her with the reason. Her ``build`` makes her own map,
``{user}.{name}`` (:func:`fabric.keys.user_map`), never the class's, within a few maps per user and a cap for
all users (:mod:`.map_store`); plans use the class's map unless the request names another. The forms without
``by/`` are the staff's (sim, compute and instructor logins in a class; anyone in a world without access
control): served in full.

Every refusal (unknown robot, no pose yet, no map, goal outside the map or in an
obstacle, no path) is a :class:`~fabric.interfaces.ServiceError` reply with the
reason; nothing here can make a query time out or take the peer down.

This module is the wiring: it declares the subscribers and queryables, routes
what arrives to the parts, each in a module of its own (:mod:`.poses` the robots'
recent poses, :mod:`.discovery` what the sims say about the robots,
:mod:`.scan_mapping` scans into the grid, :mod:`.map_store` maps, costmaps and
files, :mod:`.map_service` and :mod:`.plan_service` the two services' actions,
:mod:`.owners` who owns each robot), and turns their refusals into error replies.
"""

from __future__ import annotations

import threading
from pathlib import Path as FsPath
from typing import Any

from fabric import keys
from fabric.interfaces import MapReply, MapRequest, OccupancyGrid, PlanReply, PlanRequest, Pose, Scan, ServiceError
from fabric.rate import Clock
from fabric.session import Fabric, undeclare_all

from .discovery import RobotDescriptions
from .errors import NavigationError
from .map_service import MapService
from .map_store import MapLimit, MapStore
from .mapping import MapperConfig, OccupancyMapper
from .owners import OwnerWatch
from .plan_service import PlanService
from .planner import PlannerSettings
from .poses import MAX_ROBOTS, POSE_HISTORY, PoseHistory
from .scan_mapping import ScanMapping

__all__ = ["MAX_ROBOTS", "POSE_HISTORY", "STAFF_MAP_ACTIONS", "NavigationService", "register_navigation"]

STAFF_MAP_ACTIONS = frozenset({"set", "reset", "stop", "save", "load"})
"""Map actions that change what every user of the world plans on: refused to a user asking in her name."""


class NavigationService:
    """Mapping + planning for one world. A context manager; ``close()`` is idempotent.

    ``robots``: the robot ids to map and plan for; None means every robot seen on the world.
    ``mapper_config``: the grid (default 20 m x 20 m at 5 cm around the origin). ``settings``: vehicle and
    planner defaults. ``map_name``: the map built from scans. ``goal_object``: the scene object whose pose is
    the default goal. ``maps_dir``: the only folder ``save``/``load`` may touch (None: disabled).
    ``mapping``: accumulate scans from the start. ``sensor_offset`` (all robots) / ``sensor_offsets`` (per
    robot): LIDAR mounting (x, y, yaw) in the robot frame; otherwise learnt from ``srv/world`` when
    ``discover``, else (0, 0, 0). ``clock``: for the discovery's rate limit.

    Its parts: ``poses`` (:class:`PoseHistory`), ``descriptions`` (:class:`RobotDescriptions`), ``scans``
    (:class:`ScanMapping`), ``store`` (:class:`MapStore`), ``map_service`` (:class:`MapService`),
    ``plan_service`` (:class:`PlanService`; in-process, ``map_service.handle(req)`` and
    ``plan_service.handle(req)`` answer a request without Zenoh), ``owners`` (:class:`OwnerWatch`).
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
        self.counters: dict[str, int] = {
            "scans": 0,  # folded into the map
            "scans_ignored": 0,  # arrived while mapping was off
            "scans_without_pose": 0,
            "scans_held": 0,  # stamped after its moving robot's newest pose: held for the pose after it (then folded or dropped)
            "scans_out_of_step": 0,  # its stamp beyond the robot's poses kept, which it moved too fast to guess across
            "scans_waiting_for_sensor": 0,  # dropped while the sensor's mounting is being looked up
            "scans_rejected": 0,
            "plans": 0,
            "plans_unpublished": 0,  # a plan for a robot its asker does not own: in the reply only
            "refusals": 0,
            "refused_staff_only": 0,  # a map action of the staff's asked by a user (also in refusals)
            "refused_map_limit": 0,  # a user's new map past the store's caps (also in refusals)
            "poses_narrowed": 0,  # 1 once only the described mobile robots' poses are heard (_hear_described)
        }
        self.poses = PoseHistory(POSE_HISTORY)
        self.descriptions = RobotDescriptions(
            fabric,
            followed=self.poses.robots,
            sensor_offset=sensor_offset,
            sensor_offsets=sensor_offsets,
            discover=discover,
            clock=clock,
        )
        vehicle_radius = self.settings.vehicle.robot_radius
        self.scans = ScanMapping(
            self.poses,
            sensor_offset=self.descriptions.sensor_offset,
            radius=lambda robot: self.descriptions.radius(robot, vehicle_radius),
            counters=self.counters,
            config=mapper_config,
            on=mapping,
        )
        self.store = MapStore(maps_dir)
        self.map_service = MapService(fabric, self.store, self.scans, map_name=self.map_name)
        which = "configured for this peer" if self.robots is not None else "seen on this world (no pose received)"
        self.plan_service = PlanService(
            fabric,
            self.map_service,
            self.poses,
            self.descriptions,
            known=self._known,
            unknown_reason=which,
            settings=self.settings,
            goal_object=self.goal_object,
            counters=self.counters,
        )
        self._lock = threading.Lock()  # new robots: the check and the first pose together
        self._closed = False
        self._resources: list[Any] = []
        self._poses_lock = threading.Lock()  # the switch from every robot's poses to the described ones'
        self._pose_wildcard: Any = None  # robot/*/pose, until the sims have described the world's mobile robots
        self._pose_keys: frozenset[str] = frozenset()  # robot/{id}/pose of each heard on its own subscription
        self._pose_subs: list[Any] = []
        self.descriptions.on_described = self._hear_described
        self.owners = OwnerWatch(fabric)  # the trusted replica of the ownership records
        self._declare()

    # ------------------------------------------------------------------ lifecycle

    def _declare(self) -> None:
        f = self.fabric
        if self.robots is None:
            # poses and scans only: a class's arms publish joints and flange poses at 100 Hz each, which this
            # service never uses (robot/** made a compute peer decode the whole world, 0.3 cores for 32 robots);
            # every robot's poses only until the sims describe the mobile ones (_hear_described)
            self._pose_wildcard = f.subscribe(
                keys.robot_stream_all(self.world, "pose"), self._on_any_pose, expected=Pose
            )
            self._resources.append(
                f.subscribe(keys.robot_stream_all(self.world, "scan"), self._on_robot, expected=Scan)
            )
        else:
            for r in self.robots:
                self._resources.append(f.subscribe(keys.robot_pose(self.world, r), self._on_robot, expected=Pose))
                self._resources.append(f.subscribe(keys.robot_scan(self.world, r), self._on_robot, expected=Scan))
        self._resources.append(
            f.subscribe(keys.object_pose_all(self.world, self.goal_object), self._on_goal, expected=Pose, history=True)
        )
        # srv/{map,plan}/{name}: the nearest compute peer; srv/{map,plan}/{name}/{peer_id}: this one (docs/compute.md)
        # and each with .../by/{user}: a user asking in her own name (keys.srv_asked)
        for peer in (None, f.peer_id):
            for service, handler, expected in (("map", self._on_map, MapRequest), ("plan", self._on_plan, PlanRequest)):
                self._resources.append(
                    f.rpc.serve(keys.srv_per_subject(self.world, service, peer), handler, expected=expected)
                )
                self._resources.append(
                    f.rpc.serve(keys.srv_asked_all(self.world, service, peer), handler, expected=expected)
                )

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
        self.descriptions.close()
        with self._poses_lock:
            subs, self._pose_subs = [self._pose_wildcard, *self._pose_subs], []
            self._pose_wildcard = None
        undeclare_all([s for s in subs if s is not None])
        undeclare_all(self._resources)
        self.owners.close()

    # ------------------------------------------------------------------ the parts, for in-process use

    @property
    def mapping(self) -> bool:
        """Whether scans are being folded into the map."""
        return self.scans.on

    @mapping.setter
    def mapping(self, on: bool) -> None:
        self.scans.on = bool(on)

    @property
    def mapper(self) -> OccupancyMapper:
        """The grid the scans are folded into."""
        return self.scans.mapper

    @property
    def maps(self) -> dict[str, OccupancyGrid]:
        """The maps held, by name."""
        return self.store.maps

    def discover_robots(self, timeout: float = 2.0) -> int:
        """Learn each mobile robot's LIDAR mounting and radius from the sim peers' ``srv/world``; returns how many.

        Explicit ``sensor_offsets`` are never overridden.
        """
        return self.descriptions.discover(timeout)

    # ------------------------------------------------------------------ inputs

    def _known(self, robot: str) -> bool:
        if self.robots is not None:
            return robot in self.robots
        return robot in self.poses

    def _on_robot(self, key: str, msg: Any) -> None:
        try:
            parsed = keys.parse(key)
        except ValueError:  # any login may put on robot/**: a key of no layout is counted, never a traceback
            self.counters["bad_key"] = self.counters.get("bad_key", 0) + 1
            return
        robot = parsed.subject
        if parsed.category != "robot" or (self.robots is not None and robot not in self.robots):
            return
        if robot not in self.poses:  # nothing is kept for robots the world does not have
            if self.descriptions.not_mobile(robot):  # an arm's flange pose, 100 Hz: not a robot to map or plan for
                return
            if not self.descriptions.admits(robot) or len(self.poses) >= MAX_ROBOTS:
                self.counters["unknown_robot"] = self.counters.get("unknown_robot", 0) + 1
                return
        if isinstance(msg, Pose) and parsed.leaf == "pose":
            with self._lock:
                if robot not in self.poses:
                    self.descriptions.sensor_offset(robot)  # a new robot: look its sensor up before its scans come
                self.poses.add(robot, msg)
            self.scans.pose_added(robot)  # the scans held ahead of it
        elif isinstance(msg, Scan) and parsed.leaf == "scan":
            if self._closed:
                self.counters["scans_ignored"] += 1
                return
            self.scans.integrate(robot, msg)

    def _on_any_pose(self, key: str, msg: Pose) -> None:
        """A pose heard on ``robot/*/pose``: passed on unless its robot is heard on its own subscription already."""
        if key not in self._pose_keys:
            self._on_robot(key, msg)

    def _hear_described(self, robots: set[str]) -> None:
        """Once the sims have described the world's mobile robots, hear the poses of those alone: the others are
        not followed (:meth:`RobotDescriptions.admits`), and on ``robot/*/pose`` every arm's flange pose came at 100
        Hz, each decoded and passed over (and published by the sim for this service alone): an idle combined world's
        compute peer, sim and router took 0.32 cores, 0.23 without. Called after each lookup the sims answered (a
        later one may describe more robots); never on a Zenoh callback thread."""
        with self._poses_lock:
            if self._closed or self.robots is not None:
                return
            new = []
            for robot in sorted(robots):
                try:
                    key = keys.robot_pose(self.world, robot)
                except ValueError:  # not an id: nothing to hear
                    continue
                if key not in self._pose_keys and len(self._pose_keys) + len(new) < MAX_ROBOTS:
                    new.append((robot, key))
            if not new and self._pose_wildcard is None:
                return
            # its own subscription first, marked before it is declared: the wildcard passes over what it hears from
            # then on (at most a pose lost in between, never one taken twice)
            self._pose_keys = self._pose_keys | {key for _, key in new}
            for _, key in new:
                self._pose_subs.append(self.fabric.subscribe(key, self._on_robot, expected=Pose))
            wildcard, self._pose_wildcard = self._pose_wildcard, None
        if wildcard is not None:
            undeclare_all([wildcard])
            self.counters["poses_narrowed"] = 1

    def _on_goal(self, key: str, msg: Pose) -> None:
        self.plan_service.set_goal(msg)

    # ------------------------------------------------------------------ queries

    def _on_map(self, key: str, req: MapRequest | None) -> MapReply:
        parsed = keys.parse(key)
        if req is None:
            req = MapRequest("get", name=parsed.rest[0] if parsed.rest else self.map_name)
        asker = keys.asker(parsed)
        if asker and req.action in STAFF_MAP_ACTIONS:
            self.counters["refusals"] += 1
            self.counters["refused_staff_only"] += 1
            raise ServiceError(
                f"map {req.action!r} changes the map everyone plans on: an instructor's, not {asker}'s "
                f"(start, status, build and get are open)",
                key=key,
            )
        try:
            return self.map_service.handle(req, user=asker)
        except MapLimit as exc:
            self.counters["refusals"] += 1
            self.counters["refused_map_limit"] += 1
            raise ServiceError(str(exc), key=key) from None
        except (NavigationError, OSError) as exc:
            self.counters["refusals"] += 1
            raise ServiceError(str(exc), key=key) from None

    def _on_plan(self, key: str, req: PlanRequest | None) -> PlanReply:
        if req is None:
            self.counters["refusals"] += 1
            raise ServiceError("a plan query needs a PlanRequest payload (robot, goal, planner...)", key=key)
        parsed = keys.parse(key)
        rest = parsed.rest
        tail = rest[0] if rest else ""
        if tail and tail != req.robot:
            self.counters["refusals"] += 1
            raise ServiceError(f"query on {key} names robot {tail!r} but the request is for {req.robot!r}", key=key)
        asker = keys.asker(parsed)
        # a user's plan is published on the robot's path key only when she owns the robot: else another
        # user's base would show, and might follow, a path it was never planned for
        publish = not asker or self.owners.owner_of(req.robot) == asker
        try:
            reply = self.plan_service.handle(req, publish=publish)
        except NavigationError as exc:
            self.counters["refusals"] += 1
            raise ServiceError(str(exc), key=key) from None
        if not publish:
            self.counters["plans_unpublished"] += 1
        return reply


def register_navigation(fabric: Fabric, *, robots: list[str] | None = None, **options: Any) -> NavigationService:
    """Serve mapping and navigation for ``fabric``'s world; ``options`` go to :class:`NavigationService`."""
    return NavigationService(fabric, robots=robots, **options)

"""The plan service (``srv/plan/{robot}``, :class:`PlanRequest`): a path from the robot's pose to the goal.

The start is the robot's latest pose unless the request gives one, the goal the ``goal`` scene object's pose
unless the request gives one; the vehicle is the settings' with the robot's radius from its description. A
robot's own footprint is never an obstacle to a plan from where it stands, and the other robots, where they stand
now, are obstacles to it, :data:`OTHERS_MARGIN` beyond their radius (the maps keep none: a student planning again after her base reported ``blocked`` gets a
path around the base in her way). The
path is published on ``rf/{world}/robot/{robot}/path`` and returned; following it is the user's decision (they
send it on ``cmd/path``). Planning is CPU-bound, so plans run one at a time.
"""

from __future__ import annotations

import threading
from dataclasses import replace
from typing import TYPE_CHECKING, Callable

from fabric import keys
from fabric.interfaces import Path, PlanReply, PlanRequest, Pose, yaw_from_quaternion

from .costmap import Costmap, build_costmap
from .discovery import RobotDescriptions
from .errors import NavigationError
from .map_service import MapService
from .model import VehicleModel
from .planner import PlannerSettings, plan_path
from .poses import PoseHistory
from .robot_cells import Footprint, clear_robots, mark_robots

OTHERS_MARGIN = 0.1
"""Metres the other robots are marked beyond their radius for a plan: a base's way guard keeps other bases their
radii plus 5 cm away (``sim_peer.physics.way_guard.BASE_CLEARANCE``: a bumper looks beyond the radius ahead), and its
follower cuts a curve by up to 7 cm, so a path planned past a base standing still must pass it further than its
radius (at their radii, bases passing each other stopped, or met on the bumper)."""

if TYPE_CHECKING:
    from fabric.session import Fabric

__all__ = ["PlanService"]


class PlanService:
    """Plans for the robots ``known(robot)`` accepts, on the maps of ``maps``; counts ``plans`` in ``counters``."""

    def __init__(
        self,
        fabric: "Fabric",
        maps: MapService,
        poses: PoseHistory,
        descriptions: RobotDescriptions,
        *,
        known: Callable[[str], bool],
        unknown_reason: str,
        settings: PlannerSettings,
        goal_object: str,
        counters: dict[str, int],
    ) -> None:
        self.fabric = fabric
        self.world = fabric.world
        self.maps = maps
        self.poses = poses
        self.descriptions = descriptions
        self.settings = settings
        self.goal_object = goal_object
        self.counters = counters
        counters.setdefault("plans", 0)
        self._known = known
        self._unknown_reason = unknown_reason
        self.goal: Pose | None = None  # the goal object's latest pose
        self._plan_lock = threading.Lock()

    def set_goal(self, pose: Pose) -> None:
        self.goal = pose

    def costmap(
        self, name: str, robot_radius: float, *, standing: Footprint | None = None, others: tuple[Footprint, ...] = ()
    ) -> Costmap:
        """Map ``name`` inflated by ``robot_radius``; the scans' map is built first when it never was.

        ``standing``: the planning robot where it stands: its own footprint is never an obstacle to its own start
        (cells a map holds under it, from a scan that took it for a wall, are taken as the floor they are).
        ``others``: the other robots where they stand now: obstacles for this plan only (the map keeps none)."""
        m = self.maps
        if name == m.map_name and m.store.get(name) is None and m.scans.scans > 0:
            m.build(name)  # navigation before an explicit build: build with the default threshold
        s = self.settings
        cm = m.store.costmap(name, robot_radius, threshold=s.threshold, unknown_is_occupied=s.unknown_is_occupied)
        grid = m.store.get(name)
        if grid is None:
            return cm
        changed = clear_robots(grid, [standing], margin=0.0) if standing is not None else grid
        changed = mark_robots(changed, others, margin=OTHERS_MARGIN)
        if changed is grid:
            return cm
        return build_costmap(changed, robot_radius, threshold=s.threshold, unknown_is_occupied=s.unknown_is_occupied)

    def others(self, robot: str) -> tuple[Footprint, ...]:
        """The other robots followed, where they stand as of ``robot``'s latest pose (none gone quiet for 2 s)."""
        mine = self.poses.at(robot)
        if mine is None:
            return ()
        out = []
        for other in self.poses.robots() - {robot}:
            for p in self.poses.during(other, mine.header, lag=0.0)[-1:]:
                out.append(
                    Footprint(
                        float(p.position[0]),
                        float(p.position[1]),
                        self.descriptions.radius(other, self.settings.vehicle.robot_radius),
                    )
                )
        return tuple(out)

    def handle(self, req: PlanRequest, *, publish: bool = True) -> PlanReply:
        """Handle one plan request (also usable in-process, without Zenoh); the path goes on the robot's
        ``path`` key only with ``publish`` (the asker owns the robot, or is the staff)."""
        robot = keys.validate_id(req.robot, what="robot id")
        if not self._known(robot):
            raise NavigationError(f"unknown robot {robot!r}: not {self._unknown_reason}")
        start, goal = self._ends(robot, req)
        s = self.settings
        v = s.vehicle
        vehicle = VehicleModel(
            robot_radius=req.robot_radius or self.descriptions.radius(robot, v.robot_radius),
            turning_radius=req.turning_radius or v.turning_radius,
            allow_reverse=self.descriptions.reverse(robot, v.allow_reverse)
            if req.direction == "default"
            else req.direction == "both",
        )
        own = req.start.shape[0] != 3  # from where the robot stands
        costmap = self.costmap(
            req.map,
            vehicle.robot_radius,
            standing=Footprint(start[0], start[1], vehicle.robot_radius) if own else None,
            others=self.others(robot),
        )
        with self._plan_lock:
            result = plan_path(costmap, start, goal, planner=req.planner, settings=replace(s, vehicle=vehicle))
        key = keys.robot_path(self.world, robot)
        path = Path(result.x, result.y, result.theta, "world", self.fabric.header(key))
        if publish:
            self.fabric.publish(key, path)
        self.counters["plans"] += 1
        return PlanReply(
            path,
            robot,
            result.planner,
            result.seconds,
            result.length,
            result.expansions,
            req.map,
            self.fabric.header(keys.srv(self.world, "plan", robot)),
            result.note,
        )

    def _ends(self, robot: str, req: PlanRequest) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """(start, goal) as (x, y, yaw): the request's, else the robot's latest pose and the goal object's."""
        if req.start.shape[0] == 3:
            start = tuple(float(v) for v in req.start)
        else:
            pose = self.poses.at(robot)
            if pose is None:
                raise NavigationError(f"no pose received for robot {robot!r} yet; give a start or wait for its pose")
            start = (float(pose.position[0]), float(pose.position[1]), yaw_from_quaternion(pose.quaternion))
        g = self.goal
        if req.goal.shape[0] == 3:
            goal = tuple(float(v) for v in req.goal)
        elif g is not None:
            goal = (float(g.position[0]), float(g.position[1]), yaw_from_quaternion(g.quaternion))
        else:
            raise NavigationError(
                f"no goal given and no pose received on {keys.object_pose_all(self.world, self.goal_object)} yet"
            )
        return start, goal

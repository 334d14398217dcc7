"""The paper's two tests as scripted users, written only against the public user API.

* **Test A** (arm): the user moves the IK target sphere along a path; for each
  target the compute peer solves IK and the user applies the joints; the arm
  follows and its flange must reach each target within a tolerance.
* **Test B** (mobile robot): the user drives the base while the compute peer
  maps, builds the map, sets the goal pointer, asks for a Hybrid A* path and
  has the base follow it to the goal.

Users take turns through ownership: each scenario requests its robot (queuing
if someone else holds it), and Test B ends by taking the arm over once its
owner releases it, showing that the arm continues from where it was.

Each scenario returns a :class:`ScenarioResult`; the CLI prints it and exits 0
only on success, which is what ``robofabric demo`` reports.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from fabric import keys
from fabric.interfaces import Header
from user_peer.api import Arm, Base, World
from user_peer.errors import FabricUserError, NotOwner, Timeout, Unreachable

__all__ = ["ScenarioResult", "test_a", "test_b", "SCENARIOS", "target_path"]


@dataclass
class ScenarioResult:
    name: str
    user: str
    ok: bool = False
    lines: list[str] = field(default_factory=list)
    figures: dict[str, float] = field(default_factory=dict)

    def say(self, text: str, log: Callable[[str], None] | None = print) -> None:
        self.lines.append(text)
        if log is not None:
            log(f"[{self.name} {self.user}] {text}")


def _acquire(robot, res: ScenarioResult, timeout: float) -> int:
    """Request ``robot``, waiting in the queue while someone else holds it."""
    deadline = time.monotonic() + timeout
    last = ""
    while True:
        try:
            epoch = robot.request(timeout=min(5.0, max(0.5, deadline - time.monotonic())))
            res.say(f"owns {robot.id} (epoch {epoch})")
            return epoch
        except Timeout:
            if robot.record is None:  # no authority answers and none ever published: a world without ownership
                res.say(f"no ownership authority answers for {robot.id}: commanding it without a lease")
                return 0
            raise
        except NotOwner as exc:
            if exc.reason.startswith("ownership is not available") and robot.record is None:
                res.say(f"this world runs without ownership: commanding {robot.id} without a lease")
                return 0
            if exc.reason != last:
                res.say(f"waiting for {robot.id}: {exc.reason}")
                last = exc.reason
            if time.monotonic() > deadline:
                raise
            time.sleep(0.5)


def target_path(center: np.ndarray, radius: float, n: int) -> np.ndarray:
    """``n`` points on a circle of ``radius`` in the y-z plane around ``center``: the sphere's route."""
    a = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)
    return np.stack([np.full(n, center[0]), center[1] + radius * np.cos(a), center[2] + radius * np.sin(a)], axis=1)


def _arm_reach_center(world: World, arm: Arm) -> np.ndarray:
    """A comfortable point in front of the arm: its zero-pose flange, a little lower (world frame)."""
    info = world.info()
    r = info.robot(arm.id) if hasattr(info, "robot") else None
    x, y, z, yaw = (float(v) for v in (r.pose if r is not None else (0.0, 0.0, 0.0, 0.0)))
    local = np.array([0.19, 0.0, 0.25])
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([x + c * local[0] - s * local[1], y + s * local[0] + c * local[1], z + local[2]])


def _pose_after(pose: Header, settled: Header, now: Any) -> bool:
    """Whether a pose with header ``pose`` shows the arm after the joints (header ``settled``) that showed it settled:
    the same sim's, stamped no earlier; or another sim's, that sim serving the arm now (``now``: the latest joints)."""
    if pose.source == settled.source:
        return bool(pose.stamp >= settled.stamp)
    return now is not None and pose.source == now.header.source


def _flange_error(arm: Arm, target: np.ndarray, after: int, timeout: float = 3.0) -> float:
    """Distance from the published flange position to ``target``, from a flange pose that arrived after
    the mark ``after`` (``world.latest.mark()``: local arrival order) and that its sim stamped no earlier than the
    joints that showed the arm settled: at load a pose published mid-move arrived after the mark, and target 1 of a
    sharded Test A read 76.6 mm off (whole run 14 of 2026-11-30). Stamps are compared within one sim's streams only;
    a pose from another sim (a take-over meanwhile) is taken as it comes if that sim serves the arm now (its joints are
    the latest): a dead sim's last pose, arriving late at load after a second take-over, read 20.55 mm off (a whole
    run of 2026-11-30, the two-SIGKILL fail-over)."""
    deadline = time.monotonic() + timeout
    key, joints = keys.robot_pose(arm.world.name, arm.id), keys.robot_joints(arm.world.name, arm.id)
    settled = arm.world.latest.get(joints)
    while time.monotonic() < deadline:
        p = arm.world.latest.get_after(key, after)
        if p is not None and (settled is None or _pose_after(p.header, settled.header, arm.world.latest.get(joints))):
            return float(np.linalg.norm(np.asarray(p.position) - target))
        time.sleep(0.02)
    raise FabricUserError(f"no flange pose from {arm.id} after the move")


def test_a(
    world: World, *, arm_id: str = "arm1", points: int = 8, radius: float = 0.05, tol: float = 0.005, hold: float = 0.5
) -> ScenarioResult:
    """Move the target sphere around a circle; IK each target; apply; check the flange reaches it."""
    res = ScenarioResult("test-a", world.user)
    arm = world.robot(arm_id)
    if not isinstance(arm, Arm):
        res.say(f"{arm_id} is not an arm")
        return res
    target = world.object("target")
    arm.wait_for("joints")
    _acquire(arm, res, timeout=60.0)
    t0 = time.monotonic()
    errors = []
    streamed = [0, 0]  # targets solved by the IK stream, by a query
    try:
        center = _arm_reach_center(world, arm)
        for i, p in enumerate(target_path(center, radius, points)):
            target.set_pose(p)
            q, how = _joints_for(arm, p, streamed)
            arm.move_joints(q, timeout=20.0)
            err = _flange_error(arm, p, world.latest.mark())  # from a flange pose that arrived after the arm settled
            errors.append(err)
            res.say(
                f"target {i + 1}/{points} at ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}): joints {np.round(np.degrees(q), 1).tolist()} deg "
                f"({how}), error {err * 1000:.2f} mm"
            )
            time.sleep(hold)
    finally:
        try:
            arm.release()
            res.say(f"released {arm.id}")
        except FabricUserError as exc:
            res.say(f"release failed: {exc.reason}")
    res.figures.update(
        targets=len(errors),
        streamed=streamed[0],
        queried=streamed[1],
        max_error_mm=max(errors) * 1000 if errors else float("nan"),
        seconds=time.monotonic() - t0,
    )
    res.ok = len(errors) == points and max(errors) <= tol
    res.say(
        f"{'reached' if res.ok else 'FAILED'}: {len(errors)}/{points} targets, max error {res.figures['max_error_mm']:.2f} mm "
        f"(tolerance {tol * 1000:.1f} mm) in {res.figures['seconds']:.1f} s"
    )
    return res


def _joints_for(arm: Arm, p: np.ndarray, counts: list[int]) -> tuple[np.ndarray, str]:
    """The joints for target ``p``: the compute peer's streamed solution (the paper's Test A), else an IK query."""
    if counts[1] and not counts[0]:
        counts[1] += 1
        return arm.ik(p), "IK query"  # no compute peer streams this arm: do not wait for one again
    try:
        sol = arm.wait_ik_stream(p, timeout=3.0)
    except Timeout:
        counts[1] += 1
        return arm.ik(p), "IK query: no stream"
    if not sol.ok:
        raise Unreachable(f"the IK stream refused the target: {sol.reason}")
    counts[0] += 1
    return np.asarray(sol.q), f"streamed, {sol.seconds:.2f} s move"


def test_b(
    world: World,
    *,
    base_id: str = "base1",
    arm_id: str | None = "arm1",
    goal: tuple[float, float, float] = (-2.5, 0.5, math.pi),
    tol: float = 0.3,
    turn: float = 2.0 * math.pi,
) -> ScenarioResult:
    """Drive while mapping, build the map (the user's own, ``{user}.map``), set the goal, plan on it, follow; then
    take the arm over in turn."""
    res = ScenarioResult("test-b", world.user)
    base = world.robot(base_id)
    if not isinstance(base, Base):
        res.say(f"{base_id} is not a mobile robot")
        return res
    base.wait_for("pose")
    _acquire(base, res, timeout=60.0)
    t0 = time.monotonic()
    reached = False
    try:
        base.start_mapping()
        omega = 0.8
        end = base.drive(0.0, omega, turn / omega)
        res.say(
            f"drove while mapping: turned {math.degrees(turn):.0f} deg in place, now at ({end[0]:.2f}, {end[1]:.2f})"
        )
        grid = base.build_map()
        mine = keys.user_map("map", world.user)  # a user's build makes her own map; the class's map is the staff's
        known = float(np.mean(grid.cells != 255))
        res.say(
            f"map built as {mine!r}: {grid.cells.shape[1]}x{grid.cells.shape[0]} cells at {grid.resolution:.2f} m, {known:.0%} known, {int(np.sum((grid.cells >= 50) & (grid.cells != 255)))} occupied"
        )
        world.object("goal").set_pose([goal[0], goal[1], 0.0], yaw=goal[2])
        res.say(f"goal set at ({goal[0]:.2f}, {goal[1]:.2f}, {math.degrees(goal[2]):.0f} deg)")
        tp = time.monotonic()
        path = base.plan_to(*goal, map_name=mine)
        length = float(np.sum(np.hypot(np.diff(path.x), np.diff(path.y))))
        res.say(f"planned {len(path)} poses, {length:.2f} m, in {time.monotonic() - tp:.2f} s")
        final = base.follow(path, tol=tol, timeout=90.0)
        dist = math.hypot(final[0] - goal[0], final[1] - goal[1])
        res.figures.update(path_m=length, goal_error_m=dist)
        reached = dist <= tol
        res.say(f"followed the path: stopped at ({final[0]:.2f}, {final[1]:.2f}), {dist:.2f} m from the goal")
    finally:
        try:
            base.release()
            res.say(f"released {base.id}")
        except FabricUserError as exc:
            res.say(f"release failed: {exc.reason}")
    handed = True
    if arm_id is not None and arm_id in world.robots():
        handed = _take_turn_on_arm(world, arm_id, res)
    res.figures["seconds"] = time.monotonic() - t0
    res.ok = reached and handed
    res.say(
        f"{'reached the goal' if reached else 'FAILED to reach the goal'}{'' if handed else '; arm handover FAILED'} in {res.figures['seconds']:.1f} s"
    )
    return res


def _take_turn_on_arm(world: World, arm_id: str, res: ScenarioResult) -> bool:
    """Wait until the arm's owner lets it go, take it, and move it home from wherever she left it.

    Not a request while she still holds it: her arm stands still between two of Test A's targets, and a request then
    takes a still robot over, as the rules allow a class, failing her test midway (a demo on a loaded box did)."""
    arm = world.robot(arm_id)
    assert isinstance(arm, Arm)
    deadline = time.monotonic() + 120.0
    holder = ""
    while (rec := arm.record) is not None and rec.owner not in ("", world.user) and time.monotonic() < deadline:
        if rec.owner != holder:
            holder = rec.owner
            res.say(f"waiting for {holder} to let go of {arm_id}")
        time.sleep(0.2)
    try:
        _acquire(arm, res, timeout=max(1.0, deadline - time.monotonic()))
        q0 = arm.joints
        res.say(f"took {arm_id} over where it was: joints {np.round(np.degrees(q0), 1).tolist()} deg")
        arm.move_joints(np.zeros(len(q0)), timeout=20.0)
        res.say(f"moved {arm_id} home")
        return True
    except FabricUserError as exc:
        res.say(f"turn on {arm_id} failed: {exc.reason}")
        return False
    finally:
        try:
            arm.release()
        except FabricUserError:
            pass


SCENARIOS: dict[str, Callable[..., ScenarioResult]] = {"test-a": test_a, "test-b": test_b}

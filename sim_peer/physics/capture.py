"""A world's whole state as a message, and putting a world back into it.

The primary serves :class:`WorldState` on ``rf/{world}/srv/state``; a standby polls it and keeps the
last one, together with the newest joints and poses from the streams (which come ten times more
often). On take-over :func:`restore` puts every robot and object back where it was (no reset) and
every controller back on its way: an arm's joint target and speed scale, a base's commanded twist,
a path follower's points and progress; what a robot's state is, each robot type says with its
``snapshot()``, ``restore()`` and ``overlay()`` (:mod:`sim_peer.robot`). What is not captured cannot be restored: MuJoCo's own
dynamic state of free bodies and contacts in progress (the robots here are kinematic), sensor noise
streams (the standby's generator is its own) and commands that arrived after the last snapshot
(see docs/sim.md).

No zenoh here: the peer and the standby do the I/O.
"""

from __future__ import annotations

from fabric.interfaces import JointState, ObjectInfo, Pose, RobotState, WorldState
from sim_peer.physics.world import SimWorld

__all__ = ["RobotState", "WorldState", "capture", "restore", "overlay_joints", "overlay_pose", "advance"]


# ---------------------------------------------------------------------- capture


def capture(world: SimWorld) -> tuple[float, int, tuple[RobotState, ...], tuple[ObjectInfo, ...]]:
    """(sim time, steps, robots, objects) of ``world`` now; call with the world's lock held. Each robot's
    state is its own ``snapshot()`` (a robot type that gives none is not carried over)."""
    robots = tuple(st for st in (r.snapshot() for r in world.robots.values()) if st is not None)
    objects = []
    for o in world.scene.objects:
        pos, quat = world.objects.pose(o.id)
        objects.append(ObjectInfo(o.id, o.kind, o.policy, pos, quat))
    return world.time, world.steps, robots, tuple(objects)


# ---------------------------------------------------------------------- restore


def restore(world: SimWorld, state: WorldState) -> None:
    """Put ``world`` into ``state``: time, every robot's controller, every object. Robots or objects
    the state does not name keep what they have; call with the world's lock held."""
    for s in state.robots:
        r = world.robots.get(s.id)
        if r is not None:
            r.restore(s)
    for o in state.objects:
        if o.id in world.objects:
            world.objects.set_pose(o.id, o.position, o.quaternion)
    world.data.time = float(state.time)
    world.steps = int(state.steps)
    world.settle()


def overlay_joints(world: SimWorld, rid: str, js: JointState) -> None:
    """A robot's joints from its stream (newer than the last snapshot): where it is and how fast it goes."""
    r = world.robots.get(rid)
    if r is not None:
        r.overlay("joints", js)


def overlay_pose(world: SimWorld, rid: str, pose: Pose) -> None:
    """A robot's pose from its stream: a base's position, heading and the velocities the stream carries."""
    r = world.robots.get(rid)
    if r is not None:
        r.overlay("pose", pose)


def advance(world: SimWorld, lag: dict[str, float]) -> None:
    """Step each robot's controller alone by its ``lag`` (s): robots last heard at different sim times
    are brought to one time the way the primary would have moved them (the controllers are
    deterministic; the bumper and the rest of the world are not stepped for these few milliseconds)."""
    for rid, t in lag.items():
        r = world.robots.get(rid)
        n = int(round(t / world.dt)) if t > 0 else 0
        for _ in range(min(n, 5000)):
            r.before_step(world.physics)
    world.touch()

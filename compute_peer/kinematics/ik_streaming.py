"""Streamed IK, the paper's Test A: an arm follows a scene object by IK solved at a fixed rate.

For each ``(robot, object)`` pair the service watches the object's pose (every user's, latest wins), and
at each tick solves position IK near the arm's current joints whenever the target moved since the last
solution, and publishes :class:`IKStream` on ``rf/{world}/robot/{robot}/ik``; applying it is the owner's
choice. An unreachable target is published as such (``ok`` false, with the reason) and reported once per
interval as an ``ik_unreachable`` event.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Iterable

import numpy as np

from fabric import keys
from fabric.interfaces import Event, EventKind, IKStream, JointState, Pose
from fabric.session import Fabric

from .arm import PlacedArm
from .arm_directory import ArmDirectory

log = logging.getLogger("robofabric.kinematics")


class IKStreams:
    """The streamed pairs of one service; ``tick(now)`` is its rate loop's callback. ``joints(robot)`` is the
    arm's latest joint state (the seed), ``counters`` the service's (``streamed``, ``stream_unreachable``)."""

    def __init__(
        self,
        fabric: Fabric,
        pairs: Iterable[tuple[str, str]],
        arms: ArmDirectory,
        joints: Callable[[str], JointState | None],
        counters: dict[str, int],
    ) -> None:
        self.fabric = fabric
        self.pairs = [(keys.validate_id(r, what="robot id"), keys.validate_id(o, what="object id")) for r, o in pairs]
        self.arms = arms
        self.joints = joints
        self.counters = counters
        self._lock = threading.Lock()
        self._targets: dict[str, Pose] = {}
        self._solved: dict[tuple[str, str], tuple[float, ...]] = {}

    def target_seen(self, key: str, msg: Pose) -> None:
        """A streamed object's pose (its subscription's callback; one per streamed object, never a made-up id)."""
        obj = keys.parse(key).subject
        with self._lock:
            self._targets[obj] = msg

    def tick(self, now: float) -> None:
        for robot, obj in self.pairs:
            with self._lock:
                target = self._targets.get(obj)
            arm = self.arms.get(robot)
            if target is None:
                continue
            if arm is None:
                if self.arms.discovering:
                    self.arms.look_soon()
                continue
            position = tuple(float(v) for v in target.position)
            if self._solved.get((robot, obj)) == position:
                continue  # the target has not moved since the last solution
            js = self.joints(robot)
            try:
                self.publish(robot, obj, arm, np.asarray(position), None if js is None else np.asarray(js.q, float))
            except Exception as exc:  # a closing session; the next tick tries again
                log.debug("IK stream for %s failed: %s", robot, exc)
                continue
            self._solved[(robot, obj)] = position

    def publish(self, robot: str, obj: str, arm: PlacedArm, position: np.ndarray, q_now: np.ndarray | None) -> IKStream:
        """Solve one streamed target and publish it on ``robot/{robot}/ik``."""
        step = arm.stream_step(position, q_now)
        key = keys.robot_stream(self.fabric.world, robot, "ik")
        msg = IKStream(
            robot,
            obj,
            position,
            step.ok,
            step.reason,
            step.q,
            step.dq,
            step.speeds,
            step.seconds,
            self.fabric.header(key),
        )
        self.fabric.publish(key, msg)
        if step.ok:
            self.counters["streamed"] += 1
        else:
            self.counters["stream_unreachable"] += 1
            self.fabric.reports.emit(
                Event(
                    kind=EventKind.IK_UNREACHABLE,
                    reason=step.reason,
                    object=robot,
                    severity="warning",
                    header=self.fabric.header("event"),
                ),
                "compute",
                robot,
            )
        return msg


__all__ = ["IKStreams"]

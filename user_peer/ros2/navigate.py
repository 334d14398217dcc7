"""``/NS/ROBOT/navigate_to_pose``: Nav2's NavigateToPose action for each base the bridge drives.

What RViz's Nav2 panel and Nav2's clients send: a goal pose, feedback while the base moves (its pose, the distance
left, the time so far), a result at the end. A goal takes the bridge's ``goal_pose`` path (:mod:`user_peer.ros2.goals`:
the frame checked, planned with the world's planner on the goal map, the plan on ``/ROBOT/path``, followed by the
sim); the goal succeeds when the base stands within ``tol`` of the path's end, is aborted with the reason
(``error_msg``, and ``/rosout``) when it is refused or cannot be planned or not reached in ``timeout``, and a cancel
stops the base. ``behavior_tree`` is ignored (there is no Nav2 behaviour tree here).

``nav2_msgs`` is not among ROS 2 Kilted's wheels: :mod:`user_peer.ros2.msgbuild` builds its NavigateToPose into the
environment (``make test`` does). Without it there is no action server and ``available`` is False (said at start).
The servers live on a node of their own, ``<bridge's node>_navigate`` (:mod:`.action_host` says why).
"""

from __future__ import annotations

import math
import time
from typing import Any, Callable

from fabric import keys
from user_peer.errors import FabricUserError
from user_peer.openfmt.ros2 import sim_time_ns
from user_peer.ros2.action_host import ActionHost
from user_peer.ros2.commands import CommandError
from user_peer.ros2.direct import pose_stamped

__all__ = ["NavigateActions", "navigate_action_class"]


def navigate_action_class() -> type | None:
    """``nav2_msgs.action.NavigateToPose`` where importable (built by :mod:`user_peer.ros2.msgbuild`), else None."""
    try:
        from nav2_msgs.action import NavigateToPose
    except ImportError:
        return None
    return NavigateToPose


class NavigateActions(ActionHost):
    """One NavigateToPose action server per driven base, on the bridge's action node."""

    def __init__(
        self,
        node: Any,
        namespace: str,
        prefix: str,
        check_owner: Callable[[str, str], Any],
        refuse: Callable[[str, str, str], None],
        goal_of: Callable[[Any, str], tuple[float, float, float]],
        map_name: str = "",
        *,
        tol: float = 0.25,
        timeout: float = 120.0,
        period: float = 0.1,
    ) -> None:
        super().__init__(node, namespace, navigate_action_class(), "navigate_to_pose", "navigate")
        self.prefix = prefix
        self.check_owner, self.refuse, self.goal_of, self.map_name = check_owner, refuse, goal_of, map_name
        self.tol, self.timeout, self.period = tol, timeout, period
        self.succeeded = 0

    def _end(self, rid: str, handle: Any, code: int, why: str) -> Any:
        """Abort the goal with ``why`` (told on /rosout as a refusal)."""
        self.refuse(rid, "navigate_to_pose", why)
        handle.abort()
        return self.action.Result(error_code=code, error_msg=why)

    def _execute(self, rid: str, handle: Any) -> Any:
        R = self.action.Result
        base = self.check_owner(rid, "navigate_to_pose")
        if base is None:
            return self._end(rid, handle, R.GOAL_REJECTED, f"{rid}: this bridge's login may not command it")
        try:
            goal = self.goal_of(handle.request.pose, self.prefix)  # goals.goal_of: the frame checked
            name = self.map_name or keys.user_map("map", base.world.user)
            path = base.plan_to(*goal, map_name=name)
            base.follow(path, wait=False)
        except CommandError as exc:
            return self._end(rid, handle, R.GOAL_REJECTED, str(exc))
        except (FabricUserError, ValueError) as exc:
            return self._end(rid, handle, R.UNKNOWN, getattr(exc, "reason", str(exc)))
        return self._watch(rid, handle, base, (float(path.x[-1]), float(path.y[-1])))

    def _watch(self, rid: str, handle: Any, base: Any, end: tuple[float, float]) -> Any:
        """Feedback every ``period`` until the base stands at ``end``, the goal is canceled or time runs out."""
        start = time.monotonic()
        feedback = self.action.Feedback()
        while True:
            elapsed = time.monotonic() - start
            p = base.pose
            if handle.is_cancel_requested:
                base.stop(confirm=False)
                handle.canceled()
                return self.action.Result(error_code=self.action.Result.NONE, error_msg="canceled")
            if p is not None:
                left = math.hypot(end[0] - p.position[0], end[1] - p.position[1])
                pose_stamped(feedback.current_pose, p, sim_time_ns(p), self.prefix)
                feedback.distance_remaining = float(left)
                feedback.navigation_time.sec, feedback.navigation_time.nanosec = int(elapsed), int(elapsed % 1 * 1e9)
                handle.publish_feedback(feedback)
                still = math.hypot(p.linear[0], p.linear[1]) < 0.02 and abs(p.angular[2]) < 0.05
                if left <= self.tol and still:
                    handle.succeed()
                    self.succeeded += 1
                    return self.action.Result(error_code=self.action.Result.NONE, error_msg="")
            if elapsed > self.timeout:
                return self._end(
                    rid,
                    handle,
                    self.action.Result.TIMEOUT,
                    f"{rid} did not reach ({end[0]:.2f}, {end[1]:.2f}) within {self.timeout:.0f} s",
                )
            time.sleep(self.period)

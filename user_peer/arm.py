"""An arm's handle: joint moves, and Cartesian moves through a compute peer's IK (:class:`Arm`, kind ``arm``)."""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from fabric import keys
from fabric.interfaces import JointState, JointTarget, JointTrajectory, Pose, ServiceError
from user_peer import services
from user_peer.errors import Timeout, Unreachable
from user_peer.pause import PauseRider
from user_peer.robot import Robot

__all__ = ["Arm"]


class Arm(Robot):
    """A robot arm: joint moves and Cartesian moves through a compute peer's IK."""

    kind = "arm"
    data_stream = "joints"

    @property
    def joint_state(self) -> JointState | None:
        return self.latest("joints")

    @property
    def joints(self) -> np.ndarray | None:
        """The latest joint positions (rad), or None before the first JointState."""
        js = self.joint_state
        return None if js is None else np.array(js.q)

    @property
    def flange(self) -> Pose | None:
        return self.latest("pose")

    def _reset_target(self) -> np.ndarray | None:
        """Where the sim's controller takes the joints on a reset: zero, within range (None: the world gave
        no limits)."""
        e = self.entry
        if not e.lower or len(e.lower) != len(e.upper):
            return None
        return np.clip(np.zeros(len(e.lower)), np.asarray(e.lower), np.asarray(e.upper))

    def move_joints(
        self,
        q: Sequence[float],
        *,
        wait: bool = True,
        tol: float = 1e-3,
        timeout: float = 20.0,
        speed_scale: float = 1.0,
    ) -> np.ndarray:
        """Command joint targets (rad). With ``wait``, block until within ``tol`` of them and still."""
        target = np.asarray(q, dtype=float)
        n = len(self.entry.joint_names)
        if target.shape != (n,):
            raise ValueError(f"{self.id} has {n} joints, got {target.shape[0] if target.ndim else 0} values")
        if not np.isfinite(target).all():
            raise ValueError(f"joint targets must be finite, got {target.tolist()}")
        lo, hi = np.asarray(self.entry.lower), np.asarray(self.entry.upper)
        if lo.shape == target.shape and ((target < lo - 1e-9) | (target > hi + 1e-9)).any():
            j = int(np.flatnonzero((target < lo - 1e-9) | (target > hi + 1e-9))[0])
            raise Unreachable(
                f"{self.entry.joint_names[j]} target {math.degrees(target[j]):.1f} deg is outside its limits "
                f"[{math.degrees(lo[j]):.1f}, {math.degrees(hi[j]):.1f}] deg"
            )
        marks = self.world.event_mark(), self.world.latest.mark()
        key = keys.robot_cmd(self._w, self.id, "joints", self.world.user)
        cmd = self.send("joints", JointTarget(target, speed_scale, self.world.fabric.header(key)))
        if not wait:
            return target
        rider = PauseRider(
            self, "joints", cmd, marks[0], resend_on_takeover=True, heard=lambda: self._moving_or_at(target, tol, marks)
        )
        return self._wait_joints(target, tol, timeout, marks, rider)

    def follow_joints(
        self,
        times: Sequence[float],
        positions: Sequence[Sequence[float]],
        *,
        wait: bool = True,
        tol: float = 1e-3,
        timeout: float | None = None,
    ) -> np.ndarray:
        """Play timed joint positions (rad): ``positions[i]`` at ``times[i]`` s after the sim takes the command,
        from where the arm is, linearly between points (a ROS ``JointTrajectory``'s meaning). The sim plays it in
        its own time, so a late or starved client changes nothing of its timing. With ``wait``, block until within
        ``tol`` of the last point and still (``timeout``: the trajectory's duration plus 20 s)."""
        t = np.asarray(times, dtype=float).reshape(-1)
        pts = np.asarray(positions, dtype=float)
        n = len(self.entry.joint_names)
        if pts.ndim != 2 or pts.shape != (t.shape[0], n) or t.shape[0] == 0:
            raise ValueError(
                f"{self.id}: a trajectory of {t.shape[0]} times needs as many points of {n} joints, got {pts.shape}"
            )
        if not (np.isfinite(t).all() and np.isfinite(pts).all()):
            raise ValueError("a trajectory's times and positions must be finite")
        if t[0] < 0 or (np.diff(t) < 0).any():
            raise ValueError(f"a trajectory's times must start at 0 or later and not decrease: {t.tolist()}")
        marks = self.world.event_mark(), self.world.latest.mark()
        key = keys.robot_cmd(self._w, self.id, "trajectory", self.world.user)
        cmd = self.send("trajectory", JointTrajectory(t, pts, self.world.fabric.header(key)))
        goal = pts[-1]
        if not wait:
            return goal
        # not sent again on a standby's takeover: it would play the trajectory again from where the arm stands
        rider = PauseRider(self, "trajectory", cmd, marks[0], heard=lambda: self._moving_or_at(goal, tol, marks))
        return self._wait_joints(goal, tol, float(t[-1]) + 20.0 if timeout is None else timeout, marks, rider)

    def _moving_or_at(self, goal: np.ndarray, tol: float, marks: tuple[int, int]) -> bool:
        """Whether joints that arrived after the command show the arm moving, or at ``goal``: a sign that the sim has
        the command (a :class:`PauseRider`'s ``heard`` test; without one, the command is sent again)."""
        js = self.world.latest.get_after(keys.robot_joints(self._w, self.id), marks[1])
        return js is not None and bool(
            np.max(np.abs(js.dq), initial=0.0) >= 1e-2 or np.max(np.abs(np.asarray(js.q) - goal)) <= tol
        )

    def _wait_joints(
        self, target: np.ndarray, tol: float, timeout: float, marks: tuple[int, int], rider: PauseRider
    ) -> np.ndarray:
        """Until joints that arrived after the command (local arrival order, never the sim's clock) are at
        ``target`` and still; a rejection that arrived after it raises (:class:`NotOwner`, :class:`Rejected`),
        but a sim that held its robots is ridden out (:mod:`user_peer.pause`)."""
        key = keys.robot_joints(self._w, self.id)
        data_mark = marks[1]

        def done() -> bool:
            rider.check()
            js = self.world.latest.get_after(key, data_mark)
            if js is None:
                return False
            return bool(np.max(np.abs(np.asarray(js.q) - target)) <= tol and np.max(np.abs(js.dq)) < 1e-2)

        if not self.world.latest.wait_for(done, timeout):
            js = self.world.latest.get(key)
            err = float(np.max(np.abs(np.asarray(js.q) - target))) if js is not None else float("nan")
            raise Timeout(
                f"{self.id} did not reach its joint targets within {timeout:.1f} s (max error {math.degrees(err):.2f} deg)"
                + rider.note()
            )
        return np.array(self.world.latest.get(key).q)

    def ik(self, xyz: Sequence[float], quaternion: Sequence[float] | None = None) -> np.ndarray:
        """Joint angles placing the flange at ``xyz`` (world frame, m), from a compute peer.

        :class:`Unreachable` when the compute peer refuses (with its reason), :class:`Timeout` when none answers.
        """
        try:
            return self.world.compute_route.ask(
                lambda peer: services.ik(
                    self.world.fabric, self.id, xyz, quaternion, self.joints, timeout=self.world.timeout, peer=peer
                )
            )
        except ServiceError as exc:
            if exc.reason.startswith("no reply"):
                raise Timeout(f"IK for {self.id}: {exc.reason}") from None
            raise Unreachable(f"IK for {self.id} at {list(map(float, xyz))}: {exc.reason}") from None

    @property
    def ik_stream(self) -> Any:
        """The latest streamed IK solution (``fabric.interfaces.IKStream``) for this arm, or None."""
        return self.latest("ik")

    def wait_ik_stream(self, xyz: Sequence[float], *, timeout: float | None = None, tol: float = 1e-9) -> Any:
        """The streamed IK solution for a target at ``xyz`` (world frame), once a compute peer has solved it.

        Streaming runs in a compute peer started with ``--stream ROBOT:OBJECT``; :class:`Timeout` if no
        solution for this target arrives in time. Check ``.ok`` / ``.reason`` before applying ``.q``.
        """
        goal = np.asarray(xyz, dtype=float)
        key = keys.robot_stream(self._w, self.id, "ik")

        def match() -> Any:
            msg = self.world.latest.get(key)
            if msg is not None and np.max(np.abs(np.asarray(msg.position) - goal)) <= tol:
                return msg
            return None

        wait = self.world.timeout if timeout is None else timeout
        msg = self.world.latest.wait_for(match, wait)
        if msg is None:
            raise Timeout(
                f"no streamed IK for {self.id} at {goal.tolist()} within {wait:.1f} s (is a compute peer streaming it?)"
            )
        return msg

    def move_to(
        self,
        xyz: Sequence[float],
        quaternion: Sequence[float] | None = None,
        *,
        wait: bool = True,
        tol: float = 1e-3,
        timeout: float = 20.0,
    ) -> np.ndarray:
        """Move the flange to ``xyz`` (world frame, m) through IK; :class:`Unreachable` if IK refuses.

        ``tol`` is on the joints (rad), as in :meth:`move_joints`; returns the joints reached.
        """
        q = self.ik(xyz, quaternion)
        return self.move_joints(q, wait=wait, tol=tol, timeout=timeout)

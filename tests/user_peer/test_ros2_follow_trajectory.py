"""The FollowJointTrajectory action server (user_peer.ros2.follow_trajectory) with a real rclpy ActionClient: under a
namespace its name is ``/NS/ARM/follow_joint_trajectory``; a goal for an arm this login may not command is aborted
with ``INVALID_GOAL`` and the reason, and one whose ``joint_names`` are not the arm's with ``INVALID_JOINTS`` and
what is wrong, told as a refusal (the bridge's ``/rosout`` line); and the tolerance rules control_msgs defines. A
cancel stops the trajectory and the arm. A
goal followed to its end is tests/user_peer/test_ros2_ros_users.py's (slow: a world with an arm)."""

from __future__ import annotations

import contextlib
import importlib.util
import math
import os
import threading
from types import SimpleNamespace

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor

from robofabric.testing import wait_until
from user_peer.ros2.follow_trajectory import FollowTrajectoryActions, joint_names_error, tolerance_miss, tolerances
from user_peer.ros2.trajectory import TrajectoryPlayer

BUILD_IT = (
    "control_msgs is not importable: it is not among ROS 2 Kilted's wheels; build it into this environment "
    "with `python -m user_peer.ros2.msgbuild` (make test does; it needs g++ and Python's headers)"
)
JOINTS = ("joint_1", "joint_2", "joint_3", "joint_4", "joint_5", "joint_6")


def test_joint_names_must_be_the_arms_each_once_in_any_order():
    assert joint_names_error("arm1", JOINTS, list(reversed(JOINTS))) is None
    assert joint_names_error("arm1", JOINTS, ["joint_1", "elbow"]) == (
        f"joint_names ['joint_1', 'elbow'] are not arm1's joints {list(JOINTS)}: unknown ['elbow'], "
        "missing ['joint_2', 'joint_3', 'joint_4', 'joint_5', 'joint_6']"
    )
    assert "a joint named twice" in joint_names_error("arm1", ("a", "b"), ["a", "b", "a"])
    assert "missing ['a', 'b']" in joint_names_error("arm1", ("a", "b"), [])


def test_tolerances_follow_control_msgs_zero_default_and_minus_one_erased():
    tol = lambda name, v: SimpleNamespace(name=name, position=v)  # noqa: E731 (a JointTolerance's two fields read)
    got = tolerances(("a", "b", "c", "d"), [tol("b", 0.2), tol("c", -1.0), tol("d", 0.0)], 0.01)
    assert got == (0.01, 0.2, math.inf, 0.01)
    assert (
        tolerance_miss(("a", "b"), [0.005, -0.3], (0.01, 0.2))
        == "b is 0.3000 rad from where it should be (tolerance 0.2000 rad)"
    )
    assert tolerance_miss(("a", "b"), [0.005, -0.3], (0.01, math.inf)) is None


def _client(context, node_name: str):
    executor = SingleThreadedExecutor(context=context)
    node = rclpy.create_node(node_name, context=context)
    executor.add_node(node)
    threading.Thread(target=executor.spin, daemon=True).start()
    return executor, node


def _close(actions, executor, context) -> None:
    """The action servers, the client's executor and the rclpy context, whichever were made."""
    if actions is not None:
        actions.close()
    if executor is not None:
        executor.shutdown(timeout_sec=2.0)
    rclpy.shutdown(context=context)


@contextlib.contextmanager
def _arm1_served(arm, player: TrajectoryPlayer, name: str, seed: int):
    """arm1's FollowJointTrajectory server (no namespace; the login may command ``arm``) and a client of it."""
    from control_msgs.action import FollowJointTrajectory
    from rclpy.action import ActionClient

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=1 + (os.getpid() * 13 + seed) % 100)
    actions = executor = None
    try:
        node = rclpy.create_node(f"{name}_test", context=context)
        actions = FollowTrajectoryActions(node, "", player, lambda rid, what, told: arm, lambda rid, what, why: None)
        actions.serve("arm1")
        executor, client_node = _client(context, f"{name}_client")
        client = ActionClient(client_node, FollowJointTrajectory, "/arm1/follow_joint_trajectory")
        assert client.wait_for_server(timeout_sec=30)
        yield client
    finally:
        _close(actions, executor, context)


def _result(client, goal):
    sent = client.send_goal_async(goal)
    handle = wait_until(lambda: sent.done() and sent.result(), timeout=30, what="the goal answered")
    assert handle.accepted  # taken, then aborted: the owner is checked when it runs, as a joint_trajectory's
    got = handle.get_result_async()
    wait_until(got.done, timeout=30, what="the result")
    return got.result()


def test_a_goal_for_an_arm_not_commandable_or_with_wrong_joints_is_aborted_with_the_reason():
    assert importlib.util.find_spec("control_msgs") is not None, BUILD_IT
    from control_msgs.action import FollowJointTrajectory
    from builtin_interfaces.msg import Duration
    from rclpy.action import ActionClient
    from trajectory_msgs.msg import JointTrajectoryPoint

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=1 + (os.getpid() * 13 + 46) % 100)
    refused: list[tuple[str, str, str]] = []
    # arm2 may not be commanded (the bridge's check tells why); arm1 may: a handle with its joint names, never moved
    arm1 = SimpleNamespace(entry=SimpleNamespace(joint_names=JOINTS, lower=(), upper=()), joints=None)

    def check_owner(rid: str, what: str, told) -> object:
        if rid == "arm1":
            return arm1
        why = f"rosuser does not own {rid} (owner: someone)"
        refused.append((rid, what, why))
        told(why)
        return None

    player = TrajectoryPlayer()
    actions = executor = None
    try:
        node = rclpy.create_node("follow_server_test", context=context)
        actions = FollowTrajectoryActions(
            node, "class1", player, check_owner, lambda rid, what, why: refused.append((rid, what, why))
        )
        assert actions.available
        actions.serve("arm1")
        actions.serve("arm2")
        executor, client_node = _client(context, "follow_client_test")
        goal = FollowJointTrajectory.Goal()
        goal.trajectory.joint_names = ["joint_1", "elbow"]

        client = ActionClient(client_node, FollowJointTrajectory, "/class1/arm2/follow_joint_trajectory")
        assert client.wait_for_server(timeout_sec=30)
        result = _result(client, goal)
        assert result.status == 6  # action_msgs/GoalStatus.STATUS_ABORTED
        assert result.result.error_code == FollowJointTrajectory.Result.INVALID_GOAL
        assert result.result.error_string == "rosuser does not own arm2 (owner: someone)"
        assert refused == [("arm2", "follow_joint_trajectory", result.result.error_string)]

        client = ActionClient(client_node, FollowJointTrajectory, "/class1/arm1/follow_joint_trajectory")
        assert client.wait_for_server(timeout_sec=30)
        result = _result(client, goal)
        assert result.status == 6
        assert result.result.error_code == FollowJointTrajectory.Result.INVALID_JOINTS
        assert result.result.error_string.startswith("joint_names ['joint_1', 'elbow'] are not arm1's joints")
        assert refused[1:] == [("arm1", "follow_joint_trajectory", result.result.error_string)]

        goal.trajectory.joint_names = list(JOINTS)
        goal.trajectory.points = [
            JointTrajectoryPoint(positions=[0.1] * 6, time_from_start=Duration(sec=2)),
            JointTrajectoryPoint(positions=[0.2] * 6, time_from_start=Duration(sec=1)),
        ]
        result = _result(client, goal)
        assert result.result.error_code == FollowJointTrajectory.Result.INVALID_GOAL
        assert result.result.error_string == "point 1's time_from_start 1.000 s goes back (times must not decrease)"
        assert player.playing() == set()  # nothing played for a refused goal
    finally:
        _close(actions, executor, context)


def test_a_canceled_goal_stops_the_trajectory_and_the_arm():
    assert importlib.util.find_spec("control_msgs") is not None, BUILD_IT
    from builtin_interfaces.msg import Duration
    from control_msgs.action import FollowJointTrajectory
    from trajectory_msgs.msg import JointTrajectoryPoint

    stops: list[bool] = []
    # arm1's joints and its stop, what the server reads and calls; the trajectory sent to nobody
    arm1 = SimpleNamespace(
        entry=SimpleNamespace(joint_names=JOINTS, lower=(), upper=()),
        joints=[0.0] * 6,
        follow_joints=lambda times, positions, wait: None,
        stop=lambda confirm: stops.append(confirm),
    )
    player = TrajectoryPlayer()
    with _arm1_served(arm1, player, "follow_cancel", 47) as client:
        goal = FollowJointTrajectory.Goal()
        goal.trajectory.joint_names = list(JOINTS)
        goal.trajectory.points = [JointTrajectoryPoint(positions=[0.3] * 6, time_from_start=Duration(sec=60))]
        feedback: list = []
        sent = client.send_goal_async(goal, feedback_callback=lambda m: feedback.append(m.feedback))
        handle = wait_until(lambda: sent.done() and sent.result(), timeout=30, what="the goal answered")
        wait_until(
            lambda: feedback and player.playing() == {"arm1"}, timeout=30, what="the goal playing, with feedback"
        )
        assert list(feedback[0].joint_names) == list(JOINTS) and feedback[0].index == 0
        canceling = handle.cancel_goal_async()
        wait_until(canceling.done, timeout=30, what="the cancel answered")
        got = handle.get_result_async()
        wait_until(got.done, timeout=30, what="the result")
        assert got.result().status == 5  # action_msgs/GoalStatus.STATUS_CANCELED
        assert player.playing() == set() and stops == [False]  # the trajectory dropped, the arm told to stop


def test_the_goal_is_judged_on_a_reading_taken_after_its_deadline_not_on_the_clock():
    """A starved bridge's clock (any robot's newest state) can run ahead of the arm's last reading: the goal's
    tolerance is judged by when that reading was taken (its stamp), its positions from the same sample."""
    from user_peer.ros2.follow_trajectory import _reading

    js = SimpleNamespace(q=[0.1] * 6, header=SimpleNamespace(stamp=103.2))
    q, at = _reading(SimpleNamespace(joint_state=js, joints=[9.0] * 6), t0=100.0, now=4.5)
    assert q == [0.1] * 6 and at == pytest.approx(3.2)  # read 3.2 s in, though the clock says 4.5
    unstamped = SimpleNamespace(joint_state=SimpleNamespace(q=[0.2] * 6, header=SimpleNamespace(stamp=0.0)))
    assert _reading(unstamped, t0=100.0, now=4.5) == ([0.2] * 6, 4.5)  # no reading's time: the clock
    assert _reading(SimpleNamespace(joints=[0.0] * 6), t0=100.0, now=4.5) == ([0.0] * 6, 4.5)


def test_the_start_is_where_the_arm_left_where_it_stood_by_its_readings_stamp():
    """began_at: the reading's stamp less how far along the trajectory its positions are, on the segment nearest
    them (a bridge that missed readings finds the arm past the first point)."""
    from user_peer.ros2.follow_trajectory import began_at

    q0, times, points = [0.0, 0.0], [1.0, 3.0], [[0.2, 0.0], [0.2, 0.4]]
    assert began_at(times, points, q0, q0, 50.0) is None  # not left yet
    assert began_at(times, points, q0, [0.05, 0.0], 50.0) == pytest.approx(50.0 - 0.25)
    assert began_at(times, points, q0, [0.2, 0.1], 50.0) == pytest.approx(50.0 - 1.5)  # on the second segment
    assert began_at([0.5, 1.5], [q0, [0.4, 0.0]], q0, [0.1, 0.0], 9.0) == pytest.approx(9.0 - 0.75)  # held, then
    assert began_at([1.0], [q0], q0, [0.1, 0.0], 9.0) is None  # moved, but not by this trajectory


class PlayingArm:
    """A sim's arm as the server reads it: it takes a trajectory ``late`` s after it was sent and plays it in the
    wall's time (the player's clock here) from ``q0``, joint_1 ``off(t)`` rad from the trajectory ``t`` s in."""

    entry = SimpleNamespace(joint_names=JOINTS, lower=(), upper=())

    def __init__(self, late: float = 0.0, off=lambda t: 0.0) -> None:
        self.late, self.off, self.q0 = late, off, [0.0] * 6
        self.sent: tuple[float, list, list] | None = None
        self.stops: list[bool] = []

    def follow_joints(self, times, positions, wait):
        import time

        self.sent = (time.monotonic() + self.late, list(times), [list(p) for p in positions])

    @property
    def joint_state(self):
        import time

        from fabric.interfaces import sample_trajectory

        now, q, moving = time.monotonic(), list(self.q0), False
        if self.sent is not None and now >= self.sent[0] and not self.stops:
            played, over = sample_trajectory(self.sent[1], self.sent[2], self.q0, now - self.sent[0])
            q, moving = [float(v) for v in played], not over
            q[0] += self.off(now - self.sent[0])
        return SimpleNamespace(q=q, dq=[0.3 if moving else 0.0] * 6, header=SimpleNamespace(stamp=now))

    @property
    def joints(self):
        return self.joint_state.q

    def stop(self, confirm):
        self.stops.append(confirm)


def _goal(seconds: float, *, path_tol: float = 0.0, goal_time: float = 0.0):
    """A goal to 0.3 rad on every joint in ``seconds``; joint_1's path tolerance, the goal time tolerance."""
    from builtin_interfaces.msg import Duration
    from control_msgs.action import FollowJointTrajectory
    from control_msgs.msg import JointTolerance
    from trajectory_msgs.msg import JointTrajectoryPoint

    goal = FollowJointTrajectory.Goal()
    goal.trajectory.joint_names = list(JOINTS)
    at = Duration(sec=int(seconds), nanosec=int(seconds % 1 * 1e9))
    goal.trajectory.points = [JointTrajectoryPoint(positions=[0.3] * 6, time_from_start=at)]
    if path_tol:
        goal.path_tolerance = [JointTolerance(name="joint_1", position=path_tol)]
    goal.goal_time_tolerance = Duration(sec=int(goal_time), nanosec=int(goal_time % 1 * 1e9))
    return goal


@pytest.mark.slow  # seconds: a trajectory played 2 s late
def test_a_goal_the_sim_began_late_is_judged_from_when_it_began():
    """The bridge's clock at the goal is a floor of the sim's start: a goal that reached a loaded sim 2 s late (or a
    starved bridge that heard /clock 2 s late) is judged from when the arm left where it stood, by its readings'
    stamps. Judged from the bridge's clock, this 0.5 s trajectory had not begun by its deadline (CI's 3 s one,
    2026-12-02: 0.13 rad short)."""
    assert importlib.util.find_spec("control_msgs") is not None, BUILD_IT
    import time

    from control_msgs.action import FollowJointTrajectory

    arm = PlayingArm(late=2.0)
    with _arm1_served(arm, TrajectoryPlayer(), "follow_late", 48) as client:  # its clock the wall's, as the sim's
        result = _result(client, _goal(0.5))
        assert result.result.error_code == FollowJointTrajectory.Result.SUCCESSFUL, result.result.error_string
        assert arm.sent is not None and time.monotonic() >= arm.sent[0] + 0.5  # judged after the sim's end


@pytest.mark.slow  # seconds: two trajectories played in real time
def test_an_arm_off_its_path_or_short_of_its_goal_is_told_by_how_much():
    """PATH_TOLERANCE_VIOLATED once joint_1 strays past its path tolerance while it plays (the arm stopped); and
    GOAL_TOLERANCE_VIOLATED where it ends 0.05 rad short, once the goal time tolerance after the end has passed."""
    assert importlib.util.find_spec("control_msgs") is not None, BUILD_IT
    from control_msgs.action import FollowJointTrajectory

    R = FollowJointTrajectory.Result
    stray = PlayingArm(late=0.5, off=lambda t: 0.2 if t > 0.3 else 0.0)
    with _arm1_served(stray, TrajectoryPlayer(), "follow_stray", 49) as client:
        result = _result(client, _goal(1.0, path_tol=0.05)).result
        assert result.error_code == R.PATH_TOLERANCE_VIOLATED, result.error_string
        assert result.error_string.startswith("joint_1 is 0.2") and stray.stops == [False], result.error_string
    short = PlayingArm(late=0.5, off=lambda t: -0.05)
    with _arm1_served(short, TrajectoryPlayer(), "follow_short", 50) as client:
        result = _result(client, _goal(0.5, goal_time=0.3)).result
        assert result.error_code == R.GOAL_TOLERANCE_VIOLATED, result.error_string
        assert result.error_string == (
            "joint_1 is 0.0500 rad from where it should be (tolerance 0.0100 rad), 0.30 s after the trajectory's end"
        )

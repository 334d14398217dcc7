"""The NavigateToPose action server (user_peer.ros2.navigate) with a real rclpy ActionClient: under a namespace its
name is ``/NS/ROBOT/navigate_to_pose``, and a goal for a robot this login may not command is aborted with
``GOAL_REJECTED`` and the reason, told as a refusal (the bridge's ``/rosout`` line). A goal followed to its end is
tests/user_peer/test_ros2_ros_users.py's (slow: a world, a planner and a map)."""

from __future__ import annotations

import importlib.util
import os
import threading

import rclpy
from rclpy.executors import SingleThreadedExecutor

from robofabric.testing import wait_until
from user_peer.ros2.goals import goal_of
from user_peer.ros2.navigate import NavigateActions

BUILD_IT = (
    "nav2_msgs is not importable: it is not among ROS 2 Kilted's wheels; build it into this environment with "
    "`python -m user_peer.ros2.msgbuild` (make test does; it needs g++ and Python's headers)"
)


def test_a_goal_for_a_robot_this_login_may_not_command_is_rejected_with_the_reason():
    assert importlib.util.find_spec("nav2_msgs") is not None, BUILD_IT
    from nav2_msgs.action import NavigateToPose
    from rclpy.action import ActionClient

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=1 + (os.getpid() * 11 + 46) % 100)
    executor = SingleThreadedExecutor(context=context)
    refused: list[tuple[str, str, str]] = []
    actions = None
    try:
        node = rclpy.create_node("navigate_server_test", context=context)
        actions = NavigateActions(
            node,
            "class1",
            "class1/",
            lambda rid, what: None,
            lambda rid, what, why: refused.append((rid, what, why)),
            goal_of,
        )
        assert actions.available
        actions.serve("base1")
        client_node = rclpy.create_node("navigate_client_test", context=context)
        executor.add_node(client_node)
        threading.Thread(target=executor.spin, daemon=True).start()
        client = ActionClient(client_node, NavigateToPose, "/class1/base1/navigate_to_pose")
        assert client.wait_for_server(timeout_sec=30)
        goal = NavigateToPose.Goal()
        goal.pose.header.frame_id, goal.pose.pose.orientation.w = "class1/map", 1.0
        sent = client.send_goal_async(goal)
        handle = wait_until(lambda: sent.done() and sent.result(), timeout=30, what="the goal answered")
        assert handle.accepted  # taken, then aborted: the owner is checked when it runs, as a goal_pose's
        got = handle.get_result_async()
        wait_until(got.done, timeout=30, what="the result")
        result = got.result()
        assert result.status == 6  # action_msgs/GoalStatus.STATUS_ABORTED
        assert result.result.error_code == NavigateToPose.Result.GOAL_REJECTED
        assert "may not command" in result.result.error_msg
        assert refused == [("base1", "navigate_to_pose", result.result.error_msg)]
    finally:
        if actions is not None:
            actions.close()
        executor.shutdown(timeout_sec=2.0)
        rclpy.shutdown(context=context)


def test_the_action_node_takes_the_bridges_ros_args_under_a_name_of_its_own():
    """``robofabric ros2 ... --ros-args`` reaches the action servers' node as it does the bridge's: a remap renames
    the action, a parameter is set on it; its name is the bridge's remapped name with its suffix, not the
    bridge's own (a global ``__node:=`` would have given both nodes one name)."""
    assert importlib.util.find_spec("nav2_msgs") is not None, BUILD_IT
    from rclpy.action import get_action_server_names_and_types_by_node

    context = rclpy.Context()
    rclpy.init(
        args=[
            "robofabric",
            "--ros-args",
            "-r",
            "__node:=bridge9",
            "-r",
            "/class1/base1/navigate_to_pose:=/class1/base1/go",
            "-p",
            "use_sim_time:=true",
        ],
        context=context,
        domain_id=1 + (os.getpid() * 11 + 47) % 100,
    )
    actions = None
    try:
        node = rclpy.create_node("robofabric_rosargs", context=context)
        actions = NavigateActions(
            node, "class1", "class1/", lambda rid, what: None, lambda rid, what, why: None, goal_of
        )
        actions.serve("base1")
        assert (node.get_name(), actions.node.get_name()) == ("bridge9", "bridge9_navigate")
        assert actions.node.get_parameter("use_sim_time").value is True
        served = lambda: get_action_server_names_and_types_by_node(node, "bridge9_navigate", "/")  # noqa: E731
        wait_until(lambda: served(), timeout=30, what="the action server in the graph", seen=served)
        assert served() == [("/class1/base1/go", ["nav2_msgs/action/NavigateToPose"])]
    finally:
        if actions is not None:
            actions.close()
        rclpy.shutdown(context=context)

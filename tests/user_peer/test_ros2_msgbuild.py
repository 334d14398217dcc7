"""The interface packages msgbuild.py builds are upstream's on the wire: a real rclpy node sees the built
``tf2_msgs/msg/TFMessage`` with the RIHS01 type hash ROS 2 itself gives it (tf2_msgs' golden hash, the one
``ros2 topic info -v /tf`` prints next to any ROS 2 node's /tf), so RViz, tf2 and Nav2 match it; and the builder
says what is missing instead of failing obscurely."""

from __future__ import annotations

import os

import pytest
import rclpy

from user_peer.ros2 import msgbuild

TF_MESSAGE_HASH = "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"
"""tf2_msgs/msg/TFMessage's hash in ROS 2 (Jazzy on): tf2_msgs' own test of its golden hashes."""

CONTROL_MSGS_HASHES = {
    "control_msgs/msg/JointTolerance": "RIHS01_c254f9cece0f3b733017b6990fd46d1326e25242d6b8844398c97d9a88e7d648",
    "control_msgs/msg/JointComponentTolerance": "RIHS01_739ea7566931944d33830fa10f1bf5e7a7fbdc3172bce7a7eaac642bd6e3ffa4",
    "control_msgs/action/FollowJointTrajectory_Goal": "RIHS01_8a9060704b269608f5a340934cc26e66869dd14bdac29e2e7fd9ec8b9882d205",
    "control_msgs/action/FollowJointTrajectory_Result": "RIHS01_8002e99ed2c14c6faa522f2a93c26d744c5982f254f9e98ff9c6f19789bdb220",
    "control_msgs/action/FollowJointTrajectory_SendGoal": "RIHS01_b13789dddc325a7a962825c45e28c77d37237ec129dd0c34dc5994562938c57f",
}
"""Hashes in control_msgs' generated C headers (rosidl_generator_c's ``*__TYPE_HASH``): these types are the same in
Jazzy and in Kilted/Rolling (control_msgs master, what msgbuild builds)."""
JAZZY_FEEDBACK = (
    "RIHS01_3fd0aaecf71725121ae1ff7f01098a5e0da581e672be18a6b2c286cb43d96b49",
    "RIHS01_738ebcb7a2d7cfa42f9f1001cc99ce3a4383d1cfe508015d9be8485e4b1c66f6",
)
"""FollowJointTrajectory_Feedback's and the action's hashes before control_msgs 6.3.0 added the feedback's ``index``
and ``multi_dof_index`` (Jazzy's): the same headers."""

BUILD_IT = (
    "tf2_msgs, std_srvs, nav2_msgs or control_msgs is not importable: build them into this environment with "
    "`python -m user_peer.ros2.msgbuild` (make test does; it needs g++ and Python's headers)"
)


def test_the_built_tf_message_has_upstreams_type_hash_on_the_wire():
    assert msgbuild.missing() == [], BUILD_IT
    from tf2_msgs.msg import TFMessage

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=1 + (os.getpid() * 5 + 46) % 100)
    try:
        node = rclpy.create_node("msgbuild_hash", context=context)
        node.create_publisher(TFMessage, "/tf", 10)
        (info,) = node.get_publishers_info_by_topic("/tf")
        assert (info.topic_type, str(info.topic_type_hash)) == ("tf2_msgs/msg/TFMessage", TF_MESSAGE_HASH)
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)


def test_control_msgs_types_have_upstreams_hashes():
    hashes = msgbuild.type_hashes("control_msgs")
    assert {name: hashes[name] for name in CONTROL_MSGS_HASHES} == CONTROL_MSGS_HASHES
    # the action's feedback as Jazzy defines it (without the two indices) gives Jazzy's published hashes: the IDL is
    # upstream's, field for field, and the only difference from Jazzy is what control_msgs master added
    jazzy = dict(msgbuild.INTERFACES["control_msgs"])
    action = "action/FollowJointTrajectory.idl"
    jazzy[action] = jazzy[action].replace("      int32 index;\n", "").replace("      int32 multi_dof_index;\n", "")
    assert jazzy[action] != msgbuild.INTERFACES["control_msgs"][action]
    old = msgbuild.type_hashes("control_msgs", jazzy)
    assert (
        old["control_msgs/action/FollowJointTrajectory_Feedback"],
        old["control_msgs/action/FollowJointTrajectory"],
    ) == JAZZY_FEEDBACK
    assert hashes["control_msgs/action/FollowJointTrajectory_Feedback"] != JAZZY_FEEDBACK[0]


def test_the_built_joint_tolerance_has_upstreams_type_hash_on_the_wire():
    assert msgbuild.missing() == [], BUILD_IT
    from control_msgs.action import FollowJointTrajectory
    from control_msgs.msg import JointComponentTolerance, JointTolerance

    assert (JointComponentTolerance.ROTATION, FollowJointTrajectory.Result.GOAL_TOLERANCE_VIOLATED) == (5, -5)
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=1 + (os.getpid() * 5 + 47) % 100)
    try:
        node = rclpy.create_node("msgbuild_control_hash", context=context)
        node.create_publisher(JointTolerance, "/tolerance", 10)
        (info,) = node.get_publishers_info_by_topic("/tolerance")
        assert str(info.topic_type_hash) == CONTROL_MSGS_HASHES["control_msgs/msg/JointTolerance"]
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)


def test_a_built_package_says_so_and_a_second_run_builds_nothing(capsys):
    assert msgbuild.missing() == [], BUILD_IT
    assert msgbuild.main([]) == 0
    assert capsys.readouterr().out == "already importable: tf2_msgs, std_srvs, nav2_msgs, control_msgs\n"


def test_what_cannot_be_built_is_said(monkeypatch, capsys):
    assert msgbuild.main(["moveit_msgs"]) == 2
    assert (
        "unknown package moveit_msgs: this builds tf2_msgs, std_srvs, nav2_msgs, control_msgs"
        in capsys.readouterr().err
    )
    with pytest.raises(SystemExit) as out:  # --help explains, and is no package's name
        msgbuild.main(["--help"])
    assert out.value.code == 0 and "--force" in capsys.readouterr().out
    monkeypatch.setenv("CXX", "no-such-compiler-here")
    with pytest.raises(msgbuild.MsgBuildError, match="no g\\+\\+ on PATH: install a C and C\\+\\+ compiler"):
        msgbuild._compiler("g++")

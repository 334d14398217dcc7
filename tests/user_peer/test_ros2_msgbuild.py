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

BUILD_IT = ("tf2_msgs, std_srvs or nav2_msgs is not importable: build them into this environment with "
            "`python -m user_peer.ros2.msgbuild` (make test does; it needs g++ and Python's headers)")


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


def test_a_built_package_says_so_and_a_second_run_builds_nothing(capsys):
    assert msgbuild.missing() == [], BUILD_IT
    assert msgbuild.main([]) == 0
    assert capsys.readouterr().out == "already importable: tf2_msgs, std_srvs, nav2_msgs\n"


def test_what_cannot_be_built_is_said(monkeypatch, capsys):
    assert msgbuild.main(["control_msgs"]) == 2
    assert "unknown package control_msgs: this builds tf2_msgs, std_srvs, nav2_msgs" in capsys.readouterr().err
    monkeypatch.setenv("CXX", "no-such-compiler-here")
    with pytest.raises(msgbuild.MsgBuildError, match="no g\\+\\+ on PATH: install a C and C\\+\\+ compiler"):
        msgbuild._compiler("g++")

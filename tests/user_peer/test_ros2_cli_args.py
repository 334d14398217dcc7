"""``robofabric ros2``'s ROS arguments (issue 46): what follows ``--ros-args`` goes to rclpy; anything else left
over is an error that says where ROS arguments go."""

from __future__ import annotations

import pytest

from fabric.cli_common import UserError
from user_peer.ros2.cli import ros_args


def test_ros_arguments_after_ros_args_pass_through_and_none_is_none():
    assert ros_args(["--ros-args", "-r", "__node:=b1", "-p", "use_sim_time:=true"]) == [
        "--ros-args",
        "-r",
        "__node:=b1",
        "-p",
        "use_sim_time:=true",
    ]
    assert ros_args([]) == []


def test_a_stray_argument_is_refused_with_where_ros_arguments_go():
    with pytest.raises(
        UserError, match="unexpected arguments -r __node:=b1: ROS 2 arguments go last, after --ros-args"
    ):
        ros_args(["-r", "__node:=b1"])

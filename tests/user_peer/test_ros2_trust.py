"""The ROS 2 bridge's trust boundary (user_peer/ros2/trust.py): discovery on this host unless the user set it or
asks, and what the bridge says at start about whom it takes commands from. The live side (a plain rclpy node's
cmd_vel with and without --drive) is tests/user_peer/test_ros2_bridge.py."""

from __future__ import annotations

import pytest

from user_peer.ros2.trust import RANGE_VAR, boundary_lines, discovery


def test_discovery_stays_on_this_host_unless_the_user_set_it_or_asks():
    d = discovery({}, None)
    assert (d.range, d.source, dict(d.set_env)) == ("localhost", "default", {RANGE_VAR: "LOCALHOST"})
    d = discovery({RANGE_VAR: "SUBNET"}, None)  # the user's own choice is kept, and nothing set over it
    assert (d.range, d.source, dict(d.set_env)) == ("subnet", "environment", {})
    d = discovery({RANGE_VAR: "LOCALHOST"}, "subnet")  # the option wins over the environment
    assert (d.range, d.source, dict(d.set_env)) == ("subnet", "option", {RANGE_VAR: "SUBNET"})
    assert discovery({RANGE_VAR: " "}, None).source == "default"
    with pytest.raises(ValueError, match="--discovery must be one of localhost, subnet, off, system_default"):
        discovery({}, "lan")


def test_the_bridge_says_whom_it_takes_commands_from():
    only_publish = boundary_lines("ros", (), "42", discovery({}, None))
    assert only_publish == [
        "DDS discovery: this host only (the bridge's default; --discovery subnet opens it); ROS domain 42",
        "commands: none taken (publishing only); --drive ROBOT takes cmd_vel and joint commands for it",
    ]
    lan = boundary_lines("ros", ("base1", "arm1"), "42", discovery({}, "subnet"))
    assert lan[0].startswith("DDS discovery: the local network")
    assert lan[1] == (
        "commands: taken for arm1, base1 only, from any node that discovers it on ROS domain 42 (ROS 2 has no "
        "logins), sent as 'ros' while 'ros' owns the robot"
    )
    assert "any node on this host" in boundary_lines("ros", ("base1",), "0", discovery({}, None))[1]

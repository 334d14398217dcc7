"""The ownership services' names and their refusals, with a real rclpy node and client in one process (the live
test in test_ros2_ros_users.py asks a real authority): each driven robot gets ``request_ownership`` and
``release_ownership`` under the namespace, they go with the robot, and a refusal comes back as ``success``
False with the reason, not as an error of the bridge. ``std_srvs`` is built by user_peer/ros2/msgbuild.py."""

from __future__ import annotations

import os
import time

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor

from user_peer.errors import FabricUserError
from user_peer.ros2.ownership_services import OwnershipServices, trigger_class

BUILD_IT = (
    "std_srvs is not importable: it is not among ROS 2 Kilted's wheels; build it into this environment with "
    "`python -m user_peer.ros2.msgbuild` (make test does; it needs g++ and Python's headers)"
)


@pytest.fixture
def node():
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=1 + (os.getpid() * 3 + 46) % 100)
    n = rclpy.create_node("ownership_services_test", context=context)
    yield n
    n.destroy_node()
    rclpy.shutdown(context=context)


def no_such_robot(rid: str):
    raise FabricUserError(f"no robot {rid} in world w")


def services(node) -> set[str]:
    return {name for name, types in node.get_service_names_and_types() if types == ["std_srvs/srv/Trigger"]}


def test_each_driven_robot_has_its_two_services_under_the_namespace_until_it_leaves(node):
    assert trigger_class() is not None, BUILD_IT
    asking = OwnershipServices(node, "class1", no_such_robot, "alice")
    asking.add("base1")
    asking.add("base1")  # once
    asking.add("arm1")
    assert services(node) == {
        f"/class1/{r}/{s}" for r in ("base1", "arm1") for s in ("request_ownership", "release_ownership")
    }
    asking.forget("arm1")
    assert services(node) == {"/class1/base1/request_ownership", "/class1/base1/release_ownership"}


def test_a_refusal_is_an_unsuccessful_response_with_the_reason(node):
    trigger = trigger_class()
    assert trigger is not None, BUILD_IT
    asking = OwnershipServices(node, "", no_such_robot, "alice")
    asking.add("base9")
    client = node.create_client(trigger, "/base9/request_ownership")
    assert client.wait_for_service(timeout_sec=30)
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    future = client.call_async(trigger.Request())
    deadline = time.monotonic() + 30
    while not future.done() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.1)
    executor.remove_node(node)
    assert future.done(), "no response in 30 s"
    assert (future.result().success, future.result().message) == (False, "base9: no robot base9 in world w")
    assert asking.calls == 1

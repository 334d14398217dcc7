"""Each robot's owner on ROS 2 (user_peer.ros2.owners): a latched ``/NS/ROBOT/owner`` String, the owner's login or
empty when free, published when it changes (a node that subscribes later still gets the current owner), its topic
gone with its robot. A real rclpy node in this process reads it."""

from __future__ import annotations

import os

import rclpy
from rclpy.executors import SingleThreadedExecutor
from std_msgs.msg import String

from fabric.interfaces import OwnershipRecord
from robofabric.testing import wait_until
from user_peer.ros2.owners import OWNER_QOS, OwnersOut, owner_text


def test_the_owner_text_is_the_login_or_empty():
    assert owner_text(OwnershipRecord("base1", owner="alice", epoch=2)) == "alice"
    assert owner_text(OwnershipRecord("base1")) == "" and owner_text(None) == ""


def test_a_late_subscriber_gets_the_current_owner_and_each_change_once(monkeypatch):
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    ctx = rclpy.Context()
    ctx.init(domain_id=1 + (os.getpid() * 7 + 61) % 100)
    node = rclpy.create_node("owners_test", context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    records = {"base1": OwnershipRecord("base1", owner="alice", epoch=1), "arm1": None}
    got: list[str] = []
    try:
        out = OwnersOut(node, "class1")
        out.update(["base1", "arm1"], records.get)
        out.update(["base1", "arm1"], records.get)  # nothing changed: nothing more sent
        assert out.sent == 2
        node.create_subscription(
            String, "/class1/base1/owner", lambda m: got.append(m.data), OWNER_QOS
        )  # after: latched

        def spun(cond):
            ex.spin_once(timeout_sec=0.1)
            return cond()

        wait_until(lambda: spun(lambda: got == ["alice"]), timeout=30, what="the latched owner", seen=lambda: got)
        records["base1"] = OwnershipRecord("base1", epoch=2)  # released: free
        out.update(["base1", "arm1"], records.get)
        wait_until(lambda: spun(lambda: got == ["alice", ""]), timeout=30, what="base1 free", seen=lambda: got)
        out.update(["arm1"], records.get)  # base1 left the world
        assert node.count_publishers("/class1/base1/owner") == 0 and out.sent == 3
    finally:
        ex.shutdown()
        node.destroy_node()
        ctx.try_shutdown()

"""A topic map from YAML (user_peer.ros2.topic_map): renames, QoS and allow/deny as the file says, a file that
cannot be used refused with what is wrong and where (and ``robofabric ros2 --topic-map`` exits 2 saying so), and
a real rclpy node made through the map publishes under the new name with the new QoS, and nothing for a denied
topic."""

from __future__ import annotations

import os
import subprocess

import pytest
import rclpy
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import LaserScan
from std_msgs.msg import String

from robofabric.testing import robofabric_cmd
from user_peer.ros2.topic_map import MappedNode, TopicMap, TopicMapError, is_off, load_topic_map, parse_topic_map

GOOD = """
rename:
  /base1/scan: /scan
qos:
  /base1/scan: {reliability: reliable, depth: 7}
allow: [/base1/*, /map]
deny: [/base1/sonar*]
"""


def test_the_file_renames_sets_qos_and_allows_and_denies(tmp_path):
    (tmp_path / "m.yaml").write_text(GOOD)
    m = load_topic_map(tmp_path / "m.yaml")
    assert m.name("/base1/scan") == "/scan" and m.name("/base1/odom") == "/base1/odom" and m.name("/map") == "/map"
    assert m.name("/base1/sonar") is None and m.name("/base1/sonar_3") is None  # deny wins over allow
    assert m.name("/clock") is None and m.name("/arm1/joint_states") is None  # not allowed
    q = m.profile("/base1/scan", qos_profile_sensor_data)
    assert (q.reliability, q.depth, q.durability) == (ReliabilityPolicy.RELIABLE, 7, qos_profile_sensor_data.durability)
    assert m.profile("/base1/odom", 10) == 10
    assert parse_topic_map(None) == TopicMap() and TopicMap().name("/anything") == "/anything"
    assert m.summary() == "1 renamed, QoS set for 1, only /base1/*, /map, never /base1/sonar*"


@pytest.mark.parametrize(
    "text,says",
    [
        ("- /a\n", "not a mapping"),
        ("remap: {}\n", "unknown section 'remap'"),
        ("rename: {/a: b}\n", "'b' is not an absolute topic name"),
        ("rename: {/a: /1b}\n", "'/1b' is not a ROS topic name"),
        ("rename: {/a: /c, /b: /c}\n", "gives '/c' to two topics"),
        ("qos: {/a: {reliability: sometimes}}\n", "reliability 'sometimes' is not one of reliable, best_effort"),
        ("qos: {/a: {depth: 0}}\n", "depth 0 is not a whole number"),
        ("qos: {/a: {lifespan: 3}}\n", "unknown QoS field 'lifespan'"),
        ("deny: [scan]\n", "deny: give a list of absolute topic names"),
        ("rename: [/a\n", "not YAML"),
    ],
)
def test_a_map_that_cannot_be_used_is_refused_saying_what_is_wrong(tmp_path, text, says):
    (tmp_path / "m.yaml").write_text(text)
    with pytest.raises(TopicMapError, match="topic map .*m.yaml") as e:
        load_topic_map(tmp_path / "m.yaml")
    assert says in str(e.value)


@pytest.mark.slow
def test_the_bridge_refuses_a_bad_map_at_start_with_exit_2(tmp_path):
    (tmp_path / "m.yaml").write_text("rename: {/base1/scan: scan}\n")
    r = subprocess.run(
        robofabric_cmd("ros2", "--world", "nowhere", "--topic-map", str(tmp_path / "m.yaml")),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 2 and "'scan' is not an absolute topic name" in r.stderr, (r.returncode, r.stderr[-1500:])


def test_a_node_through_the_map_publishes_renamed_with_the_maps_qos_and_nothing_denied(monkeypatch):
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    ctx = rclpy.Context()
    ctx.init(domain_id=1 + (os.getpid() * 7 + 62) % 100)
    node = rclpy.create_node("topic_map_test", context=ctx)
    try:
        mapped = MappedNode(
            node,
            parse_topic_map(
                {
                    "rename": {"/base1/scan": "/scan"},
                    "qos": {"/base1/scan": {"reliability": "reliable", "durability": "transient_local"}},
                    "deny": ["/object/*"],
                }
            ),
        )
        pub = mapped.create_publisher(LaserScan, "/base1/scan", qos_profile_sensor_data)
        off = mapped.create_publisher(String, "/object/goal/pose", QoSProfile(depth=10))
        sub = mapped.create_subscription(String, "/object/goal/cmd", lambda m: None, 10)
        info = node.get_publishers_info_by_topic("/scan")
        assert len(info) == 1 and info[0].qos_profile.reliability == ReliabilityPolicy.RELIABLE
        assert info[0].qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
        assert node.count_publishers("/base1/scan") == 0 and node.count_publishers("/object/goal/pose") == 0
        assert is_off(off) and is_off(sub) and not is_off(pub) and off.get_subscription_count() == 0
        off.publish(String(data="nobody hears this"))
        assert mapped.off == {"/object/goal/pose", "/object/goal/cmd"} and mapped.get_name() == "topic_map_test"
        mapped.destroy_publisher(off)
        mapped.destroy_subscription(sub)
        mapped.destroy_publisher(pub)
        assert node.count_publishers("/scan") == 0
    finally:
        node.destroy_node()
        ctx.try_shutdown()

"""docs/ros2/robofabric.rviz shows what the bridge and the export publish: every display's topic is a name
``ros2_topic`` gives the demo's robots (base1, a mobile base; arm1, an arm), with the QoS the bridge offers
(best effort for scans, transient local for the map and a path), in the fixed frame ``map`` (REP 105's, the tree's root). rviz2 itself is not
installable here (no wheel): this checks the file against the topic table, not rviz2's rendering."""

from __future__ import annotations

from pathlib import Path

import yaml

from user_peer.openfmt.ros2 import ros2_topic

RVIZ = Path(__file__).resolve().parents[2] / "docs" / "ros2" / "robofabric.rviz"

PUBLISHED = {
    ros2_topic("rf/w/robot/base1/scan"): "Best Effort",
    ros2_topic("rf/w/robot/base1/sonar"): "Best Effort",
    ros2_topic("rf/w/robot/base1/pose", "mobile"): "Volatile",
    ros2_topic("rf/w/robot/base1/path"): "Transient Local",
    ros2_topic("rf/w/robot/arm1/pose", "arm"): "Volatile",
    ros2_topic("rf/w/map/map"): "Transient Local",
}


def test_the_rviz2_configuration_shows_the_bridges_topics_with_its_qos_in_the_map_frame():
    doc = yaml.safe_load(RVIZ.read_text())
    manager = doc["Visualization Manager"]
    assert manager["Global Options"]["Fixed Frame"] == "map"
    shown = {}
    for display in manager["Displays"]:
        topic = display.get("Topic")
        if topic:
            shown[topic["Value"]] = topic
    assert set(shown) == set(PUBLISHED), sorted(shown)
    for name, policy in PUBLISHED.items():
        qos = shown[name]
        if policy == "Best Effort":
            assert qos["Reliability Policy"] == "Best Effort", name
        else:
            assert qos["Reliability Policy"] == "Reliable" and qos["Durability Policy"] == policy, name
    assert any(d["Class"] == "rviz_default_plugins/TF" for d in manager["Displays"])
    # each robot's model from its latched robot_description (user_peer.ros2.models), with the same QoS
    models = {
        d["Description Topic"]["Value"]: d
        for d in manager["Displays"]
        if d["Class"] == "rviz_default_plugins/RobotModel"
    }
    assert set(models) == {"/arm1/robot_description", "/base1/robot_description"}, sorted(models)
    for name, d in models.items():
        q = d["Description Topic"]
        assert d["Description Source"] == "Topic" and (q["Reliability Policy"], q["Durability Policy"]) == (
            "Reliable",
            "Transient Local",
        )
        assert d["TF Prefix"] == name.split("/")[1]  # the robot's frames are under its id

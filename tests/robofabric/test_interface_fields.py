"""The fields listing of ``robofabric interfaces``: read off each type's ``SPEC``, in wire order."""

from __future__ import annotations

from fabric.interfaces import LidarInfo, RobotInfo, SonarInfo
from robofabric.interface_fields import fields_of, message_types


def test_every_registered_type_lists_its_wire_fields_in_order():
    """Each type's listing names exactly its SPEC's fields, in the order the wire carries them."""
    types = message_types()
    assert {"JointState", "RobotInfo", "WorldInfo", "Command"} <= set(types)
    for name, cls in types.items():
        assert [f.name for f in fields_of(cls)] == list(cls.SPEC), name


def test_types_ranges_and_defaults_are_described():
    """An optional part reads ``T | None`` with its default, a bounded number its range, an array its shape."""
    robot = {f.name: f for f in fields_of(RobotInfo)}
    assert robot["lidar"].type == "LidarInfo | None" and robot["lidar"].default == "None"
    lidar = {f.name: f for f in fields_of(LidarInfo)}
    assert (lidar["rays"].type, lidar["rays"].constraints) == ("int", "[1, 8192]")
    assert (lidar["range_min"].type, lidar["range_min"].constraints) == ("float", "[0, inf]")
    sonar = {f.name: f for f in fields_of(SonarInfo)}
    assert sonar["center"].type == "float64[2]" and sonar["angles"].type == "float64[]"

"""RobotCatalog: what a robot id is and where it stands, from the sim's typed world description first."""

import math

import numpy as np

from fabric.interfaces import RobotInfo, WorldInfo
from user_peer.catalog import RobotCatalog, placement_xyz_yaw


def _world(rid: str, rtype: str, kind: str, pose) -> WorldInfo:
    r = RobotInfo(rid, rtype, kind, np.array(pose, dtype=float), (), np.zeros(0), np.zeros(0), np.zeros(0))
    return WorldInfo("w", "arm_cell", 0.002, {}, (r,))


def test_the_world_description_names_the_type_and_the_base_of_an_id():
    d = RobotCatalog(_world("zarm", "meca500", "arm", [1.0, 2.0, 0.1, math.pi / 2])).drawing("zarm", {})
    assert (d.type, d.kind) == ("meca500", "arm")
    assert np.allclose(d.base.translation, [1.0, 2.0, 0.1])
    assert np.allclose(d.base.quat_xyzw, [0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4)])


def test_an_id_the_description_lacks_falls_back_to_the_scenes_then_joint_names():
    cat = RobotCatalog(_world("zarm", "meca500", "arm", [0, 0, 0, 0]), scene="arm_cell")
    assert cat.drawing("nobody", {}).type == ""
    joints = cat.descriptions()["meca500"].joint_names
    assert cat.drawing("nobody", {"joint_names": joints}).type == "meca500"
    assert RobotCatalog(None).drawing("nobody", {}).type == ""


def test_a_yaw_placement_is_the_quaternion_of_the_heading_in_x_y_z_w_order():
    p = placement_xyz_yaw(0.0, 0.0, 0.0, -2.0)
    assert np.allclose(p.quat_xyzw, [0.0, 0.0, math.sin(-1.0), math.cos(-1.0)])

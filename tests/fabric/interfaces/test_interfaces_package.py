"""The interfaces package: every built-in type registered under its class name, the wire form of before the
move, and no second import path for the types.

``GOLDEN`` holds bytes encoded at commit 9679bd3, before the types moved here (they lived in
``fabric.messages``, ``sim_peer.messages``, ``compute_peer.messages``, ``compute_peer.navigation.messages`` and
``ownership.messages``): recordings made then must still decode to the same messages.
"""

from __future__ import annotations

import importlib

import numpy as np
import pytest

import fabric.interfaces as fi
from fabric.codec import decode, encode, messages_equal, registered

GOLDEN = {
    "JointState": "95aa4a6f696e74537461746592a26a31a26a32c716010101020000009a9999999999b93f9a9999999999c9bfc716010101020000000000000000000000000000000000e03f96a6486561646572cb3ff8000000000000cf17979cfe362a000007a473696d3102",
    "Pose": "97a4506f7365c71e01010103000000000000000000f03f00000000000000400000000000000000c72601010104000000000000000000f03f000000000000000000000000000000000000000000000000c71e01010103000000000000000000000000000000000000000000000000000000c71e01010103000000000000000000000000000000000000000000000000000000a5776f726c6495a6486561646572cb3fd00000000000000501a175",
    "Scan": "96a45363616ecbbff0000000000000cb3fe0000000000000cb4028000000000000c70e01050104000000f401e803e02ee02e96a6486561646572cb3ff8000000000000cf17979cfe362a000007a473696d3102",
    "Command": "95a7436f6d6d616e64a5616c6963650394ab4a6f696e74546172676574c7160101010200000000000000000000009a9999999999b93fcb3fe000000000000095a6486561646572cb00000000000000000000a095a6486561646572cb3fd00000000000000501a175",
    "OwnershipRecord": "9aaf4f776e6572736869705265636f7264a461726d31a96578636c7573697665a5616c69636504cb402900000000000091a3626f62a66d6f76696e67a473696d3196a6486561646572cb3ff8000000000000cf17979cfe362a000007a473696d3102",
    "Event": "98a54576656e74a672656a656374a96e6f745f6f776e6572a461726d31a3626f62a77761726e696e6781a7636f6d6d616e64a66a6f696e747396a6486561646572cb3ff8000000000000cf17979cfe362a000007a473696d3102",
    "IKRequest": "97a9494b52657175657374c71e010101030000009a9999999999c93f0000000000000000333333333333d33fc70601010100000000c73601010106000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000a5776f726c64a46175746f95a6486561646572cb3fd00000000000000501a175",
    "PlanRequest": "9aab506c616e52657175657374a56261736531c71e01010103000000000000000000f03f0000000000000040000000000000e03fc70601010100000000ac6879627269645f6173746172a36d6170a764656661756c74cb0000000000000000cb000000000000000095a6486561646572cb3fd00000000000000501a175",
    "OwnRequest": "95aa4f776e52657175657374a772657175657374a5616c6963650195a6486561646572cb3fd00000000000000501a175",
    "ObjectInfo": "96aa4f626a656374496e666fa6746172676574a9696b5f746172676574a57363656e65c71e0101010300000000000000000008400000000000000000000000000000f03fc72601010104000000000000000000f03f000000000000000000000000000000000000000000000000",
}


def _samples() -> dict:
    h = fi.Header(stamp=1.5, wall_ns=1700000000000000000, seq=7, source="sim1", term=2)
    h0 = fi.Header(stamp=0.25, wall_ns=5, seq=1, source="u")
    return {
        "JointState": fi.JointState(("j1", "j2"), np.array([0.1, -0.2]), np.array([0.0, 0.5]), h),
        "Pose": fi.Pose(np.array([1.0, 2.0, 0.0]), np.array([1.0, 0.0, 0.0, 0.0]), header=h0),
        "Scan": fi.Scan.from_ranges(
            [0.5, 1.0, 12.0, float("inf")], angle_min=-1.0, angle_increment=0.5, range_max=12.0, header=h
        ),
        "Command": fi.Command("alice", 3, fi.JointTarget(np.array([0.0, 0.1]), 0.5), h0),
        "OwnershipRecord": fi.OwnershipRecord("arm1", "exclusive", "alice", 4, 12.5, ("bob",), "moving", "sim1", h),
        "Event": fi.Event(fi.EventKind.REJECT, "not_owner", "arm1", "bob", "warning", {"command": "joints"}, h),
        "IKRequest": fi.IKRequest.make([0.2, 0.0, 0.3], None, [0.0] * 6, header=h0),
        "PlanRequest": fi.PlanRequest("base1", goal=np.array([1.0, 2.0, 0.5]), header=h0),
        "OwnRequest": fi.OwnRequest("request", "alice", True, h0),
        "ObjectInfo": fi.ObjectInfo(
            "target", "ik_target", "scene", np.array([3.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0, 0.0])
        ),
    }


@pytest.mark.parametrize("name", sorted(GOLDEN))
def test_the_wire_form_is_the_one_of_before_the_move(name):
    msg = _samples()[name]
    assert encode(msg).hex() == GOLDEN[name]
    assert messages_equal(decode(bytes.fromhex(GOLDEN[name])), msg)


def test_every_built_in_type_is_registered_under_its_class_name():
    types = registered()
    mine = {n: c for n, c in types.items() if c.__module__.startswith("fabric.interfaces")}
    assert all(c.__name__ == n for n, c in mine.items())
    before = {  # the wire type names before the move: none may disappear or be renamed
        "Header",
        "JointState",
        "Pose",
        "Scan",
        "Path",
        "OccupancyGrid",
        "JointTarget",
        "Twist",
        "Stop",
        "Reset",
        "Command",
        "OwnershipRecord",
        "Event",
        "RobotInfo",
        "ObjectInfo",
        "WorldInfo",
        "RobotState",
        "WorldState",
        "IKRequest",
        "IKReply",
        "FKRequest",
        "FKReply",
        "JacobianRequest",
        "JacobianReply",
        "IKStream",
        "PlanRequest",
        "PlanReply",
        "MapRequest",
        "MapReply",
        "OwnRequest",
        "OwnReply",
    }
    assert before <= set(mine)
    assert set(mine) - before == {"BaseInfo", "LidarInfo", "SonarInfo", "JointTrajectory"}  # added since
    assert {n for n in fi.__all__ if n in types} == set(mine)  # each is exported by fabric.interfaces


@pytest.mark.parametrize(
    "old",
    [
        "fabric.messages",
        "sim_peer.messages",
        "compute_peer.messages",
        "compute_peer.navigation.messages",
        "ownership.messages",
    ],
)
def test_the_peers_message_modules_are_gone(old):
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module(old)

import pytest

from fabric import keys


def test_builders_follow_design_layout():
    assert keys.robot_joints("demo", "arm1") == "rf/demo/robot/arm1/joints"
    assert keys.robot_pose("demo", "base1") == "rf/demo/robot/base1/pose"
    assert keys.robot_scan("demo", "base1") == "rf/demo/robot/base1/scan"
    assert keys.robot_path("demo", "base1") == "rf/demo/robot/base1/path"
    assert keys.robot_cmd("demo", "arm1", "joints") == "rf/demo/robot/arm1/cmd/joints"
    assert keys.object_pose("demo", "target") == "rf/demo/object/target/pose"
    assert keys.map_key("demo", "floor") == "rf/demo/map/floor"
    assert keys.own("demo", "arm1") == "rf/demo/own/arm1"
    assert keys.srv("demo", "ik", "arm1") == "rf/demo/srv/ik/arm1"
    assert keys.peer("demo", "sim", "s1") == "rf/demo/peer/sim/s1"
    assert keys.event("demo", "reject", "arm1") == "rf/demo/event/reject/arm1"
    assert keys.world_all("demo") == "rf/demo/**"


@pytest.mark.parametrize("bad", ["", "a/b", "a*", "$x", "a#", "a?", "a b", "..", "tab\there"])
def test_bad_ids_raise_naming_the_id(bad):
    with pytest.raises(ValueError) as err:
        keys.robot_joints("demo", bad)
    assert "robot id" in str(err.value)
    if bad:
        assert repr(bad) in str(err.value)


def test_unknown_stream_command_service_kind():
    with pytest.raises(ValueError, match="unknown command"):
        keys.robot_cmd("demo", "arm1", "fly")
    with pytest.raises(ValueError, match="unknown service"):
        keys.srv("demo", "teleport")
    with pytest.raises(ValueError, match="unknown peer kind"):
        keys.peer("demo", "ghost", "x")


@pytest.mark.parametrize(
    "key,expected",
    [
        ("rf/w/robot/arm1/joints", ("robot", "arm1", "joints")),
        ("rf/w/robot/arm1/cmd/twist", ("cmd", "arm1", "twist")),
        ("rf/w/object/goal/pose", ("object", "goal", "pose")),
        ("rf/w/map/floor", ("map", "floor", "")),
        ("rf/w/own/arm1", ("own", "arm1", "")),
        ("rf/w/srv/ik/arm1", ("srv", "ik", "arm1")),
        ("rf/w/peer/user/alice", ("peer", "user", "alice")),
        ("rf/w/event/reject/arm1", ("event", "reject", "arm1")),
    ],
)
def test_parse_inverts_builders(key, expected):
    p = keys.parse(key)
    assert p.world == "w"
    assert (p.category, p.subject, p.leaf) == expected


@pytest.mark.parametrize("bad", ["ros/x/y", "rf", "rf/w/robot/arm1", "rf/w/robot/arm1/cmd/fly", "rf/w/nope/x", "rf/w/robot/*/pose"])
def test_parse_rejects_foreign_or_malformed_keys(bad):
    with pytest.raises(ValueError):
        keys.parse(bad)

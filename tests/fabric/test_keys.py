import pytest

from fabric import keys


def test_builders_follow_design_layout():
    assert keys.robot_joints("demo", "arm1") == "rf/demo/robot/arm1/joints"
    assert keys.robot_pose("demo", "base1") == "rf/demo/robot/base1/pose"
    assert keys.robot_scan("demo", "base1") == "rf/demo/robot/base1/scan"
    assert keys.robot_path("demo", "base1") == "rf/demo/robot/base1/path"
    assert keys.robot_cmd("demo", "arm1", "joints", "alice") == "rf/demo/robot/arm1/cmd/joints/by/alice"
    assert keys.robot_cmd_all("demo") == "rf/demo/robot/*/cmd/*/by/*"
    assert keys.object_pose("demo", "target", "bob") == "rf/demo/object/target/pose/by/bob"
    assert keys.object_pose_all("demo", "target") == "rf/demo/object/target/pose/by/*"
    assert keys.own_request("demo", "arm1", "alice") == "rf/demo/own/arm1/by/alice"
    assert keys.own_request_all("demo") == "rf/demo/own/*/by/*"
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
        keys.robot_cmd("demo", "arm1", "fly", "alice")
    with pytest.raises(ValueError, match="unknown service"):
        keys.srv("demo", "teleport")
    with pytest.raises(ValueError, match="unknown peer kind"):
        keys.peer("demo", "ghost", "x")


@pytest.mark.parametrize(
    "key,expected",
    [
        ("rf/w/robot/arm1/joints", ("robot", "arm1", "joints")),
        ("rf/w/robot/arm1/cmd/twist/by/alice", ("cmd", "arm1", "twist")),
        ("rf/w/object/goal/pose/by/bob", ("object", "goal", "pose")),
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


@pytest.mark.parametrize(
    "bad",
    [
        "ros/x/y",
        "rf",
        "rf/w/robot/arm1",
        "rf/w/robot/arm1/cmd/fly/by/a",
        "rf/w/robot/arm1/cmd/twist",
        "rf/w/robot/arm1/cmd/twist/to/alice",
        "rf/w/object/goal/pose",
        "rf/w/nope/x",
        "rf/w/robot/*/pose",
    ],
)
def test_parse_rejects_foreign_or_malformed_keys(bad):
    with pytest.raises(ValueError):
        keys.parse(bad)


def test_user_keys_name_the_writer():
    """Everything a user writes names the user in the key, where the router's access control sees it."""
    assert keys.parse(keys.robot_cmd("w", "arm1", "stop", "alice")).user == "alice"
    assert keys.parse(keys.object_pose("w", "goal", "bob")).user == "bob"
    p = keys.parse(keys.own_request("w", "arm1", "carol"))
    assert (p.category, p.subject, p.user) == ("own_request", "arm1", "carol")
    assert keys.parse(keys.own("w", "arm1")).user == ""
    with pytest.raises(ValueError, match="user id"):
        keys.robot_cmd("w", "arm1", "stop", "a/b")
    with pytest.raises(ValueError, match="user id"):
        keys.own_request("w", "arm1", "*")


def test_in_world_takes_full_or_world_relative_expressions():
    """What the tools and launch files accept from a person: the one place that turns it into a key."""
    assert keys.in_world("rf/other/robot/**", "demo") == "rf/other/robot/**"
    assert keys.in_world("robot/*/pose", "demo") == "rf/demo/robot/*/pose"
    assert keys.in_world("/robot/*/pose", "demo") == "rf/demo/robot/*/pose"
    with pytest.raises(ValueError, match="'robot/\\*\\*/\\*\\*' is not a valid key expression"):
        keys.in_world("robot/**/**", "demo")
    with pytest.raises(ValueError, match="world"):
        keys.in_world("robot/*/pose", "a b")

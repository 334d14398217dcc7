"""The robot streams' one table (fabric/streams.py): what each consumer derives from it is what it listed by hand
before, and no other module of the product lists stream names of its own.

The pinned values below are the consumers' tuples, sets and maps as they were written out in each module before
the table; a change to the table that changes one of them shows here. The scan walks the product's sources for a
literal tuple, list, set or dict whose items or keys hold two or more stream names: such a literal is a second
list that nothing checks against the table (docs/howto.md, "A new sensor stream").
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import fabric.interfaces as interfaces
from fabric import fencing, keys, streams
from fabric.streams import STREAMS, RobotStream, Ros2Topic

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("fabric", "sim_peer", "compute_peer", "ownership", "user_peer", "robofabric")
TABLE = "fabric/streams.py"

# ---------------------------------------------------------------- (a) every consumer's values, pinned


def test_the_key_layout_and_latching():
    assert keys.ROBOT_STREAMS == ("joints", "pose", "scan", "sonar", "path", "ik")
    assert keys.LATCHED_STREAMS == frozenset({"path"})
    assert [keys.is_latched(keys.robot_stream("w", "r1", s)) for s in keys.ROBOT_STREAMS] == [False] * 4 + [True, False]
    with pytest.raises(ValueError, match="expected one of joints, pose, scan, sonar, path, ik"):
        keys.robot_stream("w", "r1", "radar")


def test_fencing_applies_to_the_sim_authority_streams():
    assert fencing.AUTHORITY_STREAMS == frozenset({"joints", "pose", "scan", "sonar"})
    fenced = [fencing.is_authority_key(keys.robot_stream("w", "r1", s)) for s in keys.ROBOT_STREAMS]
    assert fenced == [True] * 4 + [False] * 2


def test_declared_message_types():
    from robofabric.declarations import STREAM_TYPES, key_type

    assert STREAM_TYPES == {
        "joints": "JointState",
        "pose": "Pose",
        "scan": "Scan",
        "sonar": "Scan",
        "path": "Path",
        "ik": "IKStream",
    }
    assert key_type("rf/w/robot/base1/sonar") == "Scan"
    for s in STREAMS:  # each names a message type the fabric has
        assert isinstance(getattr(interfaces, s.message), type), s


def test_the_routers_put_and_serve_rules_of_sims_and_compute_peers():
    from robofabric.secure import Identity, _own_rules

    rules = {r["id"]: r["key_exprs"] for role in ("sim", "compute") for r in _own_rules(Identity(role, role))}
    assert rules["sim-put"] == [
        "rf/*/event/decode/by/sim",
        "rf/*/robot/*/joints",
        "rf/*/robot/*/pose",
        "rf/*/robot/*/scan",
        "rf/*/robot/*/sonar",
        "rf/*/own/*",
        "rf/*/event/**",
    ]
    assert rules["compute-put"] == [
        "rf/*/event/decode/by/compute",
        "rf/*/robot/*/ik",
        "rf/*/robot/*/path",
        "rf/*/map/*",
        "rf/*/event/compute/**",
    ]
    assert rules["compute-serve"] == [
        "rf/*/srv/ik/**",
        "rf/*/srv/fk/**",
        "rf/*/srv/jacobian/**",
        "rf/*/srv/plan/**",
        "rf/*/srv/map/**",
        "rf/*/robot/*/path/@adv/**",
        "rf/*/map/*/@adv/**",
        "rf/*/robot/*/path",
        "rf/*/map/*",
        "rf/*/peer/tool/*",  # what it subscribes to and serves, told on its token's key (fabric.declared)
        "rf/*/peer/compute/*",
    ]
    assert rules["compute-tokens"] == [
        "rf/*/peer/tool/*",
        "rf/*/peer/compute/*",
        "rf/*/robot/*/path/@adv/**",
        "rf/*/map/*/@adv/**",
    ]


def test_the_sims_and_the_loads_default_rates_and_what_a_handle_follows():
    from robofabric.recording.load import DEFAULT_RATES as LOAD_RATES
    from sim_peer.serving.streams import DEFAULT_RATES
    from user_peer.following import FOLLOWED_STREAMS

    assert DEFAULT_RATES == LOAD_RATES == {"joints": 100.0, "pose": 50.0, "scan": 20.0}
    assert list(DEFAULT_RATES) == ["joints", "pose", "scan"]  # the order the sim's loops are staggered in
    assert FOLLOWED_STREAMS == ("joints", "pose", "scan", "path", "ik")


@pytest.mark.parametrize("kind", [None, "", "arm", "mobile", "drone"])
def test_the_ros2_exports_topics(kind):
    from user_peer.openfmt.ros2 import ros2_topic

    leaves = {
        "joints": "joint_states",
        "scan": "scan",
        "sonar": "sonar",
        "path": "path",
        "pose": {"mobile": "odom", "arm": "pose"}.get(kind or ""),
    }
    for s in (*keys.ROBOT_STREAMS, "radar"):
        leaf = leaves.get(s)
        assert ros2_topic(f"rf/w/robot/r1/{s}", kind, "ns") == (f"/ns/r1/{leaf}" if leaf else None), (s, kind)


def test_the_bridges_topics_types_and_qos():
    from geometry_msgs.msg import PoseStamped
    from nav_msgs.msg import OccupancyGrid, Odometry, Path
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import JointState, LaserScan

    from user_peer.ros2.bridge import _TYPES, LATCHED, STREAM

    pinned = {
        "joint_states": (JointState, STREAM),
        "scan": (LaserScan, qos_profile_sensor_data),
        "sonar": (LaserScan, qos_profile_sensor_data),
        "path": (Path, LATCHED),
        "odom": (Odometry, STREAM),
        "pose": (PoseStamped, STREAM),
        "map": (OccupancyGrid, LATCHED),
    }
    assert set(_TYPES) == set(pinned)
    for name, (cls, qos) in _TYPES.items():  # the very classes and profiles (== on QoSProfile compares fields)
        assert cls is pinned[name][0] and qos is pinned[name][1], name


# ---------------------------------------------------------------- the table itself


def test_the_table_refuses_what_no_consumer_could_follow():
    with pytest.raises(ValueError, match="unknown writer"):
        RobotStream("radar", "Scan", "user")
    with pytest.raises(ValueError, match="rate group needs its rate"):
        RobotStream("radar", "Scan", streams.SIM, "scan")
    with pytest.raises(ValueError, match="unknown QoS"):
        Ros2Topic("radar", "sensor_msgs/msg/LaserScan", "best_effort")
    with pytest.raises(ValueError, match="is not 'package/msg/Name'"):
        Ros2Topic("radar", "LaserScan", "stream")


def test_a_kind_specific_topic_is_found_before_the_common_one():
    assert streams.ros2_topic("pose", "mobile") == Ros2Topic("odom", "nav_msgs/msg/Odometry", "stream", kind="mobile")
    assert streams.ros2_topic("pose", None) is None and streams.ros2_topic("pose", "drone") is None
    assert streams.ros2_topic("ik") is None and streams.ros2_topic("x") is None
    assert streams.ros2_topic("joints", "mobile") == streams.ros2_topic("joints") == STREAMS[0].ros2[0]
    assert [s.access for s in STREAMS] == [f"robot/*/{n}" for n in streams.NAMES]
    assert streams.access("compute") == ["robot/*/ik", "robot/*/path"]  # sorted: the router's rules keep their order
    assert streams.access("compute", latched=True) == ["robot/*/path"] and streams.access("sim", latched=True) == []


# ---------------------------------------------------------------- (b) nobody else lists streams

EXCEPTIONS: dict[tuple[str, str], str] = {
    ("keys.py", "COMMANDS"): "command names (cmd/joints, cmd/path), which share two words with the streams",
    ("robot_commands.py", "COMMAND_BODIES"): "each command's body type, by command name",
    ("inbox.py", "TARGETS"): "the sim's target commands (joints, twist, path), not streams",
    ("world.py", "SPEC"): "RobotInfo's fields (its pose, its sonar ring's description), not streams",
    ("load.py", "makers"): "the load generator's message builder of each stream it fakes: code per stream",
    ("failover.py", "measure"): "the benchmark's choice of the streams whose gap a take-over leaves",
    ("ros2.py", "STREAMS"): "the ROS 2 benchmark's columns: the streams it times, and their topics",
    ("viewer.py", "RATES"): "the viewer benchmark's synthetic streams (flange, wheels, grid among them), at its rates",
    ("viewer.py", "measure_world"): "the streams of the viewer benchmark's class world",
}
"""Literals that hold two or more stream names and are no list of streams, by (file name, the name they are
assigned to or the function they are in): by name, not line or folder, so that a module's move keeps its entry."""


def _owner(node: ast.AST, parents: dict[ast.AST, ast.AST]) -> str:
    """The name a literal is assigned to, or the function or class it is in ("" at a module's top, unassigned)."""
    while node in parents:
        node = parents[node]
        if isinstance(node, (ast.Assign, ast.AnnAssign)):
            target = node.targets[0] if isinstance(node, ast.Assign) else node.target
            if isinstance(target, (ast.Name, ast.Attribute)):
                return target.id if isinstance(target, ast.Name) else target.attr
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            return node.name
    return ""


def stream_lists(source: str, names: frozenset[str]) -> list[tuple[int, str, list[str]]]:
    """(line, owner, names) of each tuple, list or set literal, and each dict's keys, holding two or more of
    ``names``."""
    if sum(f'"{n}"' in source or f"'{n}'" in source for n in names) < 2:
        return []  # no literal can hold two of them (most modules: their parse is the scan's time)
    tree = ast.parse(source)
    parents = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}
    out = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
            items: list[ast.expr | None] = list(node.elts)
        elif isinstance(node, ast.Dict):
            items = list(node.keys)
        else:
            continue
        hits = [i.value for i in items if isinstance(i, ast.Constant) and isinstance(i.value, str) and i.value in names]
        if len(hits) >= 2:
            out.append((node.lineno, _owner(node, parents), hits))
    return out


def test_the_scan_bites():
    names = frozenset(streams.NAMES)
    src = (
        'A = ("joints", "pose")\nB: dict[str, int] = {"scan": 1, "sonar": 2}\n'
        'def f():\n    for s in ["path", "ik"]:\n        pass\n    return {"joints"}, ("pose", "radar")\n'
    )
    assert [(line, owner) for line, owner, _ in stream_lists(src, names)] == [(1, "A"), (2, "B"), (4, "f")]


def test_no_module_but_the_table_lists_stream_names():
    names = frozenset(streams.NAMES)
    found: dict[tuple[str, str], str] = {}
    for pkg in PACKAGES:
        modules = sorted((ROOT / pkg).rglob("*.py"))
        assert modules, pkg  # a scan of nothing would pass
        for path in modules:
            rel = path.relative_to(ROOT).as_posix()
            if rel == TABLE:
                continue
            for line, owner, hits in stream_lists(path.read_text(encoding="utf-8"), names):
                found.setdefault((path.name, owner), f"{rel}:{line} {owner or '(module)'}: {hits}")
    extra = [where for key, where in sorted(found.items()) if key not in EXCEPTIONS]
    assert not extra, (
        "derive these from fabric.streams.STREAMS (or list them in EXCEPTIONS with a reason):\n" + "\n".join(extra)
    )
    stale = sorted(set(EXCEPTIONS) - set(found))
    assert not stale, f"exceptions that list no stream names any more; take them out: {stale}"

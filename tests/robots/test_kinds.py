"""The robot kinds' one table (robots/kinds.py): its lookups, the layers' registries that are keyed by it, and a
scan of the product's sources that fails on any branch on a kind's name outside it.

The scan walks every module of the product (AST, not text) for a comparison with a kind's name (``kind == "arm"``,
``"mobile" != k``, ``k in ("arm", ...)``), a ``case "arm":`` and a literal tuple, list or set that lists two or
more kinds (a second list of the kinds that nothing checks against the table). A branch site asks the kind's
facts instead (``facts(kind).chain``); a layer's registry keyed by kind (a dict) is what the table is for.
docs/howto.md, "A new robot kind".
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import robots
from robots.kinds import KINDS, NAMES, UNKNOWN, RobotKind, UnknownKind, facts, robot_kind

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("fabric", "sim_peer", "compute_peer", "ownership", "user_peer", "robofabric", "robots")
TABLE = "robots/kinds.py"

ALLOWED = {
    # the wire's codec checks RobotInfo.kind and RobotState.kind against the kinds' names: fabric.interfaces
    # may import nothing above fabric, so it spells them out; test_the_wire_takes_the_tables_kinds pins them
    "fabric/interfaces/world.py": 2,
}
"""Modules that may still spell out kinds, with how many times (a count that no longer matches fails: stale)."""

ROBOT = '[robot]\nkind = "{kind}"\nmjcf = "m.xml"\njoints = []\nlower = []\nupper = []\nmax_speed = []\n'


# ---------------------------------------------------------------- the table and its lookups


def test_the_kinds_and_their_facts():
    assert NAMES == tuple(KINDS) == ("arm", "mobile")
    assert all(isinstance(k, RobotKind) and k.name == name for name, k in KINDS.items())
    arm, mobile = robot_kind("arm"), robot_kind("mobile")
    assert (arm.chain, arm.base, arm.data_stream) == (True, False, "joints")
    assert (mobile.chain, mobile.base, mobile.data_stream) == (False, True, "pose")
    with pytest.raises(AttributeError):
        arm.chain = False  # type: ignore[misc]  (frozen: a peer cannot change what a kind is)


@pytest.mark.parametrize("name", ["", "drone", "Arm", "arm "])
def test_an_unknown_kind_is_named_with_the_kinds_there_are(name):
    with pytest.raises(UnknownKind, match=f"unknown robot kind {name!r}: expected one of arm, mobile"):
        robot_kind(name)
    assert isinstance(UnknownKind("x"), ValueError)  # callers that caught ValueError still do
    assert facts(name) is UNKNOWN and not UNKNOWN.chain and not UNKNOWN.base


def test_a_description_of_an_unknown_kind_is_refused_with_the_tables_kinds(tmp_path):
    (tmp_path / "m.xml").write_text("<mujoco/>")
    (tmp_path / "robot.toml").write_text('[robot]\nkind = "drone"\nmjcf = "m.xml"\n')
    with pytest.raises(robots.DescriptionError, match="kind must be one of arm, mobile, got 'drone'"):
        robots.load(str(tmp_path / "robot.toml"))
    assert robots.description.KINDS == NAMES


def test_a_base_kind_needs_its_base_table(tmp_path):
    """What the description asks of a kind follows its facts: a ``base`` kind needs ``[base]``."""
    (tmp_path / "m.xml").write_text("<mujoco/>")
    (tmp_path / "robot.toml").write_text(ROBOT.format(kind="mobile"))
    with pytest.raises(robots.DescriptionError, match=r"a mobile robot needs a \[base\] table"):
        robots.load(str(tmp_path / "robot.toml"))
    (tmp_path / "robot.toml").write_text(ROBOT.format(kind="arm"))
    assert robots.load(str(tmp_path / "robot.toml")).base is None


def test_the_wire_takes_the_tables_kinds():
    from fabric.interfaces import RobotInfo, RobotState

    assert RobotInfo.SPEC["kind"].choices == RobotState.SPEC["kind"].choices == NAMES


# ---------------------------------------------------------------- the layers' registries, keyed by kind


def test_the_stream_tables_per_kind_ros2_topics_name_kinds_of_the_table():
    """fabric.streams (below robots) keys a stream's ROS 2 topic by kind where its type depends on it: each such
    key is a kind here, and a base's pose is odometry, an arm's a stamped pose."""
    from fabric.streams import STREAMS, ros2_topic

    keyed = {t.kind for s in STREAMS for t in s.ros2 if t.kind}
    assert keyed and keyed <= set(NAMES), keyed
    types = {name: getattr(ros2_topic("pose", name), "type", None) for name in NAMES}
    assert types == {"arm": "geometry_msgs/msg/PoseStamped", "mobile": "nav_msgs/msg/Odometry"}


def test_every_kind_has_its_sim_class():
    from sim_peer.physics.registry import BUILTIN, robot_class

    assert set(BUILTIN) == set(NAMES)
    for name in NAMES:
        desc = next(d for d in map(robots.load, robots.available_robots()) if d.kind == name and not d.hooks)
        cls = robot_class(desc)
        assert cls.kind == name, (name, cls)


def test_every_kind_has_its_handle_class():
    from user_peer.robot import Robot

    for name, k in KINDS.items():
        cls = Robot.for_kind(name)
        assert cls is not Robot and cls.kind == name
        assert cls.data_stream == k.data_stream, name
    assert Robot.for_kind("drone") is Robot


# ---------------------------------------------------------------- nothing else branches on a kind's name


def _kind(node: ast.AST) -> bool:
    return isinstance(node, ast.Constant) and node.value in KINDS


def _holds_kind(node: ast.AST) -> bool:
    return _kind(node) or (isinstance(node, (ast.Tuple, ast.List, ast.Set)) and any(_kind(e) for e in node.elts))


def kind_branches(source: str) -> list[str]:
    """Each place in ``source`` that compares with a kind's name, matches one, or lists two or more kinds."""
    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Compare) and any(_holds_kind(x) for x in (node.left, *node.comparators)):
            out.append(f"{node.lineno}: {ast.unparse(node)}")
        elif isinstance(node, ast.MatchValue) and _kind(node.value):
            out.append(f"{node.lineno}: case {ast.unparse(node)}")
        elif isinstance(node, (ast.Tuple, ast.List, ast.Set)) and sum(_kind(e) for e in node.elts) >= 2:
            out.append(f"{node.lineno}: {ast.unparse(node)}")
    return out


@pytest.mark.parametrize(
    "source",
    [
        'if r.kind == "arm": pass',
        'x = "mobile" != kinds[r]',
        'ok = k in ("arm", "tracked")',
        'ok = k not in {"mobile"}',
        'match k:\n    case "arm": pass',
        'for kind in ("arm", "mobile"): pass',
        'KINDS = ["mobile", "arm"]',
    ],
)
def test_the_scan_sees_a_branch_on_a_kind(source):
    assert len(kind_branches(source)) == 1, source


@pytest.mark.parametrize(
    "source",
    [
        "if facts(r.kind).chain: pass",
        "same = r.kind == other.kind",
        'rows = {"arm": a, "mobile": b}',  # a layer's registry, keyed by kind
        'stream = "joints" if x == "pose" else "scan"',
        'prefixes = ("arm", "base")',
    ],
)
def test_the_scan_leaves_the_rest(source):
    assert kind_branches(source) == [], source


def test_nothing_outside_the_table_branches_on_a_kinds_name():
    found: dict[str, list[str]] = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            text = path.read_text()
            quoted = any(
                f"{q}{k}{q}" in text for k in KINDS for q in "'\""
            )  # no kind's name in quotes: nothing to parse
            if rel != TABLE and quoted and (hits := kind_branches(text)):
                found[rel] = hits
    stray = {rel: hits for rel, hits in found.items() if len(hits) != ALLOWED.get(rel)}
    assert not stray, (
        "branches on a kind's name outside robots/kinds.py: ask robots.kinds.facts(kind) instead "
        f"(docs/howto.md, 'A new robot kind'): {stray}"
    )
    stale = sorted(set(ALLOWED) - set(found))
    assert not stale, f"ALLOWED names modules that no longer spell out kinds: {stale}"

"""One world for everyone: the union of the sims' parts of srv/world (fabric.worldview), pure."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest

from fabric.codec import decode, encode
from fabric.interfaces import Header, ObjectInfo, RobotInfo, WorldInfo
from fabric.worldview import union


def _robot(rid: str, sim: str = "") -> RobotInfo:
    return RobotInfo(rid, "reeman", "mobile", np.zeros(4), (), np.zeros(0), np.zeros(0), np.zeros(0), sim=sim)


def _part(src: str, robots, *, objects=(), term: int = 1, rates=None) -> WorldInfo:
    return WorldInfo(
        "w",
        "warehouse",
        0.002,
        rates or {"pose": 50.0},
        tuple(_robot(r) for r in robots),
        objects,
        header=Header(source=src, term=term),
    )


GOAL = ObjectInfo("goal", "goal_pointer", "scene", np.zeros(3), np.array([1.0, 0, 0, 0]))


def test_the_union_has_every_robot_once_with_its_sim_and_the_objects_of_the_first_sim():
    info = union(
        [
            ("sim-b", _part("sim-b", ["base1"], rates={"pose": 20.0})),
            ("sim-a", _part("sim-a", ["base0"], objects=(GOAL,))),
        ]
    )
    assert [(r.id, r.sim) for r in info.robots] == [("base0", "sim-a"), ("base1", "sim-b")]
    assert [o.id for o in info.objects] == ["goal"] and info.rates == {"pose": 50.0}
    back = decode(encode(info))
    assert [(r.id, r.sim) for r in back.robots] == [(r.id, r.sim) for r in info.robots]


def test_a_robot_two_sims_describe_is_the_higher_terms():
    """A primary that lost its shard and has not noticed yet still answers: its part loses to the new one's."""
    info = union(
        [
            ("old", _part("old", ["base1"], term=1)),
            ("new", _part("new", ["base1"], term=2)),
            ("a", _part("a", ["base0"])),
        ]
    )
    assert [(r.id, r.sim) for r in info.robots] == [("base0", "a"), ("base1", "new")]


def test_one_part_is_itself_with_its_sim_named():
    info = union([("sim-a", _part("sim-a", ["base0"]))])
    assert info.robots[0].sim == "sim-a" and info.world == "w"
    with pytest.raises(ValueError):
        union([])


def test_a_robot_description_without_its_sim_keeps_the_old_wire_form_and_old_ones_decode():
    old = _robot("base0")
    raw = msgpack.unpackb(encode(old), raw=False, strict_map_key=False, ext_hook=lambda c, d: d)
    assert raw[0] == "RobotInfo" and len(raw) == 1 + 14  # no sim on the wire: what recordings before shards hold
    assert decode(encode(old)).sim == ""
    assert decode(encode(_robot("base0", "sim-a"))).sim == "sim-a"

"""A page follows in full only the robots it shows: :func:`follow_only` makes a session's followed robots the
wanted ones, and :func:`followed` gives the view the handles of those only. A real router and real sessions."""

from __future__ import annotations

import numpy as np

from fabric import keys
from fabric.interfaces import JointState, Pose
from robofabric.testing import wait_until
from user_peer.console.follow import follow_for, follow_only, followed, forget, streams
from user_peer.following import Following
from user_peer.latest import Latest


class _World:
    """What :func:`followed` reads of a world: its following."""

    def __init__(self, following: Following) -> None:
        self.following = following


def test_a_page_follows_the_robots_it_shows_and_lets_go_of_the_others(world, connect):
    sim, user = connect("sim", "sim"), connect("user", "alice")
    latest = Latest()
    following = Following(user, world, latest)
    follow_only(following, {"arm1", "base1"})  # the first arm and base, at login
    assert following.robots == {"arm1", "base1"}
    follow_only(following, {"base3"})  # she selected base3: the first two are let go of
    assert following.robots == {"base3"}
    handles = {"arm1": "h-arm1", "base1": "h-base1", "base3": "h-base3"}
    assert followed(_World(following), handles) == {"base3": "h-base3"}

    def pose_of(rid: str) -> float | None:
        p = latest.get(keys.robot_stream(world, rid, "pose"))
        return None if p is None else float(p.position[0])

    def heard(x: float) -> bool:
        for rid in ("base1", "base3"):
            sim.publish(keys.robot_stream(world, rid, "pose"), Pose(position=np.array([x, 0.0, 0.0])))
        return pose_of("base3") == x

    wait_until(lambda: heard(1.0), timeout=20, what="base3's pose", seen=lambda: pose_of("base3"))
    assert pose_of("base1") is None  # published with base3's, never decoded here
    follow_only(following, set())
    assert following.robots == frozenset() and followed(_World(following), handles) == {}


class _Page:
    """A page, as :func:`follow_for` knows it: a key."""


def test_two_pages_of_one_student_follow_what_either_shows_until_one_closes(world, connect):
    """Her pages share her world's following: her tab showing arm1 (or the tab before a reload, until its
    connection times out) no longer lets go of base1, which her other tab shows, at each of its redraws (a zoom then
    centred on the map's middle: CI, 2026-12-04)."""
    following = Following(connect("user", "dave"), world, Latest())
    old, new = _Page(), _Page()
    follow_for(following, old, {"arm1"})
    follow_for(following, new, {"base1"})
    assert following.robots == {"arm1", "base1"}
    follow_for(following, old, {"arm1"})  # the old tab's next redraw
    assert following.robots == {"arm1", "base1"}
    follow_for(following, new, {"base3"})  # she selected base3 in the new tab: base1 is let go of
    assert following.robots == {"arm1", "base3"}
    forget(following, old)  # the old tab closed
    assert following.robots == {"base3"}
    forget(following, old)  # once is enough
    forget(following, new)
    assert following.robots == frozenset()


def test_a_page_keeps_a_bases_pose_but_not_its_wheels_joints_and_an_arms_joints(world, connect):
    """A base's joints (its wheels, 100 a second) were decoded for every page that followed it, and shown nowhere:
    with 32 pages, 3,200 of the console's 5,440 messages a second."""
    sim, user = connect("sim", "sim"), connect("user", "alice")
    latest = Latest()
    kinds = {"base1": "mobile", "arm1": "arm"}
    following = Following(user, world, latest, lambda rid: streams(kinds[rid]))
    assert following.robot("base1") and following.robot("arm1")
    js = JointState(names=("a",), q=np.array([0.5]), dq=np.array([0.0]))

    def get(rid: str, stream: str):
        return latest.get(keys.robot_stream(world, rid, stream))

    def heard() -> bool:
        for rid in ("base1", "arm1"):
            sim.publish(keys.robot_stream(world, rid, "joints"), js)
            sim.publish(keys.robot_stream(world, rid, "pose"), Pose(position=np.array([1.0, 0.0, 0.0])))
        return all(get(r, s) is not None for r, s in (("base1", "pose"), ("arm1", "pose"), ("arm1", "joints")))

    wait_until(heard, timeout=20, what="base1's pose, arm1's pose and joints")
    assert get("base1", "joints") is None  # published as often as arm1's, never decoded here
    assert "joints" not in streams("mobile") and "joints" in streams("arm") and "pose" in streams("mobile")

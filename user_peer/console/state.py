"""What one page shows, read from its world: the robot list's lines and the live view's picture.

Only reads of the world's cache (ownership replicas, the latest streams); nothing here asks the
network or blocks, so the page's refresh timer may call it five times a second.
"""

from __future__ import annotations

import functools
import logging
import math
from dataclasses import dataclass

import numpy as np

from typing import Any

from fabric.codec import DecodeError, decode
from fabric.interfaces import Pose, yaw_from_quaternion
from fabric.text import one_line
from robots.kinds import facts
from user_peer.console import topview
from user_peer.console.topview import Frame, RobotMark
from user_peer.urdf_chain import UrdfChain

__all__ = ["RobotLine", "arm_chain", "arm_links", "robot_line", "scene_layout", "view_svg"]

log = logging.getLogger("robofabric.console")


@dataclass(frozen=True, slots=True)
class RobotLine:
    """One row of the robot list."""

    id: str
    kind: str
    owner: str
    state: str
    queue: tuple[str, ...]
    place: int  # the page user's place in the queue (1 = next), 0 when not waiting
    mine: bool

    def text(self) -> str:
        who = "you" if self.mine else (self.owner or "nobody")
        out = f"{self.kind} · owner: {who} · {self.state}"
        if self.queue:
            out += f" · queue: {', '.join(self.queue)}"
        if self.place:
            out += f" · your place: {self.place}"
        return one_line(out, 300)  # names are any login's text: one line, escaped


def robot_line(world, rid: str, kind: str) -> RobotLine:
    """The robot list's row for robot ``rid``, from its ownership record (the page's replica of them all)."""
    rec = world.ownership.record(rid)
    if rec is None:
        return RobotLine(rid, kind or "robot", "", "no ownership record yet", (), 0, False)
    place = rec.queue.index(world.user) + 1 if world.user in rec.queue else 0
    return RobotLine(rid, kind or "robot", rec.owner, rec.state, tuple(rec.queue), place, rec.owner == world.user)


@functools.lru_cache(maxsize=8)
def scene_boxes(scene: str) -> tuple[tuple[float, float, float, float, float], ...]:
    """The scene's static boxes (walls, shelves) as (cx, cy, half x, half y, yaw), from the scene file when this
    install has it (the sim extra); none otherwise. Read once per scene: loading the MJCF takes a while."""
    boxes = []
    try:
        import robots
        from user_peer.scene_geometry import static_boxes

        for b in static_boxes(robots.scene(scene).mjcf_path):
            if b.half_size[2] < 0.01:  # the floor
                continue
            x, y, z, w = (float(v) for v in b.quat_xyzw)
            yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
            boxes.append((float(b.center[0]), float(b.center[1]), float(b.half_size[0]), float(b.half_size[1]), yaw))
    except Exception as exc:  # no mujoco (a student's install), or a scene this install does not have
        log.info("no static geometry for scene %r: %s", scene, exc)
    return tuple(boxes)


def scene_layout(info) -> tuple[Frame, list[tuple[float, float, float, float, float]]]:
    """The view's frame and the scene's static boxes; without boxes, a frame around the robots' spawn poses."""
    boxes = list(scene_boxes(info.scene))
    pts = [(r.pose[0], r.pose[1]) for r in info.robots]
    for cx, cy, hx, hy, _ in boxes:
        pts += [(cx - hx, cy - hy), (cx + hx, cy + hy)]
    return topview.frame_around(pts, margin=0.2 if boxes else 2.0, minimum=4.0 if boxes else 10.0), boxes


def _pose(handles: dict, poses: dict[str, bytes], rid: str, decoder: Any = None) -> Any:
    """A robot's latest pose: its handle's (followed in full), else the undecoded latest, decoded now (by
    ``decoder``, the console's shared :class:`~user_peer.console.feed.Decoded`, when given)."""
    if rid in handles:
        return handles[rid].latest("pose")
    raw = poses.get(rid)
    if raw is None:
        return None
    if decoder is not None:
        return decoder.pose(rid, raw)
    try:
        return decode(raw, Pose)
    except DecodeError:
        return None


@functools.lru_cache(maxsize=16)
def arm_chain(robot_type: str) -> UrdfChain | None:
    """The joint chain of an arm type, from its URDF in ``robots`` (None when this install lacks the type or its
    URDF does not read): read once per type."""
    try:
        import robots

        urdf = robots.load(robot_type).urdf_path
        return UrdfChain.from_file(urdf) if urdf is not None else None
    except Exception as exc:
        log.info("no joint chain for %r: %s", robot_type, exc)
        return None


def arm_links(robot_type: str, q, spawn: tuple[float, ...]) -> tuple[tuple[float, float], ...]:
    """An arm's joint origins from above (world x, y), its base first: FK of ``q`` placed at its spawn pose
    (x, y, z, yaw); empty when the chain is unknown or ``q`` does not fit it."""
    chain = arm_chain(robot_type)
    if chain is None or q is None or len(q) != chain.nq:
        return ()
    pts = chain.origins(q)
    sx, sy, _, yaw = spawn
    c, s = math.cos(yaw), math.sin(yaw)
    return ((sx, sy), *((sx + c * float(x) - s * float(y), sy + s * float(x) + c * float(y)) for x, y, _ in pts))


def _mark(world, entry, pose, spawn: dict, selected: set[str], joints=None) -> RobotMark | None:
    rec = world.ownership.record(entry.id)
    owner = rec.owner if rec is not None else ""
    if facts(entry.kind).base:
        if pose is None:
            return None
        x, y, yaw = float(pose.position[0]), float(pose.position[1]), yaw_from_quaternion(pose.quaternion)
        return RobotMark(entry.id, "mobile", owner, x, y, yaw, owner == world.user, entry.id in selected)
    sx, sy, _, syaw = spawn.get(entry.id, (0.0, 0.0, 0.0, 0.0))
    flange = (float(pose.position[0]), float(pose.position[1])) if pose is not None else None
    links = arm_links(entry.type, joints.q, spawn[entry.id]) if joints is not None and entry.id in spawn else ()
    return RobotMark(
        entry.id, entry.kind or "robot", owner, sx, sy, syaw, owner == world.user, entry.id in selected, flange, links
    )


_SPAWN: dict[int, tuple[Any, dict[str, tuple[float, ...]]]] = {}  # id(description) -> (it, its robots' spawn poses)


def _spawn(info) -> dict[str, tuple[float, ...]]:
    """Every robot's spawn pose (x, y, z, yaw) by id, once per world description (each page's session has its
    own; a description is not hashable, so it is kept by identity, and held so the identity stays its own)."""
    held = _SPAWN.get(id(info))
    if held is None or held[0] is not info:
        if len(_SPAWN) > 256:
            _SPAWN.clear()
        held = _SPAWN[id(info)] = (info, {r.id: tuple(float(v) for v in r.pose) for r in info.robots})
    return held[1]


def _drawn(
    world, entry, handles: dict, poses: dict[str, bytes], frame: Frame, spawn: dict, selected: set[str], decoder: Any
) -> str:
    """One robot as the page draws it. A robot the page does not follow, whose pose came undecoded, is drawn by
    the console's ``decoder`` once for every page that holds the same pose and draws it the same way."""
    if decoder is not None and entry.id not in handles and entry.id in poses:
        rec = world.ownership.record(entry.id)
        owner = rec.owner if rec is not None else ""
        variant = (owner, owner == world.user, entry.id in selected, frame)

        def draw(pose: Any) -> str:
            mark = _mark(world, entry, pose, spawn, selected)
            return topview.robot_svg(frame, mark) if mark is not None else ""

        return decoder.drawn(entry.id, poses[entry.id], variant, draw)
    joints = handles[entry.id].latest("joints") if entry.id in handles and facts(entry.kind).chain else None
    mark = _mark(world, entry, _pose(handles, poses, entry.id, decoder), spawn, selected, joints)
    return topview.robot_svg(frame, mark) if mark is not None else ""


def view_svg(
    world,
    entries: list,
    handles: dict,
    poses: dict[str, bytes],
    frame: Frame,
    boxes,
    *,
    base_id: str | None,
    selected: set[str],
    goal: tuple[float, float, float] | None,
    target: tuple[float, float] | None,
    decoder: Any = None,
) -> str:
    """The live view's overlay: every robot with its owner, the paths and the selected base's scan of the robots
    this page follows, the IK target and the goal. ``decoder``: the console's shared pose decoder."""
    spawn = _spawn(world.info())
    drawn = [_drawn(world, e, handles, poses, frame, spawn, selected, decoder) for e in entries]
    scan = None
    paths = []
    for r in handles.values():
        path = r.latest("path")
        if path is not None and len(path):
            paths.append(np.stack([np.asarray(path.x), np.asarray(path.y)], axis=1))
        if r.id == base_id:
            s, p = r.latest("scan"), r.latest("pose")
            if s is not None and p is not None:
                scan = topview.scan_points(
                    float(p.position[0]),
                    float(p.position[1]),
                    yaw_from_quaternion(p.quaternion),
                    s.angle_min,
                    s.angle_increment,
                    s.ranges,
                    s.range_max,
                )
    return topview.svg(frame, (), boxes=boxes, scan=scan, paths=paths, target=target, goal=goal, drawn=drawn)

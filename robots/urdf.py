"""A URDF read as a tree: its links, its joints, the serial chain from the root to a tip link.

What ``robofabric robots add`` (:mod:`robots.urdf_import`) needs to know of a URDF before any compiler sees it:
which joints move the flange (the chain from the root link to the tip), their limits and speeds, and what it
cannot take (a link with two parents is a closed chain; a floating or planar joint on the chain is a mobile
base; a mimic joint on the chain moves with another one). Pure: parses text, no file is written here.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass

from robots.description import DescriptionError

MOVING = ("revolute", "continuous", "prismatic")
"""Joint types an arm's chain may hold (one degree of freedom each)."""
TURN = 2 * math.pi
"""rad: the range given to a continuous joint on each side of zero (it turns, but the controllers need limits)."""
DEFAULT_SPEED = 1.0
"""rad/s (m/s for a prismatic joint): the speed limit of a joint whose URDF gives none."""


@dataclass(frozen=True, slots=True)
class UrdfJoint:
    """One URDF joint: its type, the links it joins and its limits (``None`` when the URDF gives none)."""

    name: str
    type: str
    parent: str
    child: str
    lower: float | None = None
    upper: float | None = None
    velocity: float | None = None
    mimic: str = ""


@dataclass(frozen=True, slots=True)
class UrdfTree:
    """A URDF's name, links (file order) and joints, checked to be a tree with one root."""

    name: str
    links: tuple[str, ...]
    joints: tuple[UrdfJoint, ...]
    root: str

    def parent_joint(self, link: str) -> UrdfJoint | None:
        return next((j for j in self.joints if j.child == link), None)

    def children(self, link: str) -> list[UrdfJoint]:
        return [j for j in self.joints if j.parent == link]

    def chain(self, tip: str) -> list[UrdfJoint]:
        """The joints from the root to ``tip``, root first (fixed ones included)."""
        if tip not in self.links:
            raise DescriptionError(f"tip link {tip!r} is not a link of {self.name}; links: {', '.join(self.links)}")
        out = []
        link = tip
        while (j := self.parent_joint(link)) is not None:
            out.append(j)
            link = j.parent
        return out[::-1]

    def moving_chain(self, tip: str) -> list[UrdfJoint]:
        """The joints of the chain to ``tip`` that move (the arm's joints, in order)."""
        return [j for j in self.chain(tip) if j.type != "fixed"]


def parse(text: str, where: str = "URDF") -> UrdfTree:
    """The tree of a URDF document; :class:`DescriptionError` for what is not one (no robot, a link with two
    parents: a closed chain, several roots, a joint naming an unknown link)."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise DescriptionError(f"{where} is not valid XML: {exc}") from None
    if root.tag != "robot":
        raise DescriptionError(f"{where}: the root element is <{root.tag}>, not <robot>")
    links = tuple(str(e.get("name", "")) for e in root.findall("link"))
    joints = tuple(_joint(e, where) for e in root.findall("joint"))
    known = set(links)
    for j in joints:
        for end in (j.parent, j.child):
            if end not in known:
                raise DescriptionError(f"{where}: joint {j.name!r} names link {end!r}, which is not defined")
    parents: dict[str, list[str]] = {}
    for j in joints:
        parents.setdefault(j.child, []).append(j.name)
    closed = {link: names for link, names in parents.items() if len(names) > 1}
    if closed:
        link, names = next(iter(closed.items()))
        raise DescriptionError(
            f"{where}: link {link!r} is the child of joints {', '.join(names)}: a closed chain "
            f"(parallel mechanisms are not supported)"
        )
    roots = [link for link in links if link not in parents]
    if len(roots) != 1:
        raise DescriptionError(f"{where}: expected one root link, found {len(roots)}: {', '.join(roots) or 'none'}")
    return UrdfTree(str(root.get("name", "robot")), links, joints, roots[0])


def _joint(e: ET.Element, where: str) -> UrdfJoint:
    name = str(e.get("name", ""))
    parent, child, limit, mimic = e.find("parent"), e.find("child"), e.find("limit"), e.find("mimic")
    if parent is None or child is None:
        raise DescriptionError(f"{where}: joint {name!r} needs a <parent> and a <child>")

    def number(key: str) -> float | None:
        if limit is None or limit.get(key) is None:
            return None
        try:
            v = float(limit.get(key, ""))
        except ValueError:
            raise DescriptionError(f"{where}: joint {name!r}: limit {key}={limit.get(key)!r} is not a number") from None
        return v if math.isfinite(v) else None

    return UrdfJoint(
        name,
        str(e.get("type", "")),
        str(parent.get("link", "")),
        str(child.get("link", "")),
        number("lower"),
        number("upper"),
        number("velocity"),
        "" if mimic is None else str(mimic.get("joint", "")),
    )


def default_tip(tree: UrdfTree) -> str:
    """The flange when none is named: past the end of the longest chain of revolute joints, as far as fixed
    joints go (the UR5's ``tool0``, the Panda's ``panda_hand_tcp``; a gripper's fingers are not followed).

    Ties go to the link defined last in the file."""

    def revolute_depth(link: str) -> int:
        return sum(j.type in ("revolute", "continuous") for j in tree.chain(link))

    depth = {link: revolute_depth(link) for link in tree.links}
    best = max(depth.values())
    last = [link for link in tree.links if depth[link] == best and _enters_by_moving(tree, link)]
    start = last[-1] if last else tree.root
    # follow fixed joints only, to the deepest link (ties: the last one in the file)
    frontier, tip = [start], start
    while frontier:
        nxt = [j.child for link in frontier for j in tree.children(link) if j.type == "fixed"]
        if nxt:
            tip = sorted(nxt, key=tree.links.index)[-1]
        frontier = nxt
    return tip


def _enters_by_moving(tree: UrdfTree, link: str) -> bool:
    j = tree.parent_joint(link)
    return j is not None and j.type in ("revolute", "continuous")


@dataclass(frozen=True, slots=True)
class ArmChain:
    """The arm a URDF makes: its joints to the tip with their limits and speeds, and what was left out."""

    tip: str
    joints: tuple[str, ...]
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    max_speed: tuple[float, ...]
    locked: tuple[str, ...]  # moving joints off the chain, held at zero (a gripper's fingers)
    notes: tuple[str, ...]  # what could not be taken as it is, said to the user


def arm_chain(tree: UrdfTree, tip: str | None = None) -> ArmChain:
    """The arm from ``tree``'s root to ``tip`` (default: :func:`default_tip`); refuses a chain with a floating,
    planar or mimic joint, or none that moves."""
    tip = tip or default_tip(tree)
    chain = tree.moving_chain(tip)
    notes: list[str] = []
    for j in chain:
        if j.type not in MOVING:
            raise DescriptionError(
                f"joint {j.name!r} on the chain to {tip!r} is {j.type or 'untyped'}: only revolute, "
                f"continuous and prismatic joints are supported (mobile bases from URDF are not yet)"
            )
        if j.mimic:
            raise DescriptionError(
                f"joint {j.name!r} on the chain to {tip!r} mimics {j.mimic!r}: mimic joints are "
                f"not supported on an arm's chain"
            )
    if not chain:
        raise DescriptionError(
            f"no joint moves the link {tip!r}: pick another tip (--tip); links: {', '.join(tree.links)}"
        )
    lower, upper, speed = [], [], []
    for j in chain:
        lo, hi = _limits(j, notes)
        lower.append(lo)
        upper.append(hi)
        if j.velocity is None or j.velocity <= 0:
            notes.append(f"joint {j.name}: no velocity limit in the URDF, {DEFAULT_SPEED} taken")
            speed.append(DEFAULT_SPEED)
        else:
            speed.append(j.velocity)
    on_chain = {j.name for j in chain}
    locked = tuple(j.name for j in tree.joints if j.type != "fixed" and j.name not in on_chain)
    for name in locked:
        j = next(x for x in tree.joints if x.name == name)
        why = f"mimics {j.mimic}" if j.mimic else f"{j.type}, off the chain to {tip}"
        notes.append(f"joint {name} ({why}): held at 0 (grippers and branches are not supported yet)")
    return ArmChain(tip, tuple(j.name for j in chain), tuple(lower), tuple(upper), tuple(speed), locked, tuple(notes))


def _limits(j: UrdfJoint, notes: list[str]) -> tuple[float, float]:
    if j.type == "continuous":
        notes.append(f"joint {j.name}: continuous, given the range ±{TURN:.4f} rad")
        return -TURN, TURN
    if j.lower is None or j.upper is None or j.lower >= j.upper:
        raise DescriptionError(
            f"joint {j.name!r} ({j.type}) has no usable <limit lower upper>: an arm's joints need their range"
        )
    return j.lower, j.upper


__all__ = ["ArmChain", "DEFAULT_SPEED", "MOVING", "TURN", "UrdfJoint", "UrdfTree", "arm_chain", "default_tip", "parse"]

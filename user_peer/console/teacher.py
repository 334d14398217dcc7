"""The teacher's page, its pure part: who may open it, which actions a robot's row offers, the class's tables.

The page (:mod:`.teacher_page`) is for the console's instructor logins (``robofabric console --instructors``): a
student who logs in there is refused before any session opens, and every action checks again on the server
(:func:`require_staff`), whatever a page sends. The actions themselves are the ownership authority's staff
actions (:mod:`ownership.staff`, ``own/{robot}/staff/by/{login}``), which a class's router opens to the instructor
logins alone: the console adds no power of its own.

Pure: records and counts in, rows out (tests/user_peer/console/test_console_teacher.py).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from fabric.interfaces import STAFF_OPS, OwnershipRecord
from fabric.text import one_line
from user_peer.errors import FabricUserError

__all__ = [
    "NotStaff",
    "RobotRow",
    "StudentRow",
    "LABELS",
    "ROUTE",
    "is_staff",
    "require_staff",
    "robot_actions",
    "robot_rows",
    "student_rows",
    "class_actions",
]

ROUTE = "/teacher"
"""Where the console serves the teacher's page."""

LABELS = {"take_back": "Release", "give": "Give", "lock": "Lock", "unlock": "Unlock", "stop": "Stop", "reset": "Reset"}
"""The buttons' words for the authority's staff actions (:data:`fabric.interfaces.STAFF_OPS`)."""

CLASS_ACTIONS = ("stop_all", "reset_world")
"""The page's actions on every robot at once: each is the staff action on every exclusive robot in turn."""


class NotStaff(FabricUserError):
    """A login that is not one of the console's instructors asked for the teacher's page or one of its actions."""


def is_staff(name: str, instructors: Iterable[str]) -> bool:
    """Whether ``name`` is one of the console's instructor logins."""
    return bool(name) and name in set(instructors)


def require_staff(name: str, instructors: Iterable[str], what: str = "the teacher's page") -> None:
    """Raise :class:`NotStaff` (in words for the page) unless ``name`` is one of the console's instructors."""
    staff = sorted(set(instructors))
    if is_staff(name, staff):
        return
    if not staff:
        raise NotStaff(
            f"{what} is for instructors, and this console names none (robofabric console --instructors NAME)"
        )
    raise NotStaff(f"{what} is for instructors: {one_line(name, 64) or 'nobody'} is not one of this console's")


def robot_actions(rec: OwnershipRecord | None) -> tuple[str, ...]:
    """The staff actions a robot's row offers now, in :data:`STAFF_OPS`'s order: Release only while someone owns it,
    Give and Lock unless it is locked, Unlock only while it is; Stop and Reset always. None for a scene object."""
    if rec is None or rec.policy == "scene":
        return ()
    show = {
        "take_back": bool(rec.owner),
        "give": not rec.locked,
        "lock": not rec.locked,
        "unlock": bool(rec.locked),
        "stop": True,
        "reset": True,
    }
    return tuple(op for op in STAFF_OPS if show[op])


def class_actions(name: str, instructors: Iterable[str]) -> tuple[str, ...]:
    """What the page offers a login: the class's actions for an instructor, nothing for anyone else."""
    return CLASS_ACTIONS if is_staff(name, instructors) else ()


@dataclass(frozen=True, slots=True)
class RobotRow:
    """One robot of the class as the teacher's table shows it; names from the network made one line and capped."""

    robot: str
    kind: str
    owner: str
    queue: str
    state: str
    locked: str
    epoch: int
    actions: tuple[str, ...]


def _name(text: str) -> str:
    return one_line(text, 64)


def robot_rows(kinds: Mapping[str, str], records: Mapping[str, OwnershipRecord]) -> list[RobotRow]:
    """Every robot of ``kinds`` (robot id -> kind), in id order, with its record's owner, queue, motion and lock
    (a robot whose record has not come yet: "(no record yet)", no action)."""
    rows = []
    for rid in sorted(kinds):
        rec = records.get(rid)
        if rec is None:
            rows.append(RobotRow(_name(rid), kinds[rid], "(no record yet)", "", "", "", 0, ()))
            continue
        rows.append(
            RobotRow(
                _name(rid),
                kinds[rid],
                _name(rec.owner) or "(free)",
                ", ".join(_name(u) for u in rec.queue) or "-",
                rec.state,
                _name(rec.locked),
                rec.epoch,
                robot_actions(rec),
            )
        )
    return rows


@dataclass(frozen=True, slots=True)
class StudentRow:
    """One person of the class: her pages on this console, whether a session of hers is live (console or script),
    what she owns and what she waits for."""

    name: str
    role: str
    pages: int
    live: bool
    owns: str
    waits: str


def student_rows(
    pages: Mapping[str, int], live: Iterable[str], records: Mapping[str, OwnershipRecord], instructors: Iterable[str]
) -> list[StudentRow]:
    """Everyone the class sees: logged in on this console (``pages``: name -> open pages), live in the world
    (``live``: user peers' ids, scripts included), or named by a record (an owner, a queue); students first."""
    staff = set(instructors)
    live = set(live)
    names = (
        set(pages)
        | live
        | {r.owner for r in records.values() if r.owner}
        | {u for r in records.values() for u in r.queue}
    )
    owns: dict[str, list[str]] = {}
    waits: dict[str, list[str]] = {}
    for rid in sorted(records):
        rec = records[rid]
        if rec.owner:
            owns.setdefault(rec.owner, []).append(rid)
        for u in rec.queue:
            waits.setdefault(u, []).append(rid)
    rows = [
        StudentRow(
            _name(n),
            "instructor" if n in staff else "student",
            int(pages.get(n, 0)),
            n in live,
            ", ".join(owns.get(n, ())) or "-",
            ", ".join(waits.get(n, ())) or "-",
        )
        for n in names
        if n
    ]
    return sorted(rows, key=lambda r: (r.role != "student", r.name))

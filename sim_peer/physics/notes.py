"""What a world's robots and sensors said (a bumper stop, a clamp), kept until the peer takes it.

A world reports through one :class:`NoteLog`: robots get its ``add`` as their report sink
(:class:`sim_peer.robot.Mount`), the peer drains it with ``take`` once per tick and publishes what it took.
The log is bounded: a headless world that nobody drains keeps the newest notes and forgets the oldest,
so it never grows without end.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterator

from fabric.interfaces import EventKind
from sim_peer.robot import Note

MAX_NOTES = 1024  # notes kept until the peer takes them; a headless world that never does keeps the newest


class NoteLog:
    """Notes as (robot id, note), oldest first, at most ``limit`` of them."""

    def __init__(self, limit: int = MAX_NOTES) -> None:
        self._notes: deque[tuple[str, Note]] = deque(maxlen=limit)

    def add(self, robot_id: str, note: Note) -> None:
        """The report sink a robot is mounted with."""
        self._notes.append((robot_id, note))

    def take(self) -> list[tuple[str, Note]]:
        """What was said since the last call, oldest first; the log is empty after it."""
        out = list(self._notes)
        self._notes.clear()
        return out

    @property
    def collisions(self) -> list[tuple[str, float]]:
        """(robot id, sim time) of the bumper stops not taken yet."""
        return [(rid, n.data["t"]) for rid, n in self._notes if n.kind == EventKind.COLLISION]

    def __len__(self) -> int:
        return len(self._notes)

    def __iter__(self) -> Iterator[tuple[str, Note]]:
        return iter(tuple(self._notes))


__all__ = ["MAX_NOTES", "NoteLog"]

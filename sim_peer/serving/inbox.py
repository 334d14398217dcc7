"""Per-robot command queues: commands leave zenoh's callback thread at once and wait here, bounded.

A flood of commands must not delay other robots' commands, nor grow memory, nor lose a
stop. So each robot has one :class:`CommandQueue` that never holds more than three
commands, and still means what the sender meant:

* targets (``joints``, ``trajectory``, ``twist``, ``path``) replace each other: the latest target wins,
  whichever kind it is (a twist after a path drives the base, as it would applied in turn);
* ``stop`` supersedes every pending target (they would have been stopped anyway) and is
  kept once; ``reset`` supersedes everything pending, stops included (it stops the robot too);
* so a queue is at most ``[reset] [stop] [target]``, in that order, and a stop or a reset
  is never dropped: only commands whose effect a later one would undo anyway are.

Pure: no threads and no zenoh; :class:`sim_peer.serving.peer.SimPeer` drains the queues in a worker.
"""

from __future__ import annotations

from collections import deque
from typing import Generic, TypeVar

__all__ = ["CommandQueue", "TARGETS", "CONTROLS"]

TARGETS = ("joints", "trajectory", "twist", "path")
CONTROLS = ("stop", "reset")

T = TypeVar("T")


class CommandQueue(Generic[T]):
    """The pending commands of one robot: ``(name, command)`` pairs, at most three."""

    def __init__(self) -> None:
        self._items: deque[tuple[str, T]] = deque()
        self.superseded = 0  # commands a later one made pointless, counted

    def __len__(self) -> int:
        return len(self._items)

    def __bool__(self) -> bool:
        return bool(self._items)

    def put(self, name: str, command: T) -> None:
        """Queue ``command`` sent on ``cmd/{name}``; ``ValueError`` for a name that is not a command."""
        items = self._items
        if name in TARGETS:
            if items and items[-1][0] in TARGETS:
                items.pop()
                self.superseded += 1
            items.append((name, command))
        elif name == "stop":
            while items and items[-1][0] in TARGETS:
                items.pop()
                self.superseded += 1
            if items and items[-1][0] == "stop":
                items.pop()
                self.superseded += 1
            items.append((name, command))
        elif name == "reset":
            self.superseded += len(items)
            items.clear()
            items.append((name, command))
        else:
            raise ValueError(f"not a command: {name!r}")

    def take(self) -> list[tuple[str, T]]:
        """Everything pending, oldest first; the queue is empty afterwards."""
        out = list(self._items)
        self._items.clear()
        return out

    def peek(self) -> list[tuple[str, T]]:
        return list(self._items)

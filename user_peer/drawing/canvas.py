"""What every drawer shares: the recording, the time of the message being filed, and what was logged once.

Frequent streams are filed as :class:`Rows` and drawn as columns at a flush (:mod:`user_peer.rerun_columns`);
rare messages are logged at once, row by row, at the time :meth:`Canvas.set_time` sets. Static parts (shapes,
styles, plot names) are logged the first time :meth:`Canvas.once` is asked for their entity.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import rerun as rr

from user_peer.drawing.layout import TIMELINE_SIM, TIMELINE_WALL
from user_peer.rerun_columns import send, time_columns

__all__ = ["Canvas", "Rows"]


class Rows:
    """Rows of one stream waiting for the next flush: their times and what each message brought."""

    __slots__ = ("wall", "sim", "items")

    def __init__(self) -> None:
        self.wall: list[int] = []
        self.sim: list[float] = []
        self.items: list[Any] = []

    def add(self, wall: int, sim: float, item: Any) -> None:
        self.wall.append(wall)
        self.sim.append(sim)
        self.items.append(item)

    def times(self) -> list[rr.TimeColumn]:
        return time_columns(self.wall, self.sim)

    def clear(self) -> None:
        """Drawn: empty again, ready for the next window."""
        self.wall.clear()
        self.sim.clear()
        self.items.clear()


class Canvas:
    """One Rerun recording as the drawers see it.

    ``now`` is the message being filed, as (wall_time ns, sim_time s); ``pending`` counts the rows filed since
    the last flush (the logger flushes on its own past a bound)."""

    def __init__(self, rec: rr.RecordingStream) -> None:
        self.rec = rec
        self.now: tuple[int, float] = (0, 0.0)
        self.pending = 0
        self._static_done: set[str] = set()

    def once(self, entity: str) -> bool:
        """True the first time ``entity`` is asked: static parts are logged once."""
        if entity in self._static_done:
            return False
        self._static_done.add(entity)
        return True

    def forget(self, prefix: str) -> None:
        """Log the static parts of the entities under ``prefix`` again when next asked (a map's scale changed)."""
        self._static_done -= {k for k in self._static_done if k.startswith(prefix)}

    def file(self, store: dict, key: Any, item: Any) -> Rows:
        """File ``item`` at the current message's time under ``store[key]``, for the next flush."""
        rows = store.get(key)
        if rows is None:
            rows = store[key] = Rows()
        rows.add(*self.now, item)
        self.pending += 1
        return rows

    def set_time(self) -> None:
        """The current message's time, for the row-by-row logs of rare messages."""
        wall, sim = self.now
        self.rec.reset_time()
        self.rec.set_time(TIMELINE_WALL, timestamp=np.datetime64(int(wall), "ns"))
        if sim > 0:
            self.rec.set_time(TIMELINE_SIM, duration=sim)

    def send_now(self, entity: str, columns: Any) -> None:
        """One row of columns at the current message's time."""
        send(self.rec, entity, time_columns([self.now[0]], [self.now[1]]), columns)

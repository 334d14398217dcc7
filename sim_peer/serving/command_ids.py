"""Which commands a sim applied lately, by id, so that a command sent again is applied once.

A client that rides out a held sim (:mod:`user_peer.pause`) sends the same command again, unchanged: the same
envelope, so the same id, its header's ``(source, seq, wall_ns)`` on its key (the sending session, its per-key
sequence and when it was made).
Copies still on their way when the first one was applied must not apply it again (a path followed twice, a reset
repeated after the owner moved on). A command with no source (a bare envelope built by hand, a test's) has no id
and is always applied.

A hold (:meth:`sim_peer.serving.commanding.CommandPipeline.hold`) stops the robots mid-command and forgets the ids: the
client that awaits such a command sends it again, and that copy is carried out once.

Pure: the sim's command pipeline (:mod:`sim_peer.serving.commanding`) asks :meth:`RecentIds.seen` before it applies a
command and :meth:`RecentIds.add` after.
"""

from __future__ import annotations

from collections import OrderedDict

from fabric.interfaces import Command

__all__ = ["RecentIds", "KEEP", "command_id"]

KEEP = 64
"""How many applied ids a robot remembers (a resend follows its first copy within seconds: a few are enough)."""


def command_id(name: str, cmd: Command) -> tuple[str, str, str, int, int] | None:
    """The id of ``cmd`` sent as a ``name`` command (None: it has none). Its wall time is part of it: a session
    whose sequence table is full numbers new keys 0 every time (:mod:`fabric.sequences`)."""
    h = cmd.header
    if not h.source:
        return None
    return (name, cmd.user, h.source, h.seq, h.wall_ns)


class RecentIds:
    """The last :data:`KEEP` command ids applied to one robot, oldest first out."""

    def __init__(self, keep: int = KEEP) -> None:
        self.keep = keep
        self._ids: OrderedDict[tuple[str, str, str, int, int], None] = OrderedDict()

    def seen(self, name: str, cmd: Command) -> bool:
        """Whether this very command (by id) was applied already."""
        cid = command_id(name, cmd)
        return cid is not None and cid in self._ids

    def clear(self) -> None:
        """Forget every id: what was applied was stopped (a hold), and a copy sent again is to be done again."""
        self._ids.clear()

    def add(self, name: str, cmd: Command) -> None:
        """Remember that ``cmd`` was applied."""
        cid = command_id(name, cmd)
        if cid is None:
            return
        self._ids[cid] = None
        self._ids.move_to_end(cid)
        while len(self._ids) > self.keep:
            self._ids.popitem(last=False)

"""The world's note log: bounded, newest kept, ``take`` empties it, ``collisions`` lists the bumper stops not taken."""

from __future__ import annotations

from fabric.interfaces import EventKind
from sim_peer.physics.notes import NoteLog
from sim_peer.robot import Note


def test_the_note_log_keeps_the_newest_notes_and_take_empties_it():
    log = NoteLog(limit=3)
    for i in range(5):
        log.add(f"r{i}", Note("path_done", f"n{i}"))
    log.add("bot", Note(EventKind.COLLISION, "bumper", data={"t": 1.5}))
    assert len(log) == 3 and log.collisions == [("bot", 1.5)]
    taken = log.take()
    assert [(rid, n.reason) for rid, n in taken] == [("r3", "n3"), ("r4", "n4"), ("bot", "bumper")]
    assert log.take() == [] and log.collisions == []

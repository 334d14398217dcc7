"""A command is applied once by its id: what the sim remembers of the ids it applied (sim_peer.serving.command_ids)."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from fabric.interfaces import Command, Header, JointTarget
from sim_peer.serving.command_ids import KEEP, RecentIds


def _cmd(seq: int, source: str = "alice-1", user: str = "alice") -> Command:
    return Command(user, 3, JointTarget(np.zeros(6)), Header(seq=seq, source=source))


def test_a_copy_of_an_applied_command_is_seen_and_a_new_one_is_not():
    ids = RecentIds()
    first = _cmd(7)
    assert not ids.seen("joints", first)
    ids.add("joints", first)
    assert ids.seen("joints", first)  # the same envelope sent again
    assert ids.seen("joints", _cmd(7))  # or rebuilt with the same header
    assert not ids.seen("joints", _cmd(8))  # the next command
    assert not ids.seen("path", first)  # the same seq on another command's key
    assert not ids.seen("joints", _cmd(7, source="bob-1", user="bob"))  # another session's
    made_later = Command("alice", 3, JointTarget(np.zeros(6)), Header(seq=7, source="alice-1", wall_ns=5))
    assert not ids.seen("joints", made_later)  # a full sequence table numbers every new key 0: the time tells


def test_a_command_with_no_source_has_no_id_and_is_always_applied():
    ids = RecentIds()
    bare = Command("alice", 1, JointTarget(np.zeros(6)))
    ids.add("joints", bare)
    assert not ids.seen("joints", bare)


def test_a_hold_forgets_the_ids_so_what_it_stopped_is_done_again():
    ids = RecentIds()
    ids.add("joints", _cmd(1))
    ids.clear()
    assert not ids.seen("joints", _cmd(1))


@given(st.lists(st.integers(min_value=1, max_value=300), max_size=400))
def test_the_last_ids_applied_are_remembered_and_no_more(seqs: list[int]):
    ids = RecentIds()
    for s in seqs:
        ids.add("joints", _cmd(s))
    recent: list[int] = []
    for s in seqs:  # the model: most recently applied last, each once
        if s in recent:
            recent.remove(s)
        recent.append(s)
    kept = set(recent[-KEEP:])
    for s in range(1, 301):
        assert ids.seen("joints", _cmd(s)) == (s in kept)

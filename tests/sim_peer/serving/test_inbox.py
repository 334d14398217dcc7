"""The per-robot command queue: bounded, the latest target wins, a stop or reset is never lost."""

from __future__ import annotations

from hypothesis import given, settings, strategies as hs

from sim_peer.serving.inbox import CONTROLS, TARGETS, CommandQueue

NAMES = TARGETS + CONTROLS


def effect(seq):
    """What a robot ends up doing after applying ``seq`` in order: (was reset, stopped since, final target)."""
    reset = stopped = False
    target = None
    for name, value in seq:
        if name == "reset":
            reset, stopped, target = True, False, None
        elif name == "stop":
            stopped, target = True, None
        else:
            target = value
    return reset, stopped, target


@settings(max_examples=300, deadline=None)
@given(hs.lists(hs.lists(hs.sampled_from(NAMES), max_size=30), max_size=6))
def test_bounded_and_same_effect(batches):
    q: CommandQueue[int] = CommandQueue()
    applied, sent, n = [], [], 0
    for batch in batches:  # the worker drains between batches
        for name in batch:
            q.put(name, n)
            sent.append((name, n))
            n += 1
            assert len(q) <= 3
        applied.extend(q.take())
    assert effect(applied) == effect(sent)
    if sent and sent[-1][0] in CONTROLS:
        assert applied[-1] == sent[-1]
    assert q.superseded == len(sent) - len(applied)


def test_a_flood_of_targets_keeps_one_and_the_stop():
    q: CommandQueue[int] = CommandQueue()
    for i in range(10_000):
        q.put("joints", i)
    q.put("stop", -1)
    for i in range(10_000):
        q.put("joints", i)
    assert q.take() == [("stop", -1), ("joints", 9_999)]

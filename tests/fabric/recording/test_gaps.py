"""SeqGaps: what a recorder never received, from its publishers' numbering."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from fabric.recording.gaps import SeqGaps


def test_a_stretch_never_received_is_counted_once_as_one_hole():
    g = SeqGaps()
    for seq in [*range(100), *range(284, 300)]:
        g.seen("rf/w/robot/base1/pose", "sim-a", seq)
    assert (g.missed, g.holes) == (184, 1)


def test_streams_are_per_key_and_source_and_a_take_over_starts_one():
    g = SeqGaps()
    assert [g.seen("k", "sim-a", s) for s in (5, 6, 7)] == [0, 0, 0]
    assert g.seen("k", "sim-b", 40) == 0  # the heir numbers on from its primary: a new stream, nothing lost
    assert g.seen("j", "sim-a", 9) == 0
    assert (g.missed, g.holes) == (0, 0)


def test_late_or_repeated_samples_count_nothing_and_move_nothing_back():
    g = SeqGaps()
    for seq in (1, 2, 4, 3, 4, 2, 5):
        g.seen("k", "s", seq)
    assert (g.missed, g.holes) == (1, 1)


def test_samples_without_a_source_are_not_followed_and_the_table_is_bounded():
    g = SeqGaps(max_streams=2)
    assert g.seen("k", "", 5) == 0 and g.seen("k", "", 9) == 0
    for i in range(5):
        g.seen(f"flood/{i}", "mallory", 0)
        g.seen(f"flood/{i}", "mallory", 10)
    assert g.missed == 2 * 9 and len(g._last) == 2


@given(st.lists(st.integers(0, 500), min_size=1, max_size=200, unique=True))
def test_what_is_missed_is_what_lies_between_the_numbers_seen_in_order(seqs):
    kept = sorted(seqs)
    g = SeqGaps()
    for s in kept:
        g.seen("k", "s", s)
    assert g.missed == (kept[-1] - kept[0] + 1) - len(kept)

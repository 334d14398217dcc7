"""sim_peer.replica.kept_commands.CommandBuffer: what a standby keeps of the last seconds, on a clock passed in.

- It keeps at most ``max_count`` messages and ``max_bytes`` in all, within ``keep_s`` of the newest, and drops
  the oldest first: whatever is kept is the newest suffix of what was heard.
- ``take_since`` gives what arrived at that time or later, in arrival order, and empties the buffer.
"""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from sim_peer.replica.kept_commands import CommandBuffer


class Clock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


heard = st.lists(st.tuples(st.floats(0.0, 2.0), st.integers(0, 300)), max_size=60)


@given(heard)
def test_what_is_kept_is_the_newest_suffix_within_the_window_and_the_caps(items):
    clock = Clock()
    buf = CommandBuffer(keep_s=3.0, max_count=8, max_bytes=1000, clock=clock)
    sent = []
    for i, (dt, size) in enumerate(items):
        clock.now += dt
        sent.append((clock.now, f"k{i}", size))
        buf.keep(f"k{i}", i, size)
    kept = list(buf)
    assert len(kept) <= 8 and buf.kept_bytes <= 1000
    assert buf.kept_bytes == sum(k.size for k in kept)
    assert all(k.arrival >= clock.now - 3.0 for k in kept)
    assert [k.key for k in kept] == [key for _, key, _ in sent[len(sent) - len(kept) :]]  # the newest, in order
    if kept and len(kept) < len(sent):  # the one dropped just before the suffix broke a limit with it
        t, _, size = sent[len(sent) - len(kept) - 1]
        assert t < clock.now - 3.0 or len(kept) == 8 or buf.kept_bytes + size > 1000


def test_take_since_gives_what_came_at_or_after_it_in_order_and_empties_the_buffer():
    clock = Clock()
    buf = CommandBuffer(clock=clock)
    for i, t in enumerate([1.0, 2.0, 2.5, 3.0]):
        clock.now = t
        buf.keep(f"k{i}", f"m{i}", 10)
    assert buf.take_since(2.0) == [("k1", "m1"), ("k2", "m2"), ("k3", "m3")]
    assert len(buf) == 0 and buf.kept_bytes == 0 and buf.take_since(0.0) == []

"""The console's health line: what it reports is what was measured, and the benchmark reads it back."""

from __future__ import annotations

import asyncio
import math

from hypothesis import given
from hypothesis import strategies as st

from user_peer.console.health import Health, parse_line


def test_a_period_reports_its_own_samples_and_starts_again():
    h = Health()
    h.late += [1.0, 3.0, 250.0]
    h.key(1_000.0, arrived=1.020, sent=1.050)  # pressed at 1.000 s in the browser's clock
    h.key(None, arrived=2.0, sent=2.1)  # a page that gave no press time: not a sample
    h.dropped = 2
    first = h.take(pages=3)
    assert (first.pages, first.late_max, first.keys, first.dropped) == (3, 250.0, 1, 2)
    assert math.isclose(first.to_server_p50, 20.0, abs_tol=1e-6) and math.isclose(first.to_sent_p99, 50.0, abs_tol=1e-6)
    empty = h.take(pages=3)
    assert empty.keys == 0 and empty.dropped == 0 and math.isnan(empty.late_p99)


finite = st.floats(min_value=0, max_value=1e5, allow_nan=False)


@given(
    st.lists(finite, max_size=20),
    st.lists(st.tuples(finite, finite), max_size=20),
    st.integers(0, 500),
    st.integers(0, 50),
)
def test_the_line_reads_back_as_printed(late, keys, pages, dropped):
    h = Health()
    h.late += late
    for up, extra in keys:
        h.key(1.0, arrived=(1.0 + up) / 1e3, sent=(1.0 + up + extra) / 1e3)
    h.dropped = dropped
    taken = h.take(pages)
    back = parse_line("noise before " + Health.line(taken))
    assert back is not None and (back.pages, back.keys, back.dropped) == (pages, len(keys), dropped)
    for a, b in ((taken.late_p99, back.late_p99), (taken.to_sent_p99, back.to_sent_p99)):
        assert (math.isnan(a) and math.isnan(b)) or abs(a - b) <= 0.5


def test_the_probe_sees_a_blocked_event_loop():
    async def main() -> Health:
        h = Health()
        task = asyncio.ensure_future(h.probe())
        await asyncio.sleep(0.05)
        import time

        time.sleep(0.4)  # the loop blocked, as a page's slow handler would block it
        await asyncio.sleep(0.15)
        task.cancel()
        return h

    h = asyncio.run(main())
    assert max(h.late) >= 250.0, h.late

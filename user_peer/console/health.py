"""The console's own health, printed every few seconds: how late its event loop runs and how long a key takes.

A page's key press crosses the browser, the websocket, the server's event loop, a worker thread and zenoh
before the sim sees it. When a class says "the base answers late" the teacher (and ``robofabric bench
console``) needs to know which leg was slow: this module keeps, per period, the event loop's lateness (a
0.1 s sleep measured against the clock), the key's trip from the browser's ``Date.now()`` to the server's
handler, and from there to the twist handed to zenoh, and the pages connected; :meth:`Health.line` is one
line of text (parsed back by :func:`parse_line`).
"""

from __future__ import annotations

import asyncio
import re
import time
from dataclasses import dataclass, field

__all__ = ["Health", "HealthLine", "parse_line", "PERIOD_S"]

PERIOD_S = 10.0
"""How often the console prints its health line."""

TICK_S = 0.1


def _pct(values: list[float], q: float) -> float:
    if not values:
        return float("nan")
    s = sorted(values)
    return s[min(len(s) - 1, int(round(q / 100 * (len(s) - 1))))]


@dataclass(frozen=True)
class HealthLine:
    """One period's figures, in milliseconds (NaN when nothing was measured)."""

    pages: int
    late_p50: float
    late_p99: float
    late_max: float
    to_server_p50: float
    to_server_p99: float
    to_sent_p50: float
    to_sent_p99: float
    keys: int
    dropped: int = 0


@dataclass
class Health:
    """Samples of one period; the event loop's probe runs as a task of that loop (:meth:`probe`)."""

    late: list[float] = field(default_factory=list)
    to_server: list[float] = field(default_factory=list)
    to_sent: list[float] = field(default_factory=list)
    dropped: int = (
        0  # pages' websocket connections lost this period (each page reconnects within its window, or is gone)
    )

    def key(self, browser_ms: float | None, arrived: float, sent: float) -> None:
        """A key's twist went out: ``browser_ms`` the page's ``Date.now()`` at the press (same host clock, or
        None), ``arrived`` and ``sent`` this process's ``time.time()`` at the handler and after the publish."""
        if browser_ms:
            self.to_server.append(max(0.0, arrived * 1e3 - browser_ms))
            self.to_sent.append(max(0.0, sent * 1e3 - browser_ms))

    async def probe(self) -> None:
        """Forever: how late a ``TICK_S`` sleep wakes up (the loop's own lateness: every page waits as long)."""
        while True:
            t = time.monotonic()
            await asyncio.sleep(TICK_S)
            self.late.append(max(0.0, (time.monotonic() - t - TICK_S) * 1e3))

    def take(self, pages: int) -> HealthLine:
        """This period's figures; the samples start again."""
        late, up, sent = self.late, self.to_server, self.to_sent
        dropped, self.dropped = self.dropped, 0
        self.late, self.to_server, self.to_sent = [], [], []
        return HealthLine(
            pages,
            _pct(late, 50),
            _pct(late, 99),
            max(late, default=float("nan")),
            _pct(up, 50),
            _pct(up, 99),
            _pct(sent, 50),
            _pct(sent, 99),
            len(sent),
            dropped,
        )

    @staticmethod
    def line(h: HealthLine) -> str:
        return (
            f"console: health: {h.pages} pages · event loop late p50 {h.late_p50:.0f} / p99 {h.late_p99:.0f} / max "
            f"{h.late_max:.0f} ms · key to server p50 {h.to_server_p50:.0f} / p99 {h.to_server_p99:.0f} ms, to zenoh p50 "
            f"{h.to_sent_p50:.0f} / p99 {h.to_sent_p99:.0f} ms ({h.keys} keys) · {h.dropped} connections dropped"
        )


_LINE = re.compile(
    r"console: health: (\d+) pages · event loop late p50 (\S+) / p99 (\S+) / max (\S+) ms · key to server "
    r"p50 (\S+) / p99 (\S+) ms, to zenoh p50 (\S+) / p99 (\S+) ms \((\d+) keys\) · (\d+) connections dropped"
)


def parse_line(text: str) -> HealthLine | None:
    """A :meth:`Health.line` read back (None for any other line)."""
    m = _LINE.search(text)
    if m is None:
        return None
    g = m.groups()
    return HealthLine(int(g[0]), *(float(x) for x in g[1:8]), int(g[8]), int(g[9]))

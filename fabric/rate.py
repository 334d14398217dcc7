"""Clocks and fixed-rate loops.

The paper streamed at a fixed update rate independent of the simulation's
frame rate; here each stream owns a :class:`RateLoop`. Ticks are scheduled on
an absolute grid (``start + k / hz``) so error does not accumulate; a tick that
runs late is counted as an overrun and the grid skips ahead instead of firing a
burst of catch-up calls.

Time is injected: loops and leases take a :class:`Clock`, and tests pass a
:class:`FakeClock` whose ``sleep`` and ``wait`` advance time instead of waiting.
Every clock can ``wait(seconds, stop)``: a wait that a ``threading.Event``
cuts short (as trio's ``Clock`` owns how a deadline turns into sleeping), so
loops never need to know which clock they hold.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass
from typing import Callable, Protocol


class Clock(Protocol):
    def now(self) -> float: ...

    def sleep(self, seconds: float) -> None: ...

    def wait(self, seconds: float, stop: threading.Event | None = None) -> bool:
        """Wait ``seconds`` of this clock's time, or less if ``stop`` is set; True when ``stop`` is set."""
        ...


class MonotonicClock:
    """Real time from ``time.monotonic``.

    ``spin_s`` > 0 makes :meth:`wait` sleep until that long before the end and
    then spin (yielding the CPU) for the rest: a thread sleep may overshoot by
    tens of microseconds, which matters to a replayer keeping recorded gaps.
    """

    def __init__(self, spin_s: float = 0.0) -> None:
        if spin_s < 0:
            raise ValueError(f"spin time must not be negative, got {spin_s}")
        self.spin_s = float(spin_s)

    def now(self) -> float:
        return time.monotonic()

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds)

    def wait(self, seconds: float, stop: threading.Event | None = None) -> bool:
        end = time.monotonic() + max(0.0, seconds)
        coarse = seconds - self.spin_s
        if coarse > 0:
            if stop is not None:
                if stop.wait(coarse):
                    return True
            else:
                time.sleep(coarse)
        while time.monotonic() < end:
            if stop is not None and stop.is_set():
                return True
            time.sleep(0)
        return stop is not None and stop.is_set()


class FakeClock:
    """A clock for tests: time moves only when told to, and never backwards."""

    def __init__(self, start: float = 0.0) -> None:
        self._now = float(start)
        self._lock = threading.Lock()

    def now(self) -> float:
        with self._lock:
            return self._now

    def jump(self, seconds: float) -> None:
        if seconds < 0:
            raise ValueError(f"time cannot go backwards (jump of {seconds} s)")
        with self._lock:
            self._now += seconds

    def sleep(self, seconds: float) -> None:
        self.jump(max(0.0, seconds))

    def wait(self, seconds: float, stop: threading.Event | None = None) -> bool:
        """Advance by the whole wait at once, unless ``stop`` is already set (then time stands still)."""
        if stop is not None and stop.is_set():
            return True
        self.jump(max(0.0, seconds))
        return stop is not None and stop.is_set()


@dataclass(frozen=True, slots=True)
class RateStats:
    """What a loop has done: ticks run, ticks skipped because the callback overran, and its period."""

    ticks: int
    overruns: int
    skipped: int
    period: float


class RateLoop:
    """Call ``callback(now)`` at ``hz`` on an absolute schedule.

    ``step()`` runs at most one due tick and returns the time until the next;
    ``run(stop)`` loops until ``stop`` is set; ``start()`` (or ``with RateLoop(...) as loop:``)
    runs it in a daemon thread, which ``close()`` (or leaving the ``with``) ends.

    ``start_at`` (a time of ``clock``) fixes the grid's origin: ticks at ``start_at + k / hz``, the first one
    not before the first ``step()``. Loops given one origin and staggered offsets from it keep their ticks
    apart for as long as they run (:func:`staggered`); without it the grid starts at the first ``step()``.
    """

    def __init__(
        self,
        hz: float,
        callback: Callable[[float], None],
        *,
        clock: Clock | None = None,
        name: str = "",
        start_at: float | None = None,
    ) -> None:
        if not hz > 0:
            raise ValueError(f"rate must be positive, got {hz}")
        self.hz = float(hz)
        self.period = 1.0 / self.hz
        self.callback = callback
        self.clock = clock or MonotonicClock()
        self.name = name
        self.start_at = start_at
        self._next: float | None = None
        self._ticks = 0
        self._overruns = 0
        self._skipped = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def stats(self) -> RateStats:
        return RateStats(self._ticks, self._overruns, self._skipped, self.period)

    def step(self) -> float:
        now = self.clock.now()
        if self._next is None:
            self._next = now if self.start_at is None else self._first_on_grid(now)
        if now < self._next:
            return self._next - now
        self.callback(now)
        self._ticks += 1
        self._next += self.period
        after = self.clock.now()
        if after >= self._next:
            missed = int((after - self._next) // self.period) + 1
            self._overruns += 1
            self._skipped += missed
            self._next += missed * self.period
        return max(0.0, self._next - after)

    def _first_on_grid(self, now: float) -> float:
        """The first tick of the ``start_at`` grid at or after ``now`` (a loop started late joins its grid)."""
        start = float(self.start_at)  # type: ignore[arg-type]
        if now <= start:
            return start
        return start + math.ceil((now - start) / self.period - 1e-9) * self.period

    def run(self, stop: threading.Event | None = None) -> None:
        stop = stop or self._stop
        while not stop.is_set():
            wait = self.step()
            if wait > 0:
                self.clock.wait(wait, stop)

    def start(self) -> "RateLoop":
        self._thread = threading.Thread(target=self.run, name=f"rate-{self.name or self.hz}", daemon=True)
        self._thread.start()
        return self

    def close(self, timeout: float = 2.0) -> None:
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout)

    def __enter__(self) -> "RateLoop":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()


def staggered(rates: dict[str, float]) -> dict[str, float]:
    """Each loop's offset (s) from a shared origin, so that loops started together never tick together.

    Fastest first, loop ``i`` of ``n`` is put ``i / n`` of the fastest period after the origin. When every
    period is a whole multiple of the fastest (a sim's 100, 50 and 20 Hz streams), every loop's ticks fall on
    its own offset modulo the fastest period, so any two ticks of different loops are at least ``1 / n`` of
    that period apart, forever. Loops started on one origin without offsets put every 50 Hz tick on a 100 Hz
    one: a subscriber of both streams got both bursts at once, and the later one waited for the other.
    """
    if not rates:
        return {}
    fastest = 1.0 / max(rates.values())
    order = sorted(rates, key=lambda name: (-rates[name], name))
    return {name: i * fastest / len(order) for i, name in enumerate(order)}


def phases(rates: dict[str, float], members: dict[str, int]) -> dict[str, int]:
    """How many phases each loop's members are dealt over: its loop then ticks that many times faster, each tick
    serving one phase's members, so each member keeps its rate and a tick carries a share of the burst.

    A loop whose period is ``m`` times the fastest one is split into the largest divisor of ``m`` no greater
    than its member count: its loop's period stays a whole multiple of the fastest, so :func:`staggered`
    offsets still keep every loop's ticks apart. A loop whose period is no whole multiple keeps one phase. A
    sim's 20 Hz scans of 8 robots beside 100 Hz joints: 5 phases of 1-2 robots, one every 10 ms, instead of all
    8 scans (and their sonars) in one tick, whose burst held up a subscriber of every stream (the ROS 2
    bridge) for the joints that came next.
    """
    if not rates:
        return {}
    fastest = max(rates.values())
    out: dict[str, int] = {}
    for name, hz in rates.items():
        ratio = fastest / hz
        whole = round(ratio)
        if whole < 1 or abs(ratio - whole) > 1e-9 * ratio:
            out[name] = 1
            continue
        n = max(1, members.get(name, 1))
        out[name] = max(d for d in range(1, min(whole, n) + 1) if whole % d == 0)
    return out


def parse_rates(spec: str, defaults: dict[str, float]) -> dict[str, float]:
    """Parse ``joints=100,pose=50`` into rates over ``defaults``; unknown streams or bad numbers raise ``ValueError``."""
    rates = dict(defaults)
    if not spec:
        return rates
    for item in spec.split(","):
        name, sep, value = item.partition("=")
        name = name.strip()
        if not sep or name not in defaults:
            raise ValueError(f"bad rate {item!r}: expected NAME=HZ with NAME in {', '.join(defaults)}")
        try:
            hz = float(value)
        except ValueError:
            raise ValueError(f"bad rate {item!r}: {value!r} is not a number") from None
        if not hz > 0 or hz > 100_000:
            raise ValueError(f"bad rate {item!r}: must be in (0, 100000] Hz")
        rates[name] = hz
    return rates

"""How many physics steps to take now: real time, X times real time, or as fast as possible.

Pure: the clock is injected and :meth:`Pacer.due` returns a number of steps, so
pacing is tested with a FakeClock. When the simulation cannot keep up, the
pacer takes at most ``max_lag`` of sim time at once and lets the rest go (counted
in ``dropped``) instead of running a long catch-up burst. With ``wake_s`` the steps come in chunks of at least that
much wall time: the same steps at the same sim times, fewer wake-ups of the stepping thread.
"""

from __future__ import annotations

import math

from fabric.rate import Clock, MonotonicClock

MAX = None  # speed value meaning "as fast as possible"


def parse_speed(text: str | float | None) -> float | None:
    """``"max"`` -> None (as fast as possible); a positive number -> that multiple of real time."""
    if text is None:
        return 1.0
    if isinstance(text, str) and text.strip().lower() in ("max", "inf", "unlimited"):
        return MAX
    try:
        v = float(text)
    except (TypeError, ValueError):
        raise ValueError(f"speed {text!r} must be a positive number or 'max'") from None
    if not math.isfinite(v) or v <= 0:
        raise ValueError(f"speed {text!r} must be a positive number or 'max'")
    return v


class Pacer:
    def __init__(
        self,
        dt: float,
        speed: float | None = 1.0,
        *,
        clock: Clock | None = None,
        chunk: int = 50,
        max_lag: float = 0.25,
        wake_s: float = 0.0,
    ) -> None:
        """``wake_s``: the least wall time between two chunks at real time or slower (0: each step as it is due)."""
        self.dt = dt
        self.speed = speed
        self.clock = clock or MonotonicClock()
        self.chunk = chunk
        self.max_lag = max_lag
        self.batch = 1 if speed is None else max(1, int(wake_s * speed / dt + 1e-9))  # steps a chunk waits for
        self._t0: float | None = None
        self._steps = 0  # steps owed to the schedule so far (including dropped ones)
        self.dropped = 0

    def due(self) -> int:
        """Steps to take now (0: wait ``wait()`` seconds). Call :meth:`done` with what was taken."""
        if self.speed is None:
            return self.chunk
        now = self.clock.now()
        if self._t0 is None:
            self._t0 = now
        owed = int((now - self._t0) * self.speed / self.dt) - self._steps
        limit = max(1, int(self.max_lag * self.speed / self.dt))
        if owed > limit:
            self.dropped += owed - limit
            self._steps += owed - limit
            owed = limit
        return owed if owed >= self.batch else 0

    def done(self, n: int) -> None:
        self._steps += n

    def wait(self) -> float:
        """Seconds of wall time until the next step is due."""
        if self.speed is None or self._t0 is None:
            return 0.0
        next_wall = self._t0 + (self._steps + self.batch) * self.dt / self.speed
        return max(0.0, next_wall - self.clock.now())

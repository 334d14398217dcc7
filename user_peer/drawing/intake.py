"""What comes in, before anything is drawn: which keys the viewer draws, each message's times, thinning, and
the stream-rate plots.

Keys repeat in a world, so each one is parsed once (up to a bound: a flood of odd keys is parsed each time).
A message's time is its header's wall clock, else its arrival here; its sim time when the header has one.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import rerun as rr

from fabric import keys
from user_peer.drawing.canvas import Rows
from user_peer.rerun_columns import SCALARS, scalars, send

__all__ = ["Intake", "RateMeter", "message_times"]

MAX_KEYS = 100_000
"""Parsed keys kept: a world's keys repeat; past this, odd keys are parsed each time."""


def message_times(msg: Any, log_time_ns: int) -> tuple[int, float]:
    """(wall_time ns: the header's wall clock, else the receive time; sim_time s, 0 when unknown)."""
    header = getattr(msg, "header", None)
    if header is None:
        return log_time_ns, 0.0
    return (header.wall_ns if header.wall_ns > 0 else log_time_ns), (float(header.stamp) if header.stamp > 0 else 0.0)


class Intake:
    """Key parsing and thinning: ``max_hz`` draws at most that many messages a second per key (0: all)."""

    def __init__(self, max_hz: float) -> None:
        self.min_dt = int(1e9 / max_hz) if max_hz > 0 else 0
        self.skipped = 0
        self._last: dict[str, int] = {}
        self._keys: dict[str, tuple[keys.ParsedKey, str] | None] = {}

    def parse(self, key: str) -> tuple[keys.ParsedKey, str] | None:
        """The key parsed, with its stream's label (``arm1/joints``, ``map/map``); None: not a fabric key."""
        parsed = self._keys.get(key, False)
        if parsed is not False:
            return parsed
        try:
            p = keys.parse(key)
        except ValueError:
            return None
        if p.category == "robot":
            label = f"{p.subject}/{p.leaf}"
        elif p.category == "cmd":
            label = f"{p.subject}/cmd_{p.leaf}"
        else:
            label = f"{p.category}/{p.subject}" if p.subject else p.category
        if len(self._keys) < MAX_KEYS:
            self._keys[key] = (p, label)
        return p, label

    def due(self, key: str, t_ns: int) -> bool:
        """Whether a message on ``key`` at ``t_ns`` is drawn, or thinned out (counted in ``skipped``)."""
        if self.min_dt <= 0:
            return True
        last = self._last.get(key)
        if last is not None and t_ns - last < self.min_dt:
            self.skipped += 1
            return False
        self._last[key] = t_ns
        return True


class RateMeter:
    """Messages per second per stream, one value per ``period_s`` (the messages since the last one), plotted
    under ``plots/rates/{label}``."""

    def __init__(self, period_s: float) -> None:
        self.period = int(period_s * 1e9)
        self._window: dict[str, list[int]] = {}  # label -> [window start ns, messages since]
        self._rows: dict[str, Rows] = {}
        self.filed = 0  # periods closed and filed, every stream's: a rate is drawn only after a period of arrivals

    def count(self, label: str, t_ns: int) -> bool:
        """Count one message of ``label`` at ``t_ns``; True when that closed a period and filed its rate."""
        w = self._window.get(label)
        if w is None:
            self._window[label] = [t_ns, 0]
            return False
        w[1] += 1
        if t_ns - w[0] < self.period:
            return False
        rows = self._rows.get(label)
        if rows is None:
            rows = self._rows[label] = Rows()
        rows.add(t_ns, 0.0, w[1] * 1e9 / (t_ns - w[0]))
        w[0], w[1] = t_ns, 0
        self.filed += 1
        return True

    def flush(self, rec: rr.RecordingStream) -> None:
        for label, rows in self._rows.items():
            if rows.items:
                send(rec, f"plots/rates/{label}", rows.times(), [scalars(SCALARS, np.asarray(rows.items, dtype=float))])
                rows.clear()

"""Bumper stops, told on /rosout: the sim's ``collision`` events (its bumper stopped a base before an obstacle) in words.

A ROS node whose ``cmd_vel`` stops moving the base would otherwise see only odometry at rest. The bridge reads the
events its world's event log has from each robot's authority (a sim; a forged event on a key any login may write is
not acted on, :mod:`user_peer.event_log`) once a second, with the sims' refusals, and says each robot's stops in one
line: a warning for a base this bridge drives (its ROS commands were stopped), info for the others (someone else
drives them; a ROS user watching the class still sees why a base stopped).
"""

from __future__ import annotations

from collections.abc import Collection, Iterable

from fabric.interfaces import Event, EventKind

__all__ = ["BUMP_KINDS", "bump_lines"]

BUMP_KINDS: frozenset[str] = frozenset({EventKind.COLLISION})


def bump_lines(events: Iterable[Event], driven: Collection[str]) -> list[tuple[bool, str]]:
    """(a warning?, the line) per robot stopped by its bumper in ``events``, in robot order: how many stops, the
    sim's time of the last and its reason."""
    last: dict[str, Event] = {}
    count: dict[str, int] = {}
    for ev in events:
        if ev.kind in BUMP_KINDS and ev.object:
            last[ev.object] = ev
            count[ev.object] = count.get(ev.object, 0) + 1
    out = []
    for rid in sorted(last):
        ev, n = last[rid], count[rid]
        t = ev.data.get("t") if isinstance(ev.data, dict) else None
        detail = (ev.data.get("detail") if isinstance(ev.data, dict) else None) or ev.reason or "an obstacle"
        when = f" at sim time {float(t):.2f} s" if isinstance(t, (int, float)) else ""
        times = f" ({n} stops since the last report)" if n > 1 else ""
        out.append((rid in driven, f"bumper stop: {rid}{when}, {detail}{times}"))
    return out

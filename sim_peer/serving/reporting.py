"""What a sim tells the world: events on ``event/{kind}/{robot}``, and refusals counted and reported.

Refusals and bad payloads are reported at most a few times per reason per interval
(:meth:`fabric.reports.Reports.should_report`), with the count of the rest; the counters and rate-limit keys are
fixed words, never client text, so made-up users or ids cannot grow them.
"""

from __future__ import annotations

from collections import Counter
from typing import Any, Callable

from fabric.interfaces import Event, EventKind
from fabric.limits import clip
from sim_peer.physics.world import SimWorld

__all__ = ["Reporter"]


class Reporter:
    """Events and refusals of one sim peer, about the robots and objects of ``world``."""

    def __init__(self, fabric: Any, world: SimWorld, counters: Counter[str]) -> None:
        self.fabric = fabric
        self.world = world
        self.counters = counters

    def _known(self, robot: str) -> bool:
        return robot in self.world.robots or robot in self.world.objects

    def event(
        self,
        kind: str,
        robot: str,
        reason: str,
        *,
        user: str = "",
        severity: str = "warning",
        data: dict | None = None,
        limit: str | None = None,
    ) -> None:
        """Publish an event on ``event/{kind}/{robot}`` (``event/{kind}`` for ids this sim does not have).

        ``limit``: a rate-limit key of fixed words (fabric.reports.Reports.should_report), checked before
        anything is built, so a flood of refusals costs a counter each."""
        if limit is not None:
            suppressed = self.fabric.reports.should_report(limit)
            if suppressed is None:
                return
            if suppressed:
                data = {**(data or {}), "suppressed": suppressed}
        key_parts = (kind, robot) if self._known(robot) else (kind,)
        ev = Event(
            kind=kind,
            reason=reason,
            object=robot,
            user=user,
            severity=severity,
            data=data or {},
            header=self.fabric.header("event", stamp=self.world.time),
        )
        self.fabric.reports.emit(ev, *key_parts)

    def reject(
        self,
        robot: str,
        command: str,
        reason: str | Callable[[], str],
        detail: str | Callable[[], str],
        user: str = "",
        *,
        code: str | None = None,
    ) -> None:
        """Count and report a refusal. ``code`` (default ``reason``) is the counter and rate-limit name:
        a fixed word, never client text, so made-up users or ids cannot grow the counters. ``reason``
        and ``detail`` may be callables, built only when the refusal is reported."""
        code = code or ("refused" if callable(reason) else reason)
        self.counters["rejected"] += 1
        self.counters[f"rejected:{code}"] += 1
        known = self._known(robot)
        suppressed = self.fabric.reports.should_report(f"reject:{robot if known else '?'}:{code}")
        if suppressed is None:
            return
        # code: which check refused it ("refused": the ownership gate), so a client tells NotOwner from a bad command
        data = {"command": command, "code": code, "detail": detail() if callable(detail) else detail}
        if suppressed:
            data["suppressed"] = suppressed
        self.event(
            EventKind.REJECT,
            robot if known else clip(robot, 64),
            reason() if callable(reason) else reason,
            user=user,
            data=data,
        )

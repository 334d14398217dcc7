"""A sim's robot streams: what the robots' ``streams()`` declare, grouped by rate, each group on its own loop.

Each group runs on a :class:`fabric.rate.RateLoop` (wall-clock rates, independent of the physics step; headers
carry sim time), the groups' grids staggered from one origin (:func:`fabric.rate.staggered`: 100 Hz joints at
0, 50 Hz poses a third of 10 ms later, 20 Hz scans two thirds): each group's burst of every robot's messages
reaches a subscriber of several streams (the ROS 2 bridge, a viewer) on its own, not on top of another's. A tick
reads every stream of its group under the world's lock, then builds and publishes outside it. A stream on a key
:mod:`fabric.keys` does not know is left out with a warning (a new stream name is a protocol change:
``fabric.keys.ROBOT_STREAMS``).
"""

from __future__ import annotations

import logging
import threading
from collections import Counter
from typing import Any, Callable

from fabric import keys
from fabric.rate import MonotonicClock, RateLoop, staggered
from sim_peer.robot import Build, Stream
from sim_peer.world import SimWorld

log = logging.getLogger("robofabric.sim")

__all__ = ["DEFAULT_RATES", "StreamLoops", "gather_streams"]

DEFAULT_RATES = {"joints": 100.0, "pose": 50.0, "scan": 20.0}


def gather_streams(world_name: str, world: SimWorld) -> dict[str, list[tuple[str, Stream]]]:
    """Every robot's streams by rate group, each with its key."""
    groups: dict[str, list[tuple[str, Stream]]] = {g: [] for g in DEFAULT_RATES}
    for rid, r in world.robots.items():
        for st in r.streams():
            if st.name not in keys.ROBOT_STREAMS:
                log.warning("robot %s: stream %r is not a robot stream of fabric.keys; not published", rid, st.name)
                continue
            groups.setdefault(st.rate, []).append((keys.robot_stream(world_name, rid, st.name), st))
    return {g: entries for g, entries in groups.items() if entries}


class StreamLoops:
    """The stream groups of ``world`` and their rates (``rates`` over the defaults, then each group's own)."""

    def __init__(self, fabric: Any, world: SimWorld, lock: threading.RLock, counters: Counter[str],
                 rates: dict[str, float] | None = None) -> None:
        self.fabric, self.world, self.lock, self.counters = fabric, world, lock, counters
        self.rates = {**DEFAULT_RATES, **(rates or {})}
        self.groups = gather_streams(fabric.world, world)
        for group, entries in self.groups.items():
            self.rates.setdefault(group, entries[0][1].hz)
        self._loops: list[RateLoop] = []

    @property
    def loops(self) -> dict[str, RateLoop]:
        """The running loop of each group (empty before ``start()``)."""
        return dict(zip(self.groups, self._loops))

    def offsets(self) -> dict[str, float]:
        """Each group's first tick after the loops' shared origin (s): apart, so their bursts never coincide."""
        return staggered({group: self.rates[group] for group in self.groups})

    def start(self) -> None:
        clock = MonotonicClock()
        origin, offsets = clock.now(), self.offsets()
        for group, entries in self.groups.items():
            tick = self._guard(group, self._publisher(entries))
            self._loops.append(RateLoop(self.rates[group], tick, clock=clock, name=f"sim-{group}",
                                        start_at=origin + offsets[group]).start())

    def stop(self) -> None:
        for loop in self._loops:
            loop.close()

    def _guard(self, name: str, fn: Callable[[float], None]) -> Callable[[float], None]:
        def tick(now: float) -> None:
            if self.fabric.closed:
                return
            try:
                fn(now)
            except Exception:
                self.counters[f"stream_errors:{name}"] += 1
                log.exception("stream %s failed", name)

        return tick

    def _publisher(self, entries: list[tuple[str, Stream]]) -> Callable[[float], None]:
        """One rate group's tick: read every stream under the lock, then build and publish outside it."""
        positions = any(st.positions for _, st in entries)

        def publish(now: float) -> None:
            world = self.world
            out: list[tuple[str, Build]] = []
            with self.lock:
                stamp = world.time
                if positions:
                    world.sync()
                physics = world.physics
                for key, st in entries:
                    build = st.read(physics)
                    if build is not None:
                        out.append((key, build))
            for key, build in out:
                self.fabric.publish(key, build(self.fabric.header(key, stamp=stamp)))

        return publish

"""A sim's robot streams: what the robots' ``streams()`` declare, grouped by rate, each group on its own loop.

Each group runs on a :class:`fabric.rate.RateLoop` (wall-clock rates, independent of the physics step; headers
carry sim time), the groups' grids staggered from one origin (:func:`fabric.rate.staggered`: 100 Hz joints at
0, 50 Hz poses a third of 10 ms later, 20 Hz scans two thirds): each group's burst of every robot's messages
reaches a subscriber of several streams (the ROS 2 bridge, a viewer) on its own, not on top of another's. A
slower group's robots are dealt over phases (:func:`fabric.rate.phases`), its loop ticking as often as the
fastest and each tick serving one phase: 8 bases' scans go out 1-2 robots every 10 ms, each robot still at
20 Hz, not all 8 (with their sonars) in one tick. A tick reads its streams under the world's lock, then builds
and publishes outside it. A stream on a key :mod:`fabric.keys` does not know is left out with a warning (a new
stream name is a protocol change: a row of ``fabric.streams.STREAMS``).
"""

from __future__ import annotations

import logging
import threading
from collections import Counter
from typing import Any, Callable

from fabric import keys
from fabric.rate import MonotonicClock, RateLoop, phases, staggered
from fabric.streams import default_rates
from sim_peer.robot import Build, Stream
from sim_peer.physics.world import SimWorld

log = logging.getLogger("robofabric.sim")

__all__ = ["DEFAULT_RATES", "StreamLoops", "gather_streams"]

DEFAULT_RATES = default_rates()
"""Each rate group's default rate (Hz), from :data:`fabric.streams.STREAMS`: joints 100, pose 50, scan 20."""


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

    def __init__(
        self,
        fabric: Any,
        world: SimWorld,
        lock: threading.RLock,
        counters: Counter[str],
        rates: dict[str, float] | None = None,
    ) -> None:
        self.fabric, self.world, self.lock, self.counters = fabric, world, lock, counters
        self.rates = {**DEFAULT_RATES, **(rates or {})}
        self.groups = gather_streams(fabric.world, world)
        for group, entries in self.groups.items():
            self.rates.setdefault(group, entries[0][1].hz)
        self.phases = phases(
            {g: self.rates[g] for g in self.groups}, {g: len(_robots(entries)) for g, entries in self.groups.items()}
        )
        """Each group's phases: its loop ticks ``rate * phases`` times a second, each robot on one tick in that many."""
        self._loops: list[RateLoop] = []

    @property
    def loops(self) -> dict[str, RateLoop]:
        """The running loop of each group (empty before ``start()``)."""
        return dict(zip(self.groups, self._loops))

    def offsets(self) -> dict[str, float]:
        """Each group's first tick after the loops' shared origin (s): apart, so their bursts never coincide."""
        return staggered({group: self.loop_rate(group) for group in self.groups})

    def loop_rate(self, group: str) -> float:
        """How often ``group``'s loop ticks (Hz): its rate times its phases."""
        return self.rates[group] * self.phases[group]

    def start(self) -> None:
        clock = MonotonicClock()
        origin, offsets = clock.now(), self.offsets()
        for group, entries in self.groups.items():
            tick = self._guard(group, self._publisher(_dealt(entries, self.phases[group])))
            self._loops.append(
                RateLoop(
                    self.loop_rate(group), tick, clock=clock, name=f"sim-{group}", start_at=origin + offsets[group]
                ).start()
            )

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

    def _publisher(self, dealt: list[list[tuple[str, Stream]]]) -> Callable[[float], None]:
        """One rate group's tick: read the streams of the next phase's robots under the lock, then build and
        publish outside it (a tick the loop skipped, late, leaves the phases' order as it was)."""
        positions = [any(st.positions for _, st in entries) for entries in dealt]
        turn = [0]
        listened = getattr(self.fabric, "listened", lambda _key: True)
        stamp_ = getattr(self.fabric, "stamp", None)
        # the freeze watch (fabric.authority_stamp) takes the gap between two publications for a freeze: a sim that
        # skips its streams, nobody listening, must still tell it that it runs (a lab's primary muzzled itself and
        # bumped its term when a standby came, its last publication long ago)
        beat = stamp_.may_put if stamp_ is not None else (lambda: True)

        def publish(now: float) -> None:
            i = turn[0]
            turn[0] = (i + 1) % len(dealt)
            # asked before the world's lock (a key's first ask declares its probe with zenoh): nobody listens, zenoh
            # would drop it after its reading and encoding
            entries = [(key, st) for key, st in dealt[i] if listened(key)]
            world = self.world
            out: list[tuple[str, Build]] = []
            if entries:
                with self.lock:
                    stamp = world.time
                    if positions[i]:
                        world.sync()
                    physics = world.physics
                    for key, st in entries:
                        build = st.read(physics)
                        if build is not None:
                            out.append((key, build))
            if not out:  # nothing listened to: the tick still counts as one, for the freeze watch
                beat()
            for key, build in out:
                self.fabric.publish(key, build(self.fabric.header(key, stamp=stamp)))

        return publish


def _robots(entries: list[tuple[str, Stream]]) -> list[str]:
    """The robots of a group's entries, in order."""
    return list(dict.fromkeys(keys.parse(key).subject for key, _ in entries))


def _dealt(entries: list[tuple[str, Stream]], n: int) -> list[list[tuple[str, Stream]]]:
    """``entries`` dealt over ``n`` phases robot by robot, in turn (a robot's streams stay in one phase)."""
    phase = {rid: i % n for i, rid in enumerate(_robots(entries))}
    return [[(key, st) for key, st in entries if phase[keys.parse(key).subject] == p] for p in range(n)]

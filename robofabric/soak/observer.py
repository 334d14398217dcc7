"""The soak's observer: one session on a host the nemesis never touches, writing what the wire carries.

It subscribes without the fence (raw samples, decoded here), because the checker must see what a fenced
consumer would drop too: records and joints of a stale authority are kept with their term, and the
checker decides. Joints are thinned (a robot's sample is written when its sim or term changes, when it
moved 0.05 rad since the last one written, or after a second), so an hour's history stays tens of MB and
a jump between two samples is still a jump between two written ones.

It hears what it missed while its own link was down (a router's restart): ownership records and ownership and
reject events are kept by their publishers (:func:`fabric.keys.cache_size`), and a subscription with history asks
for them when each publisher's token is back (:mod:`fabric.history`). Such a record or event is written with the
time it arrived, after the restart.

It is also the nemesis's hand on the wire: :meth:`Observer.replay` puts a command in a user's name with an
epoch she held before (a delayed duplicate), which a sim must refuse.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any

from fabric import keys
from fabric.interfaces import EventKind
from fabric.codec import decode
from fabric.interfaces import Command, Event, JointState, JointTarget, OwnershipRecord

from robofabric.soak.history import Cmd, Joints, OwnEvent, OwnRec, Reject, Writer

__all__ = ["Observer", "JOINT_STEP", "JOINT_EVERY_S"]

JOINT_STEP = 0.05
"""A robot's joints are written again once some joint moved this far (rad) since the last written sample."""
JOINT_EVERY_S = 1.0
"""...or after this long."""


class Observer:
    """Subscribes to a world's records, events, commands and joints; writes them to ``path`` (JSON lines)."""

    def __init__(self, world: str, endpoint: str, path: Path | str, *, peer_id: str = "observer") -> None:
        from fabric.config import FabricConfig
        from fabric.session import Fabric

        self.world = world
        self.writer = Writer(path)
        self.counters = {"undecodable": 0, "samples": 0}
        self._last: dict[str, Joints] = {}
        self._records: dict[str, OwnRec] = {}
        self._lock = threading.Lock()
        self.fab = Fabric(FabricConfig.resolve(world=world, connect=[endpoint]), kind="tool", peer_id=peer_id)
        # with history: records and ownership/reject events it missed while its link was down (a router's restart)
        # come from their publishers' caches when the link is back (fabric.keys.cache_size, fabric.history)
        self.fab.subscribe_raw(keys.own_all(world), self._on_sample, history=True)
        self.fab.subscribe_raw(keys.event_all(world), self._on_sample, history=True)
        self.fab.subscribe_raw(keys.robot_cmd_all(world), self._on_sample)
        self.fab.subscribe_raw(keys.robot_stream_all(world, "joints"), self._on_sample)

    def _on_sample(self, sample: Any) -> None:
        t = time.monotonic()
        key = str(sample.key_expr)
        self.counters["samples"] += 1
        try:
            msg = decode(sample.payload.to_bytes())
            parsed = keys.parse(key)
        except Exception:
            self.counters["undecodable"] += 1
            return
        rec = _record(t, parsed, msg)
        if rec is None:
            return
        if isinstance(rec, Joints) and not self._worth_writing(rec):
            return
        if isinstance(rec, OwnRec):
            with self._lock:
                last = self._records.get(rec.obj)
                if last is None or rec.term >= last.term:
                    self._records[rec.obj] = rec
        self.writer.write(rec)

    def _worth_writing(self, j: Joints) -> bool:
        with self._lock:
            last = self._last.get(j.robot)
            if (
                last is not None
                and last.source == j.source
                and last.term == j.term
                and j.t - last.t < JOINT_EVERY_S
                and len(last.q) == len(j.q)
                and max((abs(a - b) for a, b in zip(last.q, j.q)), default=0.0) < JOINT_STEP
            ):
                return False
            self._last[j.robot] = j
            return True

    def owned(self) -> dict[str, tuple[str, int]]:
        """Each owned object's owner and epoch, by the newest authority's latest record."""
        with self._lock:
            return {o: (r.owner, r.epoch) for o, r in self._records.items() if r.owner}

    def replay(self, robot: str, user: str, epoch: int, q: list[float], speed_scale: float = 0.3) -> None:
        """Put a joints command in ``user``'s name under ``epoch`` on her key, as a delayed duplicate would arrive."""
        cmd = Command(user=user, epoch=int(epoch), body=JointTarget(q=q, speed_scale=speed_scale))
        self.fab.publish(keys.robot_cmd(self.world, robot, "joints", user), cmd)

    def close(self) -> None:
        self.fab.close()
        self.writer.close()


def _record(t: float, parsed: Any, msg: Any) -> Any:
    """The history record of one decoded sample, or None for what the checker does not read."""
    if parsed.category == "own" and isinstance(msg, OwnershipRecord):
        h = msg.header
        return OwnRec(t, msg.object, msg.owner, msg.epoch, tuple(msg.queue), msg.state, h.source, h.term)
    if parsed.category == "event" and isinstance(msg, Event):
        if msg.kind.startswith("own_"):
            return OwnEvent(t, msg.kind, msg.object, msg.user, msg.reason, msg.header.source)
        if msg.kind == EventKind.REJECT:
            return Reject(t, msg.object or parsed.leaf, msg.user, msg.reason)
        return None
    if parsed.category == "cmd" and isinstance(msg, Command):
        q = tuple(float(x) for x in msg.body.q) if isinstance(msg.body, JointTarget) else ()
        return Cmd(t, parsed.subject, parsed.user, msg.epoch, parsed.leaf, q)
    if parsed.category == "robot" and isinstance(msg, JointState):
        h = msg.header
        return Joints(t, parsed.subject, tuple(round(float(x), 5) for x in msg.q), round(h.stamp, 4), h.source, h.term)
    return None

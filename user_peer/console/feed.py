"""Every robot's pose for a page's view, at the view's rate and not the sim's, decoded once for the whole console.

The view of a page draws every robot of the world five times a second; the sim publishes each pose fifty
times a second. A callback per sample made each page's session hand every pose of every robot to Python
(the zenoh-python sample, its key, its bytes): 20 pages of a 20-robot class were 20,000 samples a second in
the console server, the one cost that grew with pages x robots. Here a page's session keeps the poses in
zenoh's own ring (:class:`zenoh.handlers.RingChannel`: the newest ``capacity`` samples, the older dropped in
Rust, no Python), and the view takes what is there when it redraws (:meth:`PoseFeed.drain`).

Each page reads through its own session (what her login may read: nothing is shared between sessions). The
decoding is shared: all pages redraw on one clock (:mod:`.ticker`), so they hold the same newest sample of a
robot, and :class:`Decoded` turns those bytes into a :class:`~fabric.interfaces.Pose` once, for every page
that holds the same bytes.
"""

from __future__ import annotations

import logging
from typing import Any, Callable, Hashable, TypeVar

import zenoh

from fabric import keys
from fabric.codec import DecodeError, decode
from fabric.interfaces import Pose

__all__ = ["PoseFeed", "Decoded", "ring_capacity"]

log = logging.getLogger("robofabric.console")

T = TypeVar("T")


def ring_capacity(robots: int) -> int:
    """How many samples a page's ring keeps: two of the sim's bursts (one pose of every robot each), so the
    newest pose of every robot is in it when the view redraws, whatever the burst's order."""
    return max(16, 2 * robots + 8)


class PoseFeed:
    """One page's subscription to every robot's pose, read when its view redraws."""

    def __init__(self, fabric: Any, world: str, capacity: int) -> None:
        # Fabric.subscribe_raw passes its second argument to zenoh's declare_subscriber, which takes a handler
        # as well as a callback: the ring is that handler
        self._sub = fabric.subscribe_raw(keys.robot_stream_all(world, "pose"), zenoh.handlers.RingChannel(capacity))
        self.raw: dict[str, bytes] = {}  # every robot's newest pose seen so far, undecoded
        self.bad = 0  # samples whose key names no robot's pose (counted, ignored)
        self.taken = 0  # samples taken from the ring (the rest were dropped there, in zenoh)
        self.closed = False

    def drain(self) -> dict[str, bytes]:
        """Take what the ring holds: :attr:`raw` with every robot's newest pose."""
        if self.closed:
            return self.raw
        try:
            while (sample := self._sub.try_recv()) is not None:
                self.taken += 1
                parts = str(sample.key_expr).split("/")  # rf/{world}/robot/{id}/pose
                if len(parts) == 5 and parts[2] == "robot" and parts[4] == "pose":
                    self.raw[parts[3]] = sample.payload.to_bytes()
                else:
                    self.bad += 1
        except Exception as exc:  # the session closed under the page (zenoh.ZError): the view keeps what it had
            log.info("console: pose feed closed: %s", exc)
            self.closed = True
        return self.raw

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            try:
                self._sub.undeclare()
            except Exception:
                pass


class Decoded:
    """The console's one decoder of poses: the same bytes of a robot's pose, held by many pages, decode once, and
    draw once for each way a page may draw it (:meth:`drawn`)."""

    def __init__(self) -> None:
        self._last: dict[str, tuple[bytes, Pose | None, dict[Hashable, Any]]] = {}
        self.decoded = 0  # decodes done (the rest were shared)
        self.bad = 0  # payloads that were not a pose

    def _entry(self, rid: str, raw: bytes) -> tuple[bytes, Pose | None, dict[Hashable, Any]]:
        last = self._last.get(rid)
        if last is not None and last[0] == raw:
            return last
        try:
            pose: Pose | None = decode(raw, Pose)
        except DecodeError:
            self.bad += 1
            pose = None
        self.decoded += 1
        if len(self._last) > 4096:  # robots of a world come and go; ids are bounded by the world, but be sure
            self._last.clear()
        self._last[rid] = last = (raw, pose, {})
        return last

    def pose(self, rid: str, raw: bytes) -> Pose | None:
        """``raw`` as a pose (None when it is not one: counted); the previous answer when the bytes are the same."""
        return self._entry(rid, raw)[1]

    def drawn(self, rid: str, raw: bytes, variant: Hashable, draw: Callable[[Pose | None], str]) -> str:
        """``draw(pose)`` of ``raw``'s pose, kept with it: another page holding the same bytes and drawing them the
        same way (``variant``: its owner, whether she is the page's user, whether it is selected) gets it as is."""
        return self.derived(rid, raw, variant, draw)

    def derived(self, rid: str, raw: bytes, variant: Hashable, make: Callable[[Pose | None], T]) -> T:
        """``make(pose)`` of ``raw``'s pose, kept with it for every page that holds the same bytes and asks for the
        same ``variant`` (a drawing of the map, a box's place in the 3D view): made once a tick, not once a page.
        What it returns is shared: never changed in place."""
        drawings = self._entry(rid, raw)[2]
        if variant in drawings:
            return drawings[variant]  # type: ignore[no-any-return]
        if len(drawings) > 64:  # a page's variants are few; be sure
            drawings.clear()
        out = drawings[variant] = make(self._last[rid][1])
        return out

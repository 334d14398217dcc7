"""When a shard adopts the scene objects after their sim went: a pure core.

:class:`sim_peer.replica.adoption.ObjectAdoption` tells it when a sim left (:func:`departed`) and when its wait is over
(:func:`waited`), and asks it whether this sim is the one that adopts (:func:`adopter`); it answers with values. No
zenoh, no lock, no clock.

The rules:

- a sim that serves the scene objects (or is closing) adopts nothing and starts no wait;
- a departure starts one wait of :func:`wait_s` (a standby of the objects' sim takes over well within it), or joins
  the one under way: at most one waits at a time, and no departure is lost (the wait looks once more);
- after the wait, with no departure since the last look, the wait ends;
- a look whose question went unanswered (no sim answered ``srv/world`` in time, this one included: a loaded box) is
  no answer: the wait goes on and looks again, as after a departure;
- the adopter is the lowest-id sim among those that serve a part of the world, when none of them describes scene
  objects and this world has some: every shard asks the same union, so exactly one adopts.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

__all__ = ["Watch", "departed", "waited", "unanswered", "stopped", "adopter", "wait_s"]


@dataclass(frozen=True, slots=True)
class Watch:
    """Whether a wait is under way (``running``), and whether a sim left since it last looked (``again``)."""

    running: bool = False
    again: bool = False


def wait_s(lease: float) -> float:
    """How long a shard waits after a sim left before asking whether the scene objects still have an authority:
    two leases and a second (a take-over by the objects' standby takes well under a lease)."""
    return 2.0 * lease + 1.0


def departed(w: Watch, *, serves_objects: bool) -> tuple[Watch, bool]:
    """A sim left: the new watch, and whether a wait must start now (none is under way)."""
    if serves_objects:
        return w, False
    return Watch(running=True, again=True), not w.running


def waited(w: Watch, *, serves_objects: bool) -> tuple[Watch, bool]:
    """A wait is over: the new watch, and whether to look now (True: it goes on waiting after the look; False: the
    wait ends, nobody left since the last look or this sim serves the objects now)."""
    if not w.again or serves_objects:
        return Watch(), False
    return Watch(running=True, again=False), True


def unanswered(w: Watch) -> Watch:
    """A look found no answer: the wait under way looks again after its next wait (a whole run at load: the only
    look after sim-a's SIGKILL went unanswered, the wait ended, and the scene objects had no authority for 90 s)."""
    return Watch(running=w.running, again=True)


def stopped(w: Watch) -> Watch:
    """The host is closing: the wait ends (a departure it had not looked at yet is kept)."""
    return Watch(running=False, again=w.again)


def adopter(parts: Mapping[str, bool], me: str, *, has_objects: bool) -> bool:
    """Whether ``me`` adopts the scene objects: ``parts`` maps each sim that serves a part of the world to whether it
    describes scene objects; ``has_objects``: whether this world has any."""
    return has_objects and bool(parts) and not any(parts.values()) and min(parts) == me

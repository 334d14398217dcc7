"""Which robots a page follows in full: the one she selected, and those of her panels that she owns.

Following a robot in full is its joints, pose, scan, path and IK decoded by her session at their stream rates
(a pose at 50 Hz and a scan at 20 Hz for a base). A page that followed the first arm and the first base
whatever she selected decoded two robots' streams she never looked at, in every page: the largest part of the
console server's cost per page in a class-sized world. Every robot she does not follow is drawn from the view's
pose feed (:mod:`.feed`), whose decoding the pages share.

A base followed in full is its pose and scan, not its wheels' joints (:func:`streams`): the sim publishes them at
100 Hz, and no part of the page shows them. With them, a class of 32 each following her base was 5,440 messages a
second handed to Python in the console server (170 a page), and zenoh's threads delivering them held the GIL longer
than the event loop did.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Iterable

from robots.kinds import facts
from user_peer.following import FOLLOWED_STREAMS, Following

if TYPE_CHECKING:
    from user_peer.robot import Robot
    from user_peer.world import World

__all__ = ["shown", "follow_only", "followed", "streams"]


def shown(world: World, selected: str | None, handles: dict[str, Robot], panels: Iterable[Robot | None]) -> set[str]:
    """The robots a page follows: ``selected`` (once its handle is made), and each robot of the ``panels`` (the
    arm and base whose controls are shown; None for a panel the page lacks) that ``world``'s user owns: their
    controls are hers to use, whatever she selected since."""
    out = {selected} if selected is not None and selected in handles else set()
    for r in panels:
        if r is None:
            continue
        rec = world.ownership.record(r.id)
        if rec is not None and rec.owner == world.user:
            out.add(r.id)
    return out


def follow_only(following: Following, wanted: set[str]) -> None:
    """Follow ``wanted`` and no other robot. A (un)declaration is a message queued to the router, so this may run
    on the pages' event loop; it changes only when the selection or an ownership does."""
    followed = following.robots
    for rid in followed - wanted:
        following.unfollow(rid)
    for rid in wanted - followed:
        following.robot(rid)


def followed(world: World, handles: dict[str, Robot]) -> dict[str, Robot]:
    """The ``handles`` whose robots ``world`` follows now: what the view draws from them (links, scan, path)."""
    now = world.following.robots
    return {rid: h for rid, h in handles.items() if rid in now}


def streams(kind: str) -> tuple[str, ...]:
    """The streams a page keeps of a robot of ``kind`` it follows (``World(followed=...)``): every followed stream,
    but a base's joints (its wheels: 100 a second, which neither the panels nor the views show)."""
    return tuple(s for s in FOLLOWED_STREAMS if not (s == "joints" and facts(kind).base))

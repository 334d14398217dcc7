"""Which robots a page follows in full: the one she selected, and those of her panels that she owns.

Following a robot in full is its joints, pose, scan, path and IK decoded by her session at their stream rates
(a pose at 50 Hz and a scan at 20 Hz for a base). A page that followed the first arm and the first base
whatever she selected decoded two robots' streams she never looked at, in every page: the largest part of the
console server's cost per page in a class-sized world. Every robot she does not follow is drawn from the view's
pose feed (:mod:`.feed`), whose decoding the pages share.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Iterable

from user_peer.following import Following

if TYPE_CHECKING:
    from user_peer.robot import Robot
    from user_peer.world import World

__all__ = ["shown", "follow_only", "followed"]


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

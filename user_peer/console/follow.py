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

A student's pages share her world (one session per user, :mod:`.login`): a second tab, or the tab before a reload
that lingers until its connection times out. Each page says what it shows (:func:`follow_for`) and the world
follows what any of them shows. When each page made the world follow only its own robots, two pages of hers let
go of each other's robot at every redraw: a zoom asked while the other page had just let go of her base centred on
the map's middle ("around its middle", make test in CI, 2026-12-04).
"""

from __future__ import annotations

import weakref
from typing import TYPE_CHECKING, Iterable

from robots.kinds import facts
from user_peer.following import FOLLOWED_STREAMS, Following

if TYPE_CHECKING:
    from user_peer.robot import Robot
    from user_peer.world import World

__all__ = ["shown", "follow_only", "follow_for", "forget", "followed", "streams"]

# what each page of a world shows, by its world's following (pages and followings: gone with their last reference)
_SHOWN: weakref.WeakKeyDictionary[Following, weakref.WeakKeyDictionary[object, frozenset[str]]]
_SHOWN = weakref.WeakKeyDictionary()


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


def follow_for(following: Following, page: object, wanted: set[str]) -> None:
    """``page`` shows ``wanted``: ``following`` follows what any of its pages shows, and no other robot. On the
    pages' event loop (one thread: the pages' table needs no lock)."""
    pages = _SHOWN.setdefault(following, weakref.WeakKeyDictionary())
    pages[page] = frozenset(wanted)
    follow_only(following, set().union(*pages.values()))


def forget(following: Following, page: object) -> None:
    """``page`` closed: ``following`` keeps only what its other pages show."""
    pages = _SHOWN.get(following)
    if pages is None or pages.pop(page, None) is None:
        return
    follow_only(following, set().union(*pages.values()))


def followed(world: World, handles: dict[str, Robot]) -> dict[str, Robot]:
    """The ``handles`` whose robots ``world`` follows now: what the view draws from them (links, scan, path)."""
    now = world.following.robots
    return {rid: h for rid, h in handles.items() if rid in now}


def streams(kind: str) -> tuple[str, ...]:
    """The streams a page keeps of a robot of ``kind`` it follows (``World(followed=...)``): every followed stream,
    but a base's joints (its wheels: 100 a second, which neither the panels nor the views show)."""
    return tuple(s for s in FOLLOWED_STREAMS if not (s == "joints" and facts(kind).base))

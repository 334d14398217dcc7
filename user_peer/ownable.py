"""What a robot handle offers about its ownership: who holds it, asking for it, giving it up, queueing.

The answers come from the user's ownership replica (:class:`~user_peer.ownership_link.OwnershipLink`), which
follows the robot's authority; a handle keeps nothing of its own.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from fabric.interfaces import OwnershipRecord

if TYPE_CHECKING:
    from user_peer.world import World

__all__ = ["Ownable"]


class Ownable:
    """Ownership of the robot ``id`` of ``world`` (a mixin of :class:`~user_peer.robot.Robot`)."""

    world: "World"
    id: str

    @property
    def record(self) -> OwnershipRecord | None:
        return self.world.ownership.record(self.id)

    @property
    def owner(self) -> str:
        rec = self.record
        return rec.owner if rec else ""

    @property
    def is_owner(self) -> bool:
        return self.owner == self.world.user

    @property
    def can_command(self) -> bool:
        """True when this user owns the robot, or the world runs without ownership (no record at all)."""
        rec = self.record
        return rec is None or rec.owner == self.world.user

    def request(self, *, timeout: float | None = None, wait: bool = False) -> int:
        """Ask to own the robot; returns the epoch (the fencing token the commands carry).

        Without ``wait`` a refusal raises :class:`NotOwner` with the authority's reason (in motion, owned
        by X). With ``wait`` the user takes a place in the queue and this call returns the epoch when that
        place becomes ownership, or raises :class:`Timeout` after ``timeout`` s, leaving the queue.
        """
        return self.world.ownership.request(self.id, timeout=timeout or self.world.timeout, wait=wait)

    def release(self) -> None:
        """Give the robot up (the next in its queue owns it). The sim stops it: a base brakes, an arm holds."""
        self.world.twists.drop(self.id)
        self.world.ownership.release(self.id, timeout=self.world.timeout)

    def queue(self, *, timeout: float | None = None) -> int:
        """Take a place in the robot's queue without waiting for it (a UI's "queue for it"); returns the
        place (1: next), or 0 when the robot was granted at once (free, or still). :class:`NotOwner` when
        refused (the queue is full). The place and the grant show in :attr:`record` as they come."""
        return self.world.ownership.enqueue(self.id, timeout=timeout or self.world.timeout)

    @property
    def queue_place(self) -> int | None:
        """This user's place in the robot's queue (1: next), or None when not waiting for it."""
        rec = self.record
        if rec is None or self.world.user not in rec.queue:
            return None
        return rec.queue.index(self.world.user) + 1

"""Who holds each robot, written beside it, and the event log.

A robot's label is placed once where the robot is known (an arm's base; above a base's body, so it moves with
the base) and written again when its owner, epoch or queue changes, at the time of the message that changed it.
"""

from __future__ import annotations

import numpy as np
import rerun as rr

from fabric.interfaces import Event, OwnershipRecord
from user_peer.drawing.canvas import Canvas

__all__ = ["OwnershipDrawer"]

LEVELS = {"debug": "DEBUG", "info": "INFO", "warning": "WARN", "error": "ERROR"}


class OwnershipDrawer:
    """Ownership labels, ``ownership/{id}`` documents and the ``events`` text log."""

    def __init__(self, canvas: Canvas) -> None:
        self.canvas = canvas
        self.owners: dict[str, OwnershipRecord] = {}
        self._places: dict[str, tuple[str, np.ndarray]] = {}  # robot -> (label entity, where)

    def place(self, rid: str, entity: str, at: np.ndarray) -> None:
        """Where ``rid``'s label goes (its style static), and its label drawn there now."""
        self._places[rid] = (entity, at)
        self.canvas.rec.log(entity, rr.Points3D.from_fields(radii=0.005, colors=[(0, 0, 0)]), static=True)
        self.write(rid)

    def write(self, rid: str) -> None:
        """``rid``'s label as of now: its owner and epoch, or free, and who waits."""
        where = self._places.get(rid)
        if where is None:
            return
        rec = self.owners.get(rid)
        text = f"{rid}: " + (f"{rec.owner} (epoch {rec.epoch})" if rec and rec.owner else "free")
        if rec and rec.queue:
            text += f", waiting {', '.join(rec.queue)}"
        self.canvas.send_now(where[0], rr.Points3D.columns(positions=[where[1]], labels=[text]))

    def log_ownership(self, rec: OwnershipRecord) -> bool:
        before = self.owners.get(rec.object)
        self.owners[rec.object] = rec
        if before is None or before.owner != rec.owner or before.epoch != rec.epoch or before.queue != rec.queue:
            self.write(rec.object)
        log = self.canvas.rec.log
        if before is None or before.owner != rec.owner or before.epoch != rec.epoch:
            who = rec.owner or "nobody"
            log("events", rr.TextLog(f"{rec.object}: owned by {who} (epoch {rec.epoch}, {rec.state})", level="INFO"))
        log(
            f"ownership/{rec.object}",
            rr.TextDocument(
                f"owner: {rec.owner or '-'}\nepoch: {rec.epoch}\nqueue: {', '.join(rec.queue) or '-'}\nstate: {rec.state}"
            ),
        )
        return True

    def log_event(self, where: str, ev: Event, *, any_login: bool = False) -> bool:
        """One line of the event log; ``any_login``: it came on a key any login may write (a decode report),
        so it is marked as such: its kind, user and object are the writer's say-so (docs/security.md)."""
        level = LEVELS.get(ev.severity, "INFO")
        who = f" [{ev.user}]" if ev.user else ""
        obj = f" {ev.object}:" if ev.object else ""
        mark = f"(unverified: {where}, any login may write it) " if any_login else ""
        self.canvas.rec.log("events", rr.TextLog(f"{mark}{ev.kind}{who}{obj} {ev.reason}".strip(), level=level))
        return True

"""Who owns each robot, as the navigation service needs to know it: the trusted replica of the ownership records.

A user's plan is published on her robot's ``path`` key only when she owns the robot (docs/security.md,
:mod:`.service`), so the service reads the records the sims' ownership authorities publish, through an
:class:`ownership.OwnershipClient` that reads and never renews. Its first query may wait for an authority,
so the client is made on a thread of its own, off the way of the services' start; until it is there, and
for a robot it has no record of, nobody owns the robot.
"""

from __future__ import annotations

import threading
from typing import Any

from fabric.session import Fabric

__all__ = ["OwnerWatch"]


class OwnerWatch:
    """The ownership records of one world, followed from a thread; ``close()`` is idempotent and may come first."""

    def __init__(self, fabric: Fabric) -> None:
        self.fabric = fabric
        self.client: Any = None  # the replica (ownership.OwnershipClient), once made
        self._lock = threading.Lock()
        self._closed = False
        threading.Thread(target=self._follow, name="nav-ownership", daemon=True).start()

    def _follow(self) -> None:
        from ownership import OwnershipClient

        try:
            client = OwnershipClient(
                self.fabric, self.fabric.peer_id, timeout=1.0
            )  # never started: reads, never renews
        except Exception:  # a session closing under it
            return
        with self._lock:
            closed, self.client = self._closed, client
        if closed:
            client.close()

    def owner_of(self, robot: str) -> str | None:
        """``robot``'s owner as the authority last said (None: free, or not known yet)."""
        client = self.client
        rec = client.record(robot) if client is not None else None
        return rec.owner if rec is not None and rec.owner else None

    def close(self) -> None:
        """Stop following (a client made after this is closed as soon as it is there)."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            client = self.client
        if client is not None:
            client.close()

"""A sim's role, published: the liveliness token ``peer/sim/{id}/{role}/{term}/{leader}`` (:func:`fabric.keys.sim_role`).

Tests, the soak and tools learn from it whether a sim serves its shard or follows, under which term and whom,
instead of matching its log lines (which stay, for people, and are no interface). A token goes with its session,
so a sim killed, cut off or paused past the lease shows no role at all, as it shows no ``peer/sim/{id}`` token.

What is shown is a pure function of the election, whether the world is served yet and whether the standby holds
a state (:func:`shown`): a primary shows once it serves (a take-over's restore comes first), a standby once it
knows its leader and holds a state (its leader's first snapshot, or its own last one as a primary that stepped
down). Before that, a standby that took over would start the world from its scene: a test or an operator that
waits for "standby" and then kills the primary meets a standby that can carry the world on (one killed 1-3 s after
the role showed once took over "with no state seen"). Nothing decides on these tokens: the election reads the sims' own tokens and the terms it hears.
"""

from __future__ import annotations

import logging
import threading
from typing import TYPE_CHECKING

from fabric import keys
from sim_peer.replica import election as el

if TYPE_CHECKING:
    import zenoh

    from fabric.session import Fabric

log = logging.getLogger("robofabric.sim")

__all__ = ["RoleToken", "shown"]


def shown(election: el.Election, serving: bool, holds: bool = True) -> tuple[str, int, str] | None:
    """(role, term, leader) a sim shows now, or None: a primary not serving yet (a take-over restoring the world)
    and a standby that follows nobody yet, or holds no state yet (``holds``), show nothing."""
    if election.role == el.PRIMARY:
        return (el.PRIMARY, election.term, election.me) if serving else None
    return (el.STANDBY, election.term, election.leader) if election.leader and holds else None


class RoleToken:
    """The one role token of one sim session: :meth:`show` declares the new one before it undeclares the old one
    (a watcher never sees the sim with no role between two), and does nothing when nothing changed."""

    def __init__(self, fabric: Fabric) -> None:
        self._fabric = fabric
        self._lock = threading.Lock()
        self._shown: tuple[str, int, str] | None = None
        self._token: zenoh.LivelinessToken | None = None
        self._closed = False

    @property
    def role(self) -> tuple[str, int, str] | None:
        """What is shown now: (role, term, leader), or None."""
        return self._shown

    def show(self, election: el.Election, serving: bool, holds: bool = True) -> None:
        """Show what :func:`shown` says for ``election``; a closed session or a closed token shows nothing more."""
        want = shown(election, serving, holds)
        with self._lock:
            if self._closed or want is None or want == self._shown:
                return
            f = self._fabric
            try:
                token = f.session.liveliness().declare_token(keys.sim_role(f.world, f.peer_id, *want))
            except Exception:  # a closing session: its tokens go with it
                log.debug("role token not declared", exc_info=True)
                return
            old, self._token, self._shown = self._token, token, want
        _undeclare(old)

    def close(self) -> None:
        """Undeclare the token; idempotent (the session's close takes it too)."""
        with self._lock:
            self._closed = True
            old, self._token, self._shown = self._token, None, None
        _undeclare(old)


def _undeclare(token: zenoh.LivelinessToken | None) -> None:
    if token is None:
        return
    try:
        token.undeclare()
    except Exception:  # already gone with a closing session
        pass

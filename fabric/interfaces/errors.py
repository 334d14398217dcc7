"""The errors that cross peers: a service call that was refused or that nobody answered, and a payload
that is not a message.

A service handler refuses a request by raising :class:`ServiceError` (or ``ValueError``); the session
sends the reason back as an error reply (an :class:`~fabric.interfaces.events.Event`), and the caller's
:meth:`fabric.rpc.Rpc.query` raises :class:`Refused` with the same reason. When no replier
answers at all the caller gets :class:`NoReply`. Both are :class:`ServiceError`, so code that does not
care which catches that. :class:`~fabric.codec.DecodeError` (what arrived is not a valid message) is
the codec's and is re-exported here.

The user API's own errors (``user_peer.NotOwner``, ``Unreachable``, ``Timeout``) are the words a
script sees; they are raised in the user's process from these and do not travel.
"""

from __future__ import annotations

from fabric.codec import DecodeError

__all__ = ["DecodeError", "NoReply", "Refused", "ServiceError"]


class ServiceError(RuntimeError):
    """A service refused a request, or nobody answered; ``reason`` says which and why, ``key`` where."""

    def __init__(self, reason: str, *, key: str = "") -> None:
        super().__init__(reason)
        self.reason = reason
        self.key = key


class Refused(ServiceError):
    """A service answered the request with a refusal; ``reason`` is the server's."""


class NoReply(ServiceError):
    """Nobody answered the query: nobody serves the key (``nobody``: zenoh found no server to ask), or no server
    answered in time. Told by ``nobody``, not by how long it took: a query that finds nobody may still be asked
    again for a moment (a session just opened, a link just back: :mod:`fabric.rpc`)."""

    def __init__(self, reason: str, *, key: str = "", nobody: bool = False) -> None:
        super().__init__(reason, key=key)
        self.nobody = nobody

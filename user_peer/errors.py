"""The errors a user script sees: each says why, in words a student can act on."""

from __future__ import annotations

__all__ = ["FabricUserError", "NotOwner", "Unreachable", "JoinFailed", "Timeout"]


class FabricUserError(RuntimeError):
    """Base of the user API's errors; ``reason`` holds the explanation."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


class NotOwner(FabricUserError):
    """A command or request was refused because someone else owns the robot (or the epoch is stale)."""


class Unreachable(FabricUserError):
    """A target cannot be reached: outside the workspace or limits, no IK solution, no path, no service."""


class JoinFailed(Unreachable):
    """The world could not be joined (what ``user_peer.connect()`` raises when no session opens): ``endpoint``
    is where it tried, ``cause`` why (nobody listens there, the router refused this login, the router's TLS
    certificate does not name the host this client asked for...); the message says both in one line."""

    def __init__(self, reason: str, *, endpoint: str = "", cause: str = "") -> None:
        super().__init__(reason)
        self.endpoint = endpoint
        self.cause = cause or reason


class Timeout(FabricUserError):
    """Something did not happen in time: a motion did not finish, a peer did not answer."""

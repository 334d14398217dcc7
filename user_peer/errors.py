"""The errors a user script sees: each says why, in words a student can act on."""

from __future__ import annotations

__all__ = ["FabricUserError", "NotOwner", "Rejected", "Paused", "Unreachable", "JoinFailed", "Timeout"]


class FabricUserError(RuntimeError):
    """Base of the user API's errors; ``reason`` holds the explanation."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


class NotOwner(FabricUserError):
    """A command or request was refused because someone else owns the robot (or the epoch is stale)."""


class Rejected(FabricUserError):
    """The sim refused a command for what it said, not for who sent it: a path in the wrong frame, a body
    that does not fit the command, a robot the sim does not have. ``robot`` and ``command`` name what was
    refused, ``code`` the sim's word for why (``bad_frame``, ``wrong_body``...); ``reason`` says it in full.
    Ownership refusals are :class:`NotOwner`."""

    def __init__(self, reason: str, *, robot: str = "", command: str = "", code: str = "") -> None:
        super().__init__(f"{robot} refused the {command or 'command'}: {reason}" if robot else reason)
        self.reason = reason
        self.robot = robot
        self.command = command
        self.code = code


class Paused(Rejected):
    """The sim held its robots when the command came (code ``held``): it was cut off from its world, or frozen and
    not yet sure of its link, and took no command meanwhile. A pause, not a refusal of what was asked: a command
    given with ``wait=True`` rides it out (sent again, the same command under the same epoch, once the sim hears
    again, within its timeout); a caller without ``wait`` sees this error from the next call that checks the
    robot's refusals (:meth:`user_peer.mobile_base.Base.drive`, a waited command) and may send again."""


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

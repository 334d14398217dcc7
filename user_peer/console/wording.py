"""A refusal in plain words, with what to do next: the page's message line says this, not the code's words.

``NotOwner: arm1 not granted to bob: denied: in motion, owned by alice`` told a student what the program
thought; ``arm1 is moving and belongs to alice: wait until it stops, or press Queue to be next`` tells her what
to do. The authority's own words follow in brackets, for the teacher. Pure: the error, the robot, its owner
and who asks.
"""

from __future__ import annotations

from fabric.text import one_line
from user_peer.errors import FabricUserError, NotOwner, Rejected, Timeout, Unreachable

__all__ = ["plain"]


def _next_step(exc: FabricUserError, robot: str, owner: str, me: str) -> str:
    reason = exc.reason
    if isinstance(exc, NotOwner):
        if "in motion" in reason:
            return f"{robot} is moving and belongs to {owner or 'someone else'}: wait until it stops, or press Queue to be next"
        if owner and owner != me:
            return f"{robot} belongs to {owner}: press Queue to be next, or ask {owner} to release it"
        return f"you do not own {robot}: press Request first"
    if isinstance(exc, Rejected):
        return f"{robot} refused it: {reason}"
    if isinstance(exc, Timeout):
        return "no answer in time (the world is busy, or its peer is gone): try again in a moment"
    if isinstance(exc, Unreachable):
        return f"out of reach: {reason}. Move the target or the goal and try again"
    if "forbidden character" in reason:
        return "a name may not hold a space or any of / * $ # ?: choose another"
    return reason


def plain(exc: FabricUserError, *, robot: str, owner: str, me: str) -> str:
    """What the page says for a refusal of an action on ``robot`` (owned by ``owner``, asked by ``me``): the next
    step in plain words, then the code's reason in brackets. One line."""
    step = _next_step(exc, robot or "the robot", owner, me)
    return one_line(f"{step} [{type(exc).__name__}: {exc.reason}]", 400)

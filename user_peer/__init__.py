"""User peers: the Python API for scripts and notebooks, the terminal UI, the Rerun viewer, the paper's scenarios.

``user_peer.connect(world=..., connect=[...], user=...)`` returns a :class:`World`;
``robofabric view``, ``export``, ``user`` and ``scenario`` are the commands.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from user_peer.errors import FabricUserError, JoinFailed, NotOwner, Paused, Rejected, Timeout, Unreachable

if TYPE_CHECKING:
    from user_peer.api import Arm, Base, Robot, SceneObject, World, connect
    from user_peer.streams import Sample, StreamIterator, Subscription

__all__ = [
    "connect",
    "World",
    "Robot",
    "Arm",
    "Base",
    "SceneObject",
    "FabricUserError",
    "NotOwner",
    "Rejected",
    "Paused",
    "Timeout",
    "Unreachable",
    "JoinFailed",
    "Sample",
    "StreamIterator",
    "Subscription",
]


def __getattr__(name: str) -> Any:
    """The API loads on first use of its names: ``robofabric --help`` imports :mod:`user_peer.cli`, and with it this
    package, and must not pay for the session and numpy a world needs."""
    if name in ("connect", "World", "Robot", "Arm", "Base", "SceneObject"):
        from user_peer import api

        return getattr(api, name)
    if name in ("Sample", "StreamIterator", "Subscription"):
        from user_peer import streams

        return getattr(streams, name)
    raise AttributeError(f"module 'user_peer' has no attribute {name!r}")

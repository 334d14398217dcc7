"""User peers: the Python API for scripts and notebooks, the terminal UI, the Rerun viewer, the paper's scenarios.

``user_peer.connect(world=..., connect=[...], user=...)`` returns a :class:`World`;
``robofabric view``, ``export``, ``user`` and ``scenario`` are the commands.
"""

from user_peer.api import Arm, Base, Robot, SceneObject, World, connect
from user_peer.errors import FabricUserError, JoinFailed, NotOwner, Timeout, Unreachable
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
    "Timeout",
    "Unreachable",
    "JoinFailed",
    "Sample",
    "StreamIterator",
    "Subscription",
]

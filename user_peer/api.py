"""The Python API for users: a world, its robots and scene objects, as plain objects and blocking calls.

The replacement for the paper's MATLAB scripts::

    import user_peer
    with user_peer.connect(world="demo", user="alice") as world:
        arm = world.robot("arm1")
        arm.request()
        arm.move_to([3.15, 0.0, 1.0])      # IK by a compute peer, then the joints
        print(arm.joints)

A :class:`World` is one user peer: one Zenoh session with a liveliness token
``rf/{world}/peer/user/{user}`` (ownership leases rely on it), replicas of the
latest joints, pose, scan, path and ownership record of every robot it has
been asked about, and the services of compute peers. Blocking calls wait on
those replicas with deadlines and raise :class:`NotOwner`, :class:`Rejected`,
:class:`Unreachable` or :class:`Timeout` with a reason; nothing blocks forever.
Works the same in a script and in Jupyter (no event loop of its own: Zenoh's
threads feed it).

The rooms: :mod:`user_peer.world` (the session and the handles), behind it
:mod:`user_peer.description` (what the sims describe), :mod:`user_peer.presence`
(the sims alive, failovers), :mod:`user_peer.event_log` (the events, and which may
refuse a command), :mod:`user_peer.following` (which streams are decoded) and
:mod:`user_peer.compute_route` (which compute peer is asked);
:mod:`user_peer.latest` (the cache), :mod:`user_peer.robot` (what every robot handle
offers, its ownership included; :mod:`user_peer.arm` and
:mod:`user_peer.mobile_base`, a class per kind), :mod:`user_peer.scene_object`,
:mod:`user_peer.errors`. This module joins them: :func:`connect`, and the public
names in one place.
"""

from __future__ import annotations

from typing import Iterable

from fabric.config import FabricConfig
from user_peer.errors import JoinFailed, NotOwner, Rejected, Timeout, Unreachable
from user_peer.arm import Arm
from user_peer.mobile_base import Base
from user_peer.robot import Robot
from user_peer.scene_object import SceneObject
from user_peer.world import World

__all__ = [
    "connect",
    "World",
    "Robot",
    "Arm",
    "Base",
    "SceneObject",
    "NotOwner",
    "Rejected",
    "Timeout",
    "Unreachable",
    "JoinFailed",
]


def connect(
    world: str | None = None,
    connect: Iterable[str] | str | None = None,
    user: str | None = None,
    *,
    profile: str | None = None,
    zenoh_config: str | None = None,
    timeout: float = 5.0,
    compute: str | None = None,
    wait: bool = True,
    join_timeout: float | None = None,
) -> World:
    """Join a world as ``user`` (default: $USER). ``connect``: router endpoints, e.g. ``["tcp/10.0.0.5:7447"]``
    (default ``$ROBOFABRIC_CONNECT``); ``world`` defaults to ``$ROBOFABRIC_WORLD`` or ``demo``.

    With ``wait`` (the default) it returns once a sim peer serves the world's description, waiting up
    to ``join_timeout`` seconds (default 30, at least ``timeout``) for one to start; :class:`Timeout`
    otherwise, saying how long it waited. ``timeout`` is the default for service calls afterwards.

    ``compute``: the peer id of the compute peer to use (``robofabric ps`` lists them), e.g. one running on
    this machine; ``"spread"`` sends IK queries to every live compute peer in turn; by default queries go
    to the nearest compute peer serving the world.

    A world that cannot be joined raises :class:`~user_peer.errors.JoinFailed` (an ``Unreachable``) with
    ``endpoint`` and ``cause``: nobody listens there, the router refused this login, or this client refused
    the router's TLS certificate (one that does not name the host asked for, or from another class's CA).

    The world closes itself when the interpreter exits (its robots are released first), so a script
    may end without ``close()``; ``with user_peer.connect(...) as world:`` closes it sooner.
    """
    import getpass

    if isinstance(connect, str):
        connect = [connect]
    cfg = FabricConfig.resolve(world=world, profile=profile, connect=list(connect or ()), config_file=zenoh_config)
    # with a secure zenoh config the user id is the login (a different ``user`` is a ConfigError)
    uid = cfg.user_id(user) or "".join(c if c.isalnum() or c in "-_" else "-" for c in getpass.getuser()) or "user"
    try:
        w = World(cfg, uid, timeout=timeout, compute=compute, join_timeout=join_timeout)
    except JoinFailed as exc:  # raised here: a script's traceback ends at its own connect() call
        raise JoinFailed(exc.reason, endpoint=exc.endpoint, cause=exc.cause) from None
    if wait:
        try:
            w.info()
        except BaseException:
            w.close()
            raise
    return w

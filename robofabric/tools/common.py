"""What the fabric's own commands share: joining the world a command names, and reading the key it was given."""

from __future__ import annotations

from typing import TYPE_CHECKING

from fabric import keys
from fabric.cli_common import Joining, UserError

if TYPE_CHECKING:
    from fabric.session import Fabric

__all__ = ["open_world", "resolve_key", "user_key"]


def open_world(kind: str, join: Joining, *, key: str | None = None) -> Fabric:
    """Join the world the flags name; a key given is checked first, so a typo fails before any network wait."""
    cfg = join.config()
    if key is not None:
        resolve_key(key, cfg.world)
    return join.open(kind, cfg)


def resolve_key(key: str, world: str) -> str:
    """Accept full keys (``rf/demo/robot/arm1/joints``) or world-relative ones (``robot/arm1/joints``)."""
    try:
        return keys.in_world(key, world)
    except ValueError as exc:
        raise UserError(str(exc)) from None


def user_key(full: str, user: str | None) -> str:
    """``robot/arm1/cmd/joints`` with ``--user alice`` is alice's command key ``.../cmd/joints/by/alice``
    (the sim takes the sender from the key); a key that already names its writer is kept."""
    parts = full.split("/")
    if user and len(parts) == 6 and parts[2] == "robot" and parts[4] == "cmd":
        try:
            return keys.robot_cmd(parts[1], parts[3], parts[5], user)
        except ValueError as exc:
            raise UserError(str(exc)) from None
    if user and len(parts) == 5 and parts[2] == "object" and parts[4] == "pose":
        return keys.object_pose(parts[1], parts[3], user)
    return full

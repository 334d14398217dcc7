"""The compute peer: kinematics and navigation services on one fabric session.

What MATLAB did for the paper's Unity clients, for a whole classroom from one
machine, or for one user locally: :class:`ComputePeer` hosts a
:class:`~compute_peer.kinematics.service.KinematicsService` (``srv/ik``, ``srv/fk``,
``srv/jacobian``, IK streaming) and a
:class:`~compute_peer.navigation.service.NavigationService` (``srv/map``,
``srv/plan``, mapping from scans) and reports what they did when it stops.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable

from fabric.session import Fabric

log = logging.getLogger("robofabric.compute")

__all__ = ["ComputeOptions", "ComputePeer"]


@dataclass(frozen=True, slots=True)
class ComputeOptions:
    """What to serve: kinematics and/or navigation, IK streams, the map folder and default planner settings."""

    kinematics: bool = True
    navigation: bool = True
    streams: tuple[tuple[str, str], ...] = ()
    stream_rate: float = 20.0
    maps_dir: Path | None = None
    mapping: bool = True
    navigation_options: dict[str, Any] = field(default_factory=dict)
    arms: dict[str, Any] = field(default_factory=dict)  # robot id -> ArmPlacement, for worlds without a sim to ask


class ComputePeer:
    """The services of one compute peer on ``fabric``; a context manager.

    Constructing one declares the services (they answer queries at once); ``start()`` (or ``with``, or
    ``discover()``) starts what runs on threads of its own: IK streaming and background world lookups."""

    def __init__(self, fabric: Fabric, options: ComputeOptions | None = None) -> None:
        self.fabric = fabric
        self.options = options or ComputeOptions()
        self.kinematics = None
        self.navigation = None
        o = self.options
        if o.kinematics:
            from compute_peer.kinematics.service import KinematicsService

            self.kinematics = KinematicsService(fabric, arms=o.arms, streams=o.streams, stream_rate=o.stream_rate)
        if o.navigation:
            from compute_peer.navigation.service import NavigationService

            self.navigation = NavigationService(fabric, maps_dir=o.maps_dir, mapping=o.mapping, **o.navigation_options)

    def start(self) -> "ComputePeer":
        """Start the services' threads (once; a second call does nothing)."""
        if self.kinematics is not None:
            self.kinematics.start()
        return self

    def discover(self, timeout: float = 2.0) -> list[str]:
        """Start the peer if it is not yet, and look the world's arms up now (the services also do it
        lazily); returns the arms served."""
        self.start()
        if self.kinematics is None:
            return []
        self.kinematics.discover(timeout=timeout)
        return self.kinematics.arms

    def run(self, stop: threading.Event, duration: float | None = None) -> None:
        """Serve until ``stop`` is set or ``duration`` seconds have passed (the services run on Zenoh's threads)."""
        stop.wait(duration)

    def counters(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for svc in (self.kinematics, self.navigation):
            if svc is not None:
                out.update(svc.counters)
        return out

    def close(self) -> None:
        for svc in (self.kinematics, self.navigation):
            if svc is not None:
                svc.close()

    def __enter__(self) -> "ComputePeer":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()


def parse_streams(specs: Iterable[str]) -> tuple[tuple[str, str], ...]:
    """``ROBOT:OBJECT`` pairs (``arm1:target``); ``ValueError`` naming the bad one."""
    from fabric import keys

    out = []
    for spec in specs:
        robot, sep, obj = spec.partition(":")
        if not sep or not robot or not obj:
            raise ValueError(f"--stream {spec!r}: expected ROBOT:OBJECT, e.g. arm1:target")
        out.append((keys.validate_id(robot, what="robot id"), keys.validate_id(obj, what="object id")))
    return tuple(out)


def parse_arms(specs: Iterable[str]) -> dict[str, Any]:
    """``ID:TYPE[@X,Y,Z[,YAW_DEG]]`` into arm placements; ``ValueError`` naming the bad spec or robot type."""
    import math

    import robots
    from robots.kinds import robot_kind
    from compute_peer.kinematics.service import ArmPlacement
    from fabric import keys

    out: dict[str, Any] = {}
    for spec in specs:
        head, _, where = spec.partition("@")
        rid, sep, rtype = head.partition(":")
        if not sep or not rid or not rtype:
            raise ValueError(f"--arm {spec!r}: expected ID:TYPE[@X,Y,Z[,YAW_DEG]], e.g. arm1:meca500@3,0,0.75")
        keys.validate_id(rid, what="robot id")
        try:
            desc = robots.load(rtype)
        except Exception as exc:
            raise ValueError(f"--arm {spec!r}: {exc}") from None
        if not robot_kind(desc.kind).chain:
            raise ValueError(f"--arm {spec!r}: {rtype} is a {desc.kind} robot, not an arm")
        pose = [0.0, 0.0, 0.0, 0.0]
        if where:
            try:
                vals = [float(v) for v in where.split(",")]
            except ValueError:
                raise ValueError(f"--arm {spec!r}: the placement must be numbers X,Y,Z[,YAW_DEG]") from None
            if not 3 <= len(vals) <= 4 or not all(math.isfinite(v) for v in vals):
                raise ValueError(f"--arm {spec!r}: the placement must be 3 or 4 finite numbers X,Y,Z[,YAW_DEG]")
            pose[: len(vals)] = vals
            pose[3] = math.radians(pose[3])
        out[rid] = ArmPlacement(rtype, tuple(pose))
    return out

"""What a robot type plugs into the sim: hooks with empty defaults, in the spirit of dm_control's composer.

A robot type is a :class:`SimRobot` subclass found from its description (:mod:`sim_peer.physics.registry`). The world
calls its hooks; the peer loops over them and never asks what kind of robot it holds:

* ``describe()`` - what the robot is, as the :class:`RobotInfo` the world description carries;
* ``initialize(physics)`` - back to the spawn state at once (a world reset);
* ``before_step(physics)`` - advance the controllers by one timestep (commands take effect here);
* ``after_step(physics)`` - write the robot's kinematic state into MuJoCo, run its sensors' checks;
* ``streams()`` - what it publishes: :class:`Stream` (key leaf, rate group, a reader);
* ``commands()`` - the command kinds it takes, each a function of the command's body.

Sensors (:mod:`sim_peer.sensors`, :mod:`sim_peer.bumper`) have the same hooks; a robot passes
``after_step`` and ``streams`` on to the sensors it holds. Hook names are listed in :data:`HOOKS`: a class
that defines a public method with a hook-like name (``before_step_`` typos, ``after_substep``) is refused
by :func:`check_hooks`, so a misspelt hook fails when the type is loaded instead of never being called.

No Zenoh here: a stream's reader returns a function that builds the message once the peer has a header.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import mujoco
import numpy as np

from fabric.interfaces import COMMAND_BODIES, RobotInfo, RobotState, Stop, quaternion_from_yaw
from robots import RobotDescription
from sim_peer.controllers import Clamp, CommandRejected

HOOKS = ("describe", "initialize", "before_step", "after_step", "streams", "commands")
_HOOKISH = ("describe", "initialize", "before_", "after_", "stream", "command")

Build = Callable[[Any], Any]
"""Builds a message from a ``fabric.interfaces.Header`` (called outside the world's lock)."""

CommandHandler = Callable[[Any], "Clamp | None"]
"""Applies a command's body (``JointTarget``, ``Twist`` ...); returns a :class:`Clamp` when it clipped
something, raises :class:`CommandRejected` when it takes none of it."""


class Physics:
    """What hooks see of a world: MuJoCo's model and data, the timestep, whether MuJoCo integrates the world
    (``dynamic``: free bodies beside the kinematic robots), the steps taken since the start, and whether the
    world is stepping (``after_step`` is also called to write robots' state after a reset or a restore,
    when a sensor's checks must not run)."""

    __slots__ = ("model", "data", "dt", "dynamic", "steps", "stepping")

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, dt: float, dynamic: bool) -> None:
        self.model = model
        self.data = data
        self.dt = dt
        self.dynamic = dynamic
        self.steps = 0
        self.stepping = False

    @property
    def time(self) -> float:
        return float(self.data.time)


@dataclass(frozen=True, slots=True)
class Mount:
    """Where a robot was put: its id, description, the compiled model (its names carry the prefix ``{id}/``),
    its spawn pose (x, y, z, yaw), the world's noise generator, the world's options, the sink for its notes, and
    the board its bases' way guards share (:class:`sim_peer.physics.traffic.Traffic`; None: a board of its own)."""

    id: str
    desc: RobotDescription
    model: mujoco.MjModel
    pose: tuple[float, float, float, float]
    rng: np.random.Generator
    report: Callable[[str, "Note"], None]
    twist_timeout: float | None = None
    bumper: bool = True
    traffic: Any = None

    @property
    def prefix(self) -> str:
        return f"{self.id}/"


@dataclass(frozen=True, slots=True)
class Note:
    """Something a robot or sensor wants said as an event (``Event(kind, reason, severity, data)``):
    a path followed to its end, a twist that timed out, a bumper stop. ``counter``: the peer counter it bumps."""

    kind: str
    reason: str
    severity: str = "info"
    data: dict = field(default_factory=dict)
    counter: str = ""


@dataclass(frozen=True, slots=True)
class Stream:
    """A stream a robot publishes on ``robot/{id}/{name}`` (a name :mod:`fabric.keys` knows), in the peer's
    rate loop ``rate`` (``joints``, ``pose``, ``scan``; a new group runs at ``hz``).

    ``read(physics)`` runs under the world's lock and returns a :data:`Build` (or ``None``: nothing now);
    ``positions``: the reader needs body and site positions, so the world is brought up to date first."""

    name: str
    rate: str
    read: Callable[[Physics], Build | None]
    positions: bool = False
    hz: float = 10.0


class SimRobot:
    """The base of every robot type: empty hooks, the common identity, and the surface tests and tools use.

    ``kind`` is what other peers make of the robot (``arm``: joints and a flange; ``mobile``: a base pose
    and range sensors), carried in its :class:`RobotInfo`; the sim itself never looks at it. Named for the
    side it lives on, like :class:`~sim_peer.physics.world.SimWorld`: ``user_peer.robot.Robot`` is a user's handle on a
    robot of the world.
    """

    kind: ClassVar[str] = ""

    def __init__(self, mount: Mount) -> None:
        self.id = mount.id
        self.desc = mount.desc
        self.model = mount.model
        self.prefix = mount.prefix
        self.mount = mount
        self.body_id = mount.model.body(mount.prefix + mount.desc.root_body).id

    @staticmethod
    def frame(pose: tuple[float, float, float, float]) -> tuple[list[float], list[float]]:
        """Position and quaternion of the frame the robot's MJCF is attached at, from its spawn pose."""
        x, y, z, yaw = pose
        return [x, y, z], quaternion_from_yaw(yaw).tolist()

    # hooks ---------------------------------------------------------------------
    def describe(self) -> RobotInfo:
        d = self.desc
        return RobotInfo(
            id=self.id,
            type=d.name,
            kind=d.kind,
            pose=np.array(self.mount.pose),
            joint_names=d.joint_names,
            lower=np.array(d.lower),
            upper=np.array(d.upper),
            max_speed=np.array(d.max_speed),
            flange_site=d.flange_site,
            flange_frame=d.flange_frame,
            base_radius=d.base_radius,
        )

    def initialize(self, physics: Physics) -> None:
        """Back to the spawn state at once."""

    def before_step(self, physics: Physics) -> None:
        """Advance the controllers by ``physics.dt``."""

    def after_step(self, physics: Physics) -> None:
        """Write the kinematic state into ``physics.data``; run sensor checks."""

    def streams(self) -> tuple[Stream, ...]:
        return ()

    def commands(self) -> Mapping[str, CommandHandler]:
        return {}

    # state ---------------------------------------------------------------------
    @property
    def moving(self) -> bool:
        return False

    @property
    def underway(self) -> bool:
        """Whether a command is still being carried out: moving, or (a type that says so) aiming at what it has not
        reached yet, though it has not stepped since it took the command (a hold then stopped it before it was done)."""
        return self.moving

    @property
    def kinematic_dofs(self) -> int:
        """How many of the model's degrees of freedom this robot writes itself (the world steps the rest)."""
        return 0

    def state(self, physics: Physics) -> dict[str, Any]:
        """The last known state as a small dict of plain values (the ownership record's ``state``)."""
        return {"type": self.desc.name, "kind": self.desc.kind, "moving": self.moving}

    # a standby's take-over (sim_peer/physics/capture.py, docs/sim.md) -------------------
    def snapshot(self) -> RobotState | None:
        """The controllers' whole state, for a standby to carry the robot on; None: not carried over."""
        return None

    def restore(self, state: RobotState) -> None:
        """Put the controllers back into ``state`` (a snapshot of the same type); ValueError if it does not fit."""

    def overlay(self, stream: str, message: Any) -> None:
        """Where the robot was by its own stream (``joints``, ``pose``), newer than the last snapshot."""

    def halt(self) -> None:
        """Stop because the robot lost its owner (a robot moves only while a live owner drives it): the
        default is the robot's own ``stop`` command; a type that can stop more gently (a base braking within
        its limits) says so here. Called under the world's lock by the sim peer."""
        handler = self.commands().get("stop")
        if handler is not None:
            handler(Stop())

    def note(self, note: Note) -> None:
        """Say something as an event (the peer publishes it after the step)."""
        self.mount.report(self.id, note)

    def unsupported(self, what: str) -> CommandRejected:
        return CommandRejected("unsupported", f"robot {self.id} ({self.desc.name}) does not {what}")


def body_mismatch(name: str, body: Any) -> str | None:
    """Why ``body`` cannot be the body of a ``cmd/{name}`` (the protocol's body type for the key), or None."""
    want = COMMAND_BODIES.get(name)
    if want is not None and isinstance(body, want):
        return None
    return f"cmd/{name} carries {getattr(want, '__name__', '?')}, got {type(body).__name__}"


def check_hooks(cls: type) -> type:
    """Refuse a robot or sensor class whose public methods look like hooks but are not one of :data:`HOOKS`."""
    for name in vars(cls):
        if name.startswith("_") or name in HOOKS:
            continue
        if any(name.startswith(p) for p in _HOOKISH) and callable(getattr(cls, name)):
            raise TypeError(f"{cls.__qualname__}.{name} looks like a hook but is not one of {', '.join(HOOKS)}")
    return cls


__all__ = [
    "Build",
    "CommandHandler",
    "HOOKS",
    "Mount",
    "Note",
    "Physics",
    "SimRobot",
    "Stream",
    "body_mismatch",
    "check_hooks",
]

"""The seam between a simulating peer and whoever decides who may command its robots.

The sim peer is the authority for its robots (docs/design.md): every command it
receives passes through a :class:`CommandGate` before it touches the
simulation, and the sim peer reports each robot's motion so the gate can refuse
a takeover while the robot moves; the gate in turn tells the sim when a robot loses its owner
(:meth:`CommandGate.watch_stops`), and the sim stops it. ``ownership`` provides the real gate;
:class:`OpenGate` admits everything, for worlds run without ownership.
"""

from __future__ import annotations

from typing import Any, Callable, Protocol

from fabric.interfaces import Command


class CommandGate(Protocol):
    def admit(self, robot: str, command: Command) -> str | None:
        """None to let the command through, else the reason it is refused (sent back as an event)."""

    def update_motion(self, robot: str, moving: bool) -> None:
        """The authority's latest view of whether ``robot`` is in motion."""

    def watch_stops(self, callback: Callable[[str, str, str], None]) -> None:
        """Have ``callback(robot, former_owner, reason)`` called whenever a robot loses its owner (released,
        handed over, taken over, her lease ended, she left): the sim stops the robot (a robot moves only while
        a live owner drives it). Called before any command of the new owner is admitted."""

    def export_state(self) -> tuple[tuple[Any, ...], dict[str, Any]]:
        """What a standby needs to carry the gate over at a take-over (``ownership``: records and users)."""

    def close(self) -> None: ...


class OpenGate:
    """Admits every well-formed command: no ownership."""

    def admit(self, robot: str, command: Command) -> str | None:
        return None

    def update_motion(self, robot: str, moving: bool) -> None:
        pass

    def watch_stops(self, callback: Callable[[str, str, str], None]) -> None:
        pass  # nobody owns a robot: nobody lets go of one

    def export_state(self) -> tuple[tuple[Any, ...], dict[str, Any]]:
        return (), {}

    def close(self) -> None:
        pass

"""What a page calls on a robot panel (:class:`Panel`), and the empty hooks a simple panel inherits
(:class:`PanelHooks`).

The page holds its panels in :class:`~.panels.Panels`, made from the one list :data:`~.panels.PANELS`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from nicegui.events import GenericEventArguments

    from user_peer.robot import Robot

__all__ = ["Panel", "PanelHooks"]


class Panel(Protocol):
    """What a page calls on a panel. Every call is on the pages' event loop: none may block (a user-API call
    goes through ``await page.call(...)``, off the loop)."""

    def build(self) -> None:
        """Its NiceGUI elements, once, inside its column of the page."""

    def refresh(self) -> None:
        """Its elements from what the page's world holds now: on the console's 5 Hz clock, and after an action."""

    async def switch(self, robot: Robot) -> None:
        """The page's robot of this panel's kind becomes ``robot`` (she selected it): called before the change."""

    async def let_go(self) -> None:
        """Hold nothing: the page lost focus or its connection, or she releases the robot (a held key's release
        may never come)."""

    async def key(self, e: GenericEventArguments) -> None:
        """A key pressed or let go on the page (``e.args``: ``key``, ``down``, ``t``), outside any field."""

    async def tick(self) -> None:
        """Every ``drive.REFRESH_S`` (10 Hz): what must be sent again while a key is held (a deadman's twist)."""

    def end(self) -> None:
        """The page closed: stop what it drives, at once and without the network."""


class PanelHooks:
    """Empty :class:`Panel` hooks that a panel without keys, ticks or a held state inherits: it writes only
    ``build`` and ``refresh``."""

    async def switch(self, robot: Robot) -> None:
        """Nothing to do when another robot of its kind is shown."""

    async def let_go(self) -> None:
        """Nothing held."""

    async def key(self, e: GenericEventArguments) -> None:
        """Keys are not its."""

    async def tick(self) -> None:
        """Nothing sent again."""

    def end(self) -> None:
        """Nothing to stop."""

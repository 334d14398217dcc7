"""A page's robot panels: the one list of them (:data:`PANELS`), and a page's own (:class:`Panels`).

A panel is the controls of one robot kind: the arm's sliders and IK (:mod:`.arm_panel`), the base's keys, map
and plans (:mod:`.base_panel`). A page makes one panel for each entry of :data:`PANELS` whose kind it has a robot
of, places it beside the entry's view (:mod:`.layout`) and calls it only through :class:`~.panel.Panel`, by
way of :class:`Panels`; nothing else of the page names a panel. A new panel is one module (a class that meets
:class:`~.panel.Panel`, a ``make`` function) and one entry here (docs/howto.md, "A new console panel").
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable, Iterator

from user_peer.console import arm_panel, base_panel
from user_peer.console.panel import Panel

if TYPE_CHECKING:
    from nicegui.events import GenericEventArguments

    from fabric.interfaces import WorldInfo
    from user_peer.console.page import ConsolePage
    from user_peer.robot import Robot

__all__ = ["PanelEntry", "PANELS", "VIEWS", "Panels"]

VIEWS = ("3d", "map")
"""The page's views a panel sits beside, in the page's order: the 3D view (:mod:`.view3d`), the top-down map
(:mod:`.view`)."""


@dataclass(frozen=True, slots=True)
class PanelEntry:
    """One panel of :data:`PANELS`: the robot ``kind`` it drives (the page gives it its robot of that kind, as
    ``page.robots[kind]``), ``make(page, info)`` that makes it (``info``: the world's description, for its scene
    objects), and the view of :data:`VIEWS` it sits beside."""

    kind: str
    make: Callable[["ConsolePage", "WorldInfo"], Panel]
    beside: str


PANELS: tuple[PanelEntry, ...] = (
    PanelEntry("arm", arm_panel.make, "3d"),
    PanelEntry("mobile", base_panel.make, "map"),
)
"""Every panel a page may show, one per robot kind, in the page's order."""


class Panels:
    """The panels of one page: made from ``entries`` (:data:`PANELS`) for the kinds ``page.robots`` holds a
    robot of; each call goes to every panel, in the entries' order."""

    def __init__(self, page: "ConsolePage", entries: tuple[PanelEntry, ...] = PANELS) -> None:
        for e in entries:
            if e.beside not in VIEWS:
                raise ValueError(
                    f"panel of kind {e.kind!r}: no view {e.beside!r} to sit beside (views: {', '.join(VIEWS)})"
                )
        self.page = page
        self.entries = entries
        self.made: dict[str, Panel] = {}

    def make(self, info: WorldInfo) -> None:
        """A panel for each entry whose kind the page has a robot of (``info``: the world's description)."""
        for e in self.entries:
            if self.page.robots.get(e.kind) is not None:
                self.made[e.kind] = e.make(self.page, info)

    def get(self, kind: str) -> Any:
        """The page's panel of ``kind``, or None: for a view that works with it (a drag moves the arm's target), and
        so calls what that kind's panel offers beyond :class:`~.panel.Panel` (typed as it is: ``Any``)."""
        return self.made.get(kind)

    def beside(self, view: str) -> Iterator[tuple[str, Panel]]:
        """The (kind, panel) pairs that sit beside ``view``, in order."""
        for e in self.entries:
            if e.beside == view and e.kind in self.made:
                yield e.kind, self.made[e.kind]

    def refresh(self) -> None:
        for p in self.made.values():
            p.refresh()

    async def switch(self, robot: Robot) -> None:
        """``robot`` (a handle) becomes the page's robot of its kind, when the page has a panel of that kind."""
        panel = self.made.get(robot.kind)
        if panel is not None and robot is not self.page.robots.get(robot.kind):
            await panel.switch(robot)
            self.page.robots[robot.kind] = robot

    async def let_go(self, robot: Robot | None = None) -> None:
        """Every panel lets go (the page lost focus or its connection); or only the panel of ``robot``, when it
        is the page's robot of its kind (she releases it)."""
        for kind, p in self.made.items():
            if robot is None or robot is self.page.robots.get(kind):
                await p.let_go()

    async def key(self, e: GenericEventArguments) -> None:
        for p in self.made.values():
            await p.key(e)

    async def tick(self) -> None:
        for p in self.made.values():
            await p.tick()

    def end(self) -> None:
        for p in self.made.values():
            p.end()

"""Where a page puts its parts: each robot's controls beside its view, the selected robot's first.

Two rows under the robot list, one per view (:data:`.panels.VIEWS`): the 3D view, the top-down map, each with the
panels of :data:`.panels.PANELS` that sit beside it before it (the arm's beside the 3D view, the base's beside
the map). A panel shows only while its robot is the selected one or hers (bob, who selected nothing, sees no
disabled arm panel full of stale joints); the views always show (the world at a glance). The row of the selected
robot's kind's panel comes first, so that at 1024x700 the map and Plan are on the screen together once she
selects a base. Each row's two columns sit side by side from 856 px of width and stack below it (an 800x600
window, a tablet upright): a column is at least 420 px wide. The map is never taller than the window leaves room
for.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Mapping

from nicegui import ui

from user_peer.console.panels import VIEWS

if TYPE_CHECKING:
    from user_peer.console.page import ConsolePage
    from user_peer.robot import Robot
    from user_peer.world import World

__all__ = ["Layout", "CSS", "shown_kinds"]

CSS = """
.rf-col { flex: 1 1 420px; min-width: 0; }
.rf-map { max-width: max(18rem, calc(100vh - 17rem)); }
.q-btn.disabled, .q-btn[disabled] { filter: grayscale(1); opacity: 0.4 !important; }
.q-slider.disabled { filter: grayscale(1); }
"""
"""A column takes 420 px at least and grows (two of them wrap below 856 px); the map keeps to the window's height;
a disabled button or slider is grey (Quasar only dims it: a disabled Stop still looked bright red)."""


def shown_kinds(world: World, selected: str | None, robots: Mapping[str, Robot | None]) -> set[str]:
    """The kinds ("arm", "mobile") whose panel a page shows: its robot of that kind is the selected one or hers.
    ``robots``: the page's robot of each kind (or None)."""
    out = set()
    for kind, r in robots.items():
        if r is None:
            continue
        rec = world.ownership.record(r.id)
        if r.id == selected or (rec is not None and rec.owner == world.user):
            out.add(kind)
    return out


class Layout:
    """The rows of one page, and which of them shows what."""

    def __init__(self, page: "ConsolePage") -> None:
        self.page = page
        self.rows: dict[str, Any] = {}
        self.panels: dict[str, Any] = {}
        self._row_of: dict[str, str] = {}  # a panel's kind -> the view whose row holds it
        self._first: str | None = None

    def build(self) -> None:
        page = self.page
        ui.add_css(CSS)
        with ui.column().classes("full-width") as self.body:
            for name, view in zip(VIEWS, (page.view3d, page.view)):
                with ui.row().classes("full-width items-start") as row:
                    self.rows[name] = row
                    for kind, panel in page.panels.beside(name):
                        self._row_of[kind] = name
                        with ui.column().classes("rf-col") as box:
                            panel.build()
                        self.panels[kind] = box
                    if view is not None:  # no 3D view (console --no-3d): the arm's panel alone
                        with ui.column().classes("rf-col"):
                            view.build()
        page.view.image.classes("rf-map")

    def refresh(self) -> None:
        """Show the panels of the selected robot and of hers; the selected robot's row first."""
        page = self.page
        kinds = shown_kinds(page.world, page.selected, page.robots)
        for kind, box in self.panels.items():
            box.set_visibility(kind in kinds)
        sel = page.handles.get(page.selected) if page.selected else None
        first = self._row_of.get(sel.kind, VIEWS[0]) if sel is not None else VIEWS[0]
        if first != self._first:
            self._first = first
            self.rows[first].move(self.body, target_index=0)

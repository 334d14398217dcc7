"""The console's panels are one list: a panel registered there is made, built beside its view and refreshed by
the page's layout, and gets every call of the :class:`~user_peer.console.panel.Panel` protocol.

In-process, below a real page (a page needs a live world): a stand-in page holds what the layout and the panels
read of it (its robots, its selection, its world's ownership), and NiceGUI's user simulation builds the layout
in a real NiceGUI client. The browser tests (test_console_browser.py) show the real panels on a real page.
"""

from __future__ import annotations

import asyncio
import sys
from types import SimpleNamespace
from typing import Any

import pytest
from nicegui import ui
from nicegui.testing.user_simulation import user_simulation

from user_peer.console.layout import Layout
from user_peer.console.panel import Panel, PanelHooks
from user_peer.console.panels import PANELS, VIEWS, PanelEntry, Panels


class DummyPanel(PanelHooks):
    """A panel of the made-up kind "drone" that notes every call it gets (its robot as the page shows it then)."""

    def __init__(self, page: Any, calls: list[tuple[str, Any]]) -> None:
        self.page, self.calls = page, calls

    def build(self) -> None:
        self.calls.append(("build", None))
        self.label = ui.label("drone panel, not refreshed")

    def refresh(self) -> None:
        self.calls.append(("refresh", self.page.robots["drone"].id))
        if hasattr(self, "label"):
            self.label.text = f"drone {self.page.robots['drone'].id} refreshed"

    async def switch(self, robot: Any) -> None:
        self.calls.append(("switch", (self.page.robots["drone"].id, robot.id)))

    async def let_go(self) -> None:
        self.calls.append(("let_go", self.page.robots["drone"].id))

    async def key(self, e: Any) -> None:
        self.calls.append(("key", e))

    async def tick(self) -> None:
        self.calls.append(("tick", None))

    def end(self) -> None:
        self.calls.append(("end", None))


class StandInView:
    """What the layout calls on a view: ``build`` (and the map's ``image``)."""

    def __init__(self, text: str) -> None:
        self.text = text

    def build(self) -> None:
        self.image = ui.label(self.text)


def _page(robots: dict[str, Any], selected: str | None = None) -> SimpleNamespace:
    """What the layout and the panels read of a page; its world runs without ownership (no records)."""
    world = SimpleNamespace(user="alice", ownership=SimpleNamespace(record=lambda rid: None))
    return SimpleNamespace(
        robots=dict(robots),
        selected=selected,
        handles={r.id: r for r in robots.values()},
        world=world,
        view3d=StandInView("the 3D view"),
        view=StandInView("the map"),
    )


def _drone(rid: str) -> SimpleNamespace:
    return SimpleNamespace(id=rid, kind="drone")


def _entries(calls: list, beside: str = "map") -> tuple[PanelEntry, ...]:
    def make(page: Any, info: Any) -> DummyPanel:
        calls.append(("make", info))
        return DummyPanel(page, calls)

    return (*PANELS, PanelEntry("drone", make, beside))


def test_a_registered_panel_is_made_built_beside_its_view_and_refreshed():
    calls: list = []
    info = object()

    async def run() -> None:
        page = _page({"drone": _drone("d1")}, selected="d1")
        page.panels = Panels(page, _entries(calls))

        def root() -> None:
            page.panels.make(info)  # the arm and the base have no robot here: only the drone's panel is made
            page.layout = Layout(page)
            page.layout.build()
            page.panels.refresh()
            page.layout.refresh()

        async with user_simulation(root) as user:
            await user.open("/")
            await user.should_see("drone d1 refreshed")
            await user.should_see("the map")
            assert list(page.panels.made) == ["drone"]
            assert list(page.layout.panels) == ["drone"]  # its column, shown: d1 is the selected robot
            assert page.layout.panels["drone"].visible
            # its column sits in the map's row, before the map; the map's row comes first, as the drone is selected
            row = page.layout.rows["map"]
            assert row.default_slot.children[0] is page.layout.panels["drone"]
            assert page.layout.body.default_slot.children[0] is row

    asyncio.run(run())
    assert calls == [("make", info), ("build", None), ("refresh", "d1")]


def test_every_protocol_call_reaches_the_panels_and_a_switch_comes_before_the_change():
    calls: list = []
    page = _page({"drone": _drone("d1")})
    panels = Panels(page, _entries(calls))
    panels.make(None)
    d2 = _drone("d2")

    async def run() -> None:
        await panels.key("ArrowUp")
        await panels.tick()
        await panels.let_go(_drone("d9"))  # not the page's drone: nothing to let go
        await panels.let_go(page.robots["drone"])
        await panels.switch(d2)
        await panels.switch(d2)  # shown already: no switch
        await panels.switch(SimpleNamespace(id="x1", kind="rover"))  # no panel of its kind: nothing changes
        await panels.let_go()
        panels.end()

    asyncio.run(run())
    assert calls == [
        ("make", None),
        ("key", "ArrowUp"),
        ("tick", None),
        ("let_go", "d1"),
        ("switch", ("d1", "d2")),
        ("let_go", "d2"),
        ("end", None),
    ]
    assert page.robots == {"drone": d2}
    assert panels.get("drone") is not None and panels.get("arm") is None


def test_a_panel_beside_no_view_is_refused_with_the_views_named():
    with pytest.raises(ValueError, match=r"panel of kind 'drone': no view 'sky'.*3d, map"):
        Panels(_page({}), _entries([], beside="sky"))


def test_every_registered_panel_offers_the_whole_protocol():
    wanted = {n for n in vars(Panel) if not n.startswith("_")}
    assert wanted == {"build", "refresh", "switch", "let_go", "key", "tick", "end"}
    assert [e.kind for e in PANELS] == ["arm", "mobile"] and {e.beside for e in PANELS} <= set(VIEWS)
    for e in PANELS:
        made = e.make.__annotations__["return"].strip("'\"")  # the name of the class it makes
        cls = getattr(sys.modules[e.make.__module__], made)
        missing = {n for n in wanted if not callable(getattr(cls, n, None))}
        assert not missing, f"{cls.__name__} lacks {missing}"

"""A page's live view: the world from above (:mod:`.topview`) and its mouse (drag the IK target, click the goal).

Light by design, so that twenty pages fit one 2-core machine's software rendering. Each redraw costs the
browser a paint of what changed (its GPU process rasters and composites it, in software here), so a page
redraws only what moves, and only when it moved:

- the scene's walls and shelves and her map are one PNG, drawn by the server once per map (not with every
  redraw) and fetched by URL (:mod:`.pictures`: NiceGUI resends every property of an element it updates, and a
  data: URL would ride along with each redraw);
- the SVG overlay holds the robots, the scan, the paths, the target and the goal; NiceGUI sends it only when
  its text changed, so a still world costs the browser nothing;
- every robot's pose comes from the page's :class:`~user_peer.console.feed.PoseFeed`, taken at the start of the
  clock's pass (not fifty times a second; every page's at once, :meth:`LiveView.take`), decoded and drawn once per
  tick for every page that holds the same pose.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np
from nicegui import ui

from fabric import keys
from user_peer.console import follow, mapframe, state, topview
from user_peer.console.feed import PoseFeed, ring_capacity

if TYPE_CHECKING:
    from user_peer.console.page import ConsolePage

__all__ = ["LiveView", "DRAG_GRAB_PX"]

DRAG_GRAB_PX = 12.0
"""How near the IK target (image pixels) a press must be to grab it."""


class LiveView:
    """The view of one page: its picture, every robot's latest pose, and the mouse on it."""

    def __init__(self, page: "ConsolePage", frame: topview.Frame, boxes: list) -> None:
        self.page = page
        self.whole = frame  # the whole map
        self.frame = frame  # the part shown: the whole, or a zoomed part of it (mapframe.zoomed)
        self.zoom = 1
        self._grid: Any = None  # the map drawn in the picture now
        self.boxes = boxes
        self.feed: PoseFeed | None = None  # every robot's latest pose, undecoded (decoded at a redraw)
        self._map_seq: int | None = None
        self._drag = False  # the IK target is held by the mouse
        self._swallow_click = False
        self.image: Any = None
        self.token = page.console.pictures.new_token()

    def build(self) -> None:
        self.image = (
            ui.interactive_image(
                self.page.console.pictures.put(self.token, topview.background_png(self.frame, self.boxes)),
                content="",
                on_mouse=self.mouse,
                events=["mousedown", "mouseup", "click"],
                sanitize=False,
            )
            .classes("full-width")
            .props('role="group" aria-label="Live view: click to place the goal, drag the IK target"')
        )
        with self.image:  # over the map's top-right corner: the map's row keeps its height
            with ui.row().classes("absolute-top-right q-ma-xs items-center").style("gap: 0.25rem"):
                self.zoom_label = (
                    ui.label("").classes("text-caption").style("background: #ffffffd9; padding: 0 0.25rem")
                )
                for words, fn in (
                    ("Zoom in", self.zoom_in),
                    ("Zoom out", self.zoom_out),
                    ("Whole map", self.whole_map),
                ):
                    ui.button(words, on_click=fn).props("dense no-caps unelevated color=white text-color=dark")
        ui.html(mapframe.legend_html(), sanitize=False)
        self._show_zoom()

    # ------------------------------------------------------------------ zoom

    def _centre(self) -> tuple[float, float]:
        """Where a zoom centres: the page's base when its pose is known, else the middle of what is shown."""
        base = self.page.robots.get("mobile")
        xy = base.xy_theta if base is not None and base.id in self.page.world.following.robots else None
        f = self.frame
        return (xy[0], xy[1]) if xy else ((f.xmin + f.xmax) / 2, (f.ymin + f.ymax) / 2)

    def set_zoom(self, level: int) -> None:
        """Show the map ``level`` times larger (one of :data:`.mapframe.ZOOMS`), around the page's base."""
        self.zoom = level
        self.frame = mapframe.zoomed(self.whole, level, self._centre())
        self._picture(self._grid)
        self._show_zoom()
        f, base = self.frame, self.page.robots.get("mobile")
        if level == 1:
            around = "whole"
        elif base is not None and base.id in self.page.world.following.robots:
            around = f"around {base.id}"
        else:  # no base of hers followed (none selected or hers): where the zoom centred, not "whole"
            around = "around its middle"
        self.page.say(f"zoom x{level}: the map {around}, {f.xmax - f.xmin:.1f} m wide")
        self.page.refresh()

    def zoom_in(self) -> None:
        self.set_zoom(next((z for z in mapframe.ZOOMS if z > self.zoom), mapframe.ZOOMS[-1]))

    def zoom_out(self) -> None:
        self.set_zoom(next((z for z in reversed(mapframe.ZOOMS) if z < self.zoom), 1))

    def whole_map(self) -> None:
        self.set_zoom(1)

    def _show_zoom(self) -> None:
        f = self.frame
        self.zoom_label.text = f"zoom x{self.zoom} · {f.xmax - f.xmin:.1f} m wide"

    def _picture(self, grid: Any) -> None:
        """The still picture of the part shown: her map (if any) and the scene's walls."""
        self._grid = grid
        png = topview.background_png(
            self.frame, self.boxes, (grid.cells, grid.resolution, grid.origin) if grid is not None else None
        )
        self.image.set_source(self.page.console.pictures.put(self.token, png))

    def follow_poses(self) -> None:
        """Every robot's pose, through the page's own session, kept in zenoh's ring until a redraw takes it."""
        w = self.page.world
        self.feed = PoseFeed(w.fabric, w.name, ring_capacity(len(self.page.entries)))

    def mouse(self, e: Any) -> None:
        """A press on the IK target and its release elsewhere drag the target there (its height kept; the nudges
        move it up and down); any other click places the goal."""
        page, arm_panel = self.page, self.page.panels.get("arm")
        target = arm_panel.target if arm_panel is not None else None
        if e.type == "mousedown":
            self._drag = (
                target is not None
                and math.dist(self.frame.px(float(target[0]), float(target[1])), (e.image_x, e.image_y)) <= DRAG_GRAB_PX
            )
        elif e.type == "mouseup" and self._drag:
            self._drag, self._swallow_click = False, True
            x, y = self.frame.world(e.image_x, e.image_y)
            arm_panel.move_target(np.array([x, y, float(target[2])]))
            page.say(f"IK target dragged to ({x:.3f}, {y:.3f}, {float(target[2]):.3f})")
            page.refresh()
        elif e.type == "click":
            if self._swallow_click:  # the click that ends a drag places no goal
                self._swallow_click = False
            elif page.panels.get("mobile") is not None:
                page.panels.get("mobile").clicked(e)

    def take(self) -> None:
        """What the page's feed holds now, taken (not decoded) for the next redraw: the clock calls it for every page
        at the start of its pass, so that the pages hold the same newest poses and share their drawing
        (:mod:`.ticker`)."""
        if self.feed is not None:
            self.feed.drain()

    def close(self) -> None:
        """The page went away: its picture is no longer served, its poses no longer kept."""
        self.page.console.pictures.drop(self.token)
        if self.feed is not None:
            self.feed.close()

    def refresh(self) -> None:
        """The picture again when her map changed; the overlay from what the page holds now."""
        page, w = self.page, self.page.world
        arm_panel, base_panel, base = page.panels.get("arm"), page.panels.get("mobile"), page.robots.get("mobile")
        grid = (
            w.latest.get(keys.map_key(w.name, keys.user_map("map", w.user)))
            or (base_panel.grid if base_panel else None)
            or w.latest.get(keys.map_key(w.name, "map"))
        )
        if grid is not None and id(grid) != self._map_seq:
            self._map_seq = id(grid)
            self._picture(grid)
        target = arm_panel.target if arm_panel is not None else None
        poses = self.feed.raw if self.feed is not None else {}  # what the clock's pass took (.take)
        self.image.content = state.view_svg(
            w,
            page.entries,
            follow.followed(w, page.handles),
            poses,
            self.frame,
            (),
            base_id=base.id if base else None,
            selected={page.selected} if page.selected else set(),
            goal=base_panel.goal if base_panel else None,
            target=(float(target[0]), float(target[1])) if target is not None else None,
            decoder=page.console.decoded,
        ) + mapframe.scale_bar_svg(self.frame)

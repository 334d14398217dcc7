"""The base panel of a page: arrow keys to drive (a deadman the page refreshes), Stop, Build map, the goal
clicked on the view or typed in metres (:mod:`.goal`), Hybrid A* or OMPL, Plan, Follow, the distance to the goal."""

from __future__ import annotations

import asyncio
import math
import time
from typing import TYPE_CHECKING, Any

import numpy as np
from nicegui import ui
from nicegui.events import GenericEventArguments, MouseEventArguments

from fabric import keys
from fabric.text import one_line
from user_peer.console.drive import Driver
from user_peer.console.goal import typed_goal
from user_peer.console.panel import PanelHooks
from user_peer.console.workers import TWISTS, off_loop
from user_peer.errors import FabricUserError

if TYPE_CHECKING:
    from user_peer.console.page import ConsolePage

__all__ = ["BasePanel", "PLANNERS", "make"]

PLANNERS = {"Hybrid A*": "hybrid_astar", "OMPL": "ompl"}


def make(page: "ConsolePage", info: Any) -> "BasePanel":
    """The page's base panel, with the world's goal pointer when its scene has one (``info``: the world's
    description)."""
    goal = next((o for o in info.objects if o.kind == "goal_pointer"), None)
    return BasePanel(page, page.world.object(goal.id) if goal else None)


class BasePanel(PanelHooks):
    """One card of the page, for its base ``page.robots["mobile"]`` (a :class:`~.panel.Panel`); its keys come from
    the page's listener."""

    def __init__(self, page: "ConsolePage", goal_obj: Any) -> None:
        self.page = page
        self.goal_obj = goal_obj  # the goal pointer (a scene object)
        self.driver = Driver()
        self._send_lock = asyncio.Lock()
        self.goal: tuple[float, float, float] | None = None
        self.path: Any = None
        self.grid: Any = None  # the map her last Build map returned

    @property
    def base(self) -> Any:
        return self.page.robots["mobile"]

    async def switch(self, robot: Any) -> None:
        """Another base shown: a key held for this one drives it no more."""
        await self.let_go()

    def end(self) -> None:
        """The page closed: no key is held any more (the sim's deadman stops the base)."""
        self.driver.stop()

    def build(self) -> None:
        with ui.card().classes("full-width"):
            self.title = ui.label("").classes("text-subtitle1").props('role="heading" aria-level="2"')
            ui.label("Hold an arrow key to drive · 1-3 speed · space stops").classes("text-caption")
            self.state = ui.label("").classes("rf-base-state")  # bench console reads its data-pose-wall-ms
            with ui.row().classes("items-center"):
                stop = ui.button("Stop", color="negative", on_click=self._stop).props('aria-label="Stop base"')
                build = ui.button("Build map", on_click=self._build_map)
                self.planner = ui.radio(list(PLANNERS), value="Hybrid A*").props("inline")
                self.reverse = ui.checkbox("may reverse", value=False)  # the plan may drive backwards (issue 44)
                plan = ui.button("Plan", on_click=self._plan)
                follow = ui.button("Follow", on_click=self._follow)
            with ui.row().classes("items-center no-wrap").style("gap: 0.5rem"):
                # the goal typed instead of clicked (a student who knows it in metres, or who does not use a mouse)
                self.goal_x = ui.input("Goal x (m)").props('dense aria-label="Goal x in metres"').style("width: 7rem")
                self.goal_y = ui.input("Goal y (m)").props('dense aria-label="Goal y in metres"').style("width: 7rem")
                ui.button("Set goal", on_click=self._typed).props("no-caps")
                for f in (self.goal_x, self.goal_y):
                    f.on("keydown.enter", self._typed)
            self.goal_label = ui.label("goal: click on the map or type x and y")
        self.controls = [stop, build, plan, follow]

    # ------------------------------------------------------------------ driving

    async def key(self, e: GenericEventArguments) -> None:
        if not isinstance(e.args, dict):
            return
        arrived = time.time()
        if self.driver.key(str(e.args.get("key", "")), bool(e.args.get("down"))):
            await self.send_twist()
            t = e.args.get("t")
            self.page.console.health.key(float(t) if isinstance(t, (int, float)) else None, arrived, time.time())

    async def let_go(self) -> None:
        """The page lost focus or its connection: a held key's release may never come."""
        if self.driver.stop():
            await self.send_twist()

    async def send_twist(self) -> None:
        v, w = self.driver.twist()
        async with self._send_lock:
            try:
                # hold=False: the page itself repeats a held key's twist (tick), so the sim's deadman
                # stops the base when the page goes quiet, whatever the server's session does until its grace
                base = self.base
                await off_loop(TWISTS, base.twist, v, w, hold=False)
            except FabricUserError as exc:
                self.driver.stop()
                self.page.say(f"drive {self.base.id}: {self.page.why(exc)}")

    async def tick(self) -> None:
        """Every ``REFRESH_S`` while a key is held: the twist again (the sim's twist is a deadman). A tick that finds
        the last send still under way is skipped."""
        if self.driver.driving and not self._send_lock.locked():
            await self.send_twist()

    async def _stop(self) -> None:
        self.driver.stop()
        await self.page.call(f"stop {self.base.id}", self.base.stop, confirm=False)

    # ------------------------------------------------------------------ navigation

    async def _build_map(self) -> None:
        b = self.base
        if await self.page.call("start mapping", b.start_mapping) is self.page.FAILED:
            return
        grid = await self.page.call("build map", b.build_map)
        if grid is not self.page.FAILED:
            self.grid = grid
            self.page.say(f"build map: {grid.cells.shape[1]} x {grid.cells.shape[0]} cells at {grid.resolution:.2f} m")

    def clicked(self, e: MouseEventArguments) -> None:
        """A click on the view (on the part of the map it shows): the goal, facing away from the base."""
        x, y = self.page.view.frame.world(e.image_x, e.image_y)
        self.goal_x.value, self.goal_y.value = f"{x:.2f}", f"{y:.2f}"
        self._set_goal(x, y)

    def _typed(self) -> None:
        """The goal from the x and y fields; a field that does not read as a point of the map says why, on the
        field and in the page's status line, and the goal stays where it was."""
        typed = typed_goal(self.goal_x.value or "", self.goal_y.value or "", self.page.view.whole)
        bad = dict(typed.errors)
        for name, f in (("x", self.goal_x), ("y", self.goal_y)):
            f.props["error"] = name in bad
            f.props["error-message"] = bad.get(name, "")
            f.update()
        if typed.xy is None:
            self.page.say(f"Set goal: {typed.message()}")
            return
        self._set_goal(*typed.xy)

    def _set_goal(self, x: float, y: float) -> None:
        xy = self.base.xy_theta
        yaw = math.atan2(y - xy[1], x - xy[0]) if xy else 0.0
        self.goal = (x, y, yaw)
        if self.goal_obj is not None:
            self.goal_obj.set_pose((x, y, 0.0), yaw=yaw)
        self.page.say(f"goal at ({x:.2f}, {y:.2f})")

    async def _plan(self) -> None:
        if self.goal is None:
            self.page.say("Plan: place the goal first: click on the map, or type its x and y and press Set goal")
            return
        planner = PLANNERS[self.planner.value]
        # on her own map: a student's Build map makes {user}.map (the class's map is the staff's)
        path = await self.page.call(
            f"plan ({planner})",
            self.base.plan_to,
            *self.goal,
            planner=planner,
            direction="both" if self.reverse.value else "default",
            map_name=keys.user_map("map", self.page.world.user),
        )
        if path is not self.page.FAILED:
            self.path = path
            length = float(np.sum(np.hypot(np.diff(path.x), np.diff(path.y)))) if len(path) > 1 else 0.0
            note = f" ({self.base.plan_note})" if self.base.plan_note else ""
            self.page.say(f"plan ({planner}): {len(path)} poses, {length:.2f} m{note}")

    async def _follow(self) -> None:
        if self.path is None:
            self.page.say("Follow: plan a path first")
            return
        await self.page.call(f"follow {self.base.id}", self.base.follow, self.path, wait=False)

    # ------------------------------------------------------------------ refresh

    def refresh(self) -> None:
        b = self.base
        mine = b.can_command
        rec = b.record
        who = "you" if mine and rec is not None else (rec.owner or "nobody") if rec is not None else "?"
        live = b.id in self.page.world.following.robots  # else its pose is what was kept when the page let go of it
        self.title.text = one_line(
            f"base {b.id} ({b.type}) · owner: {who}" + ("" if mine else " · controls disabled"), 300
        )
        for c in self.controls:
            c.set_enabled(mine)
        xy, pose = (b.xy_theta, b.pose) if live else (None, None)
        text = (
            f"pose ({xy[0]:+.2f}, {xy[1]:+.2f}, {math.degrees(xy[2]):+.0f}°)"
            if xy
            else ("pose -" if live else f"pose: click {b.id} to follow it")
        )
        if pose is not None:
            text += f" · v {math.hypot(pose.linear[0], pose.linear[1]):.2f} m/s"
            stamp = str(pose.header.wall_ns // 1_000_000)
            if self.state.props.get("data-pose-wall-ms") != stamp:  # the page's own lag: Date.now() against it
                self.state.props(f"data-pose-wall-ms={stamp}")
        v, om = self.driver.twist()
        self.state.text = text + f" · speed {self.driver.level} · command v {v:+.2f} w {om:+.2f}"
        if self.goal is not None and xy is not None:
            self.goal_label.text = f"goal ({self.goal[0]:.2f}, {self.goal[1]:.2f}) · distance {math.hypot(self.goal[0] - xy[0], self.goal[1] - xy[1]):.2f} m"

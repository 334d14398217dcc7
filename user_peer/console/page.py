"""One student's page: the login, then the paper's window (robot list, arm panel, base panel, live view, events).

Every button calls the Python user API (``user_peer``) of the page's own world, off the event loop
(``nicegui.run.io_bound``), so a slow answer holds up this page only. Refusals are shown with their
reason and the robot's owner. A 5 Hz timer redraws what changed; a 10 Hz one refreshes the twist
while an arrow key is held (the sim's twist is a deadman).
"""

from __future__ import annotations

import asyncio
import logging
import math
import threading
from typing import TYPE_CHECKING, Any, Callable

import numpy as np
from nicegui import run, ui
from nicegui.events import GenericEventArguments, MouseEventArguments

from fabric import keys
from user_peer.console import state, topview
from user_peer.console.drive import REFRESH_S, Driver
from user_peer.console.login import LoginError, login_config
from user_peer.errors import FabricUserError

if TYPE_CHECKING:
    from user_peer.console.server import Console

__all__ = ["ConsolePage", "PLANNERS", "NUDGE_STEPS", "event_line"]

log = logging.getLogger("robofabric.console")

PLANNERS = {"Hybrid A*": "hybrid_astar", "OMPL": "ompl"}
NUDGE_STEPS = {"1 mm": 0.001, "1 cm": 0.01, "5 cm": 0.05}
REFRESH_VIEW_S = 0.2
FAILED = object()
"""What :meth:`ConsolePage._call` returns when the call was refused (its reason is on the page)."""

KEYS_JS = """
for (const type of ['keydown', 'keyup']) document.addEventListener(type, (e) => {
  const f = document.activeElement;
  const typing = f && (['INPUT', 'TEXTAREA', 'SELECT'].includes(f.tagName) || f.getAttribute('role') === 'slider');
  if (type === 'keydown' && (typing || e.repeat)) return;
  if (!typing && ['ArrowUp', 'ArrowDown', 'ArrowLeft', 'ArrowRight', ' '].includes(e.key)) e.preventDefault();
  emitEvent('rf_key', {key: e.key, down: type === 'keydown'});
});
window.addEventListener('blur', () => emitEvent('rf_blur'));
"""
"""The page's keys: a key pressed while typing in a field or on a focused slider is that control's, never the
base's (the terminal UI turned the base when ← was meant for a slider); a release always counts, so a key
let go anywhere stops the base; the page losing focus stops it too. NiceGUI's ``ui.keyboard`` ignores by tag
name only, and every Quasar control is a ``div``."""


def event_line(ev: Any, trusted: bool) -> str:
    """An event log line; one its robot's authority did not send is marked unverified (as the terminal UI does)."""
    text = f"{ev.kind}" + (f" {ev.object}" if ev.object else "") + (f" [{ev.user}]" if ev.user else "") + (f": {ev.reason}" if ev.reason else "")
    return f"trusted · {text}" if trusted else f"unverified (display only) · {text}"


def _first_handles(world: Any, user: str) -> tuple[list, dict[str, Any]]:
    """The world's robots, and handles for the arm and the base a page shows first: hers if she owns one (a
    reload), else the first of each kind."""
    from user_peer import services

    entries = services.robot_entries(world.info())
    handles = {}
    for kind in ("arm", "mobile"):
        mine = [e for e in entries if e.kind == kind and (rec := world.ownership.record(e.id)) is not None and rec.owner == user]
        first = mine or [e for e in entries if e.kind == kind]
        if first:
            handles[first[0].id] = world.robot(first[0].id)
    return entries, handles


class ConsolePage:
    """The page of one browser tab: built by :meth:`show` when the tab opens."""

    def __init__(self, console: "Console", client: Any) -> None:
        self.console = console
        self.client = client
        self.world: Any = None
        self.entries: list = []  # every robot of the world (user_peer.services.RobotEntry)
        self.handles: dict[str, Any] = {}  # the robots this page follows in full: those she selected
        self.poses: dict[str, bytes] = {}  # every robot's latest pose, undecoded (decoded at a redraw)
        self.arm: Any = None
        self.base: Any = None
        self.selected: str | None = None
        self.driver = Driver()
        self._send_lock = asyncio.Lock()
        self._syncing = False
        self._synced = False
        self.target: np.ndarray | None = None
        self.ik_q: np.ndarray | None = None
        self.goal: tuple[float, float, float] | None = None
        self.path: Any = None
        self._map_seq: int | None = None
        self.grid: Any = None
        self._events_seen = 0
        self._gone_seen = 0
        self._owners: dict[str, str] = {}
        self._ik_task: asyncio.Task | None = None

    # ------------------------------------------------------------------ login

    def show(self) -> None:
        ui.page_title(f"robofabric console · {self.console.world}")
        self.root = ui.column().classes("w-full")
        with self.root:
            self._login_form()

    def _login_form(self) -> None:
        with ui.card().classes("mx-auto mt-16 w-96"):
            ui.label(f"robofabric · world {self.console.world}").classes("text-h6")
            self.name_in = ui.input("Name").props('autofocus aria-label="Name"').classes("w-full")
            self.pw_in = ui.input("Password", password=True, password_toggle_button=False).props('aria-label="Password"').classes("w-full")
            ui.label("In an open world (no logins) pick a name and leave the password empty.").classes("text-caption")
            self.login_btn = ui.button("Log in", on_click=self._login)
            self.pw_in.on("keydown.enter", self._login)
            self.login_msg = ui.label("").props('role="alert"').classes("text-negative")

    async def _login(self) -> None:
        name, password = (self.name_in.value or "").strip(), self.pw_in.value or ""
        self.login_btn.disable()
        self.login_msg.text = f"logging in as {name}..."
        try:
            cfg = login_config(self.console.world, self.console.connect, name, password, base_file=self.console.base_file)
            world = await run.io_bound(self.console.logins.login, cfg, name, password)
            entries, handles = await run.io_bound(_first_handles, world, name)
        except LoginError as exc:
            self.login_msg.text = exc.reason
            self.login_btn.enable()
            return
        except FabricUserError as exc:  # logged in, but the world did not answer
            self.console.logins.leave(name)
            self.login_msg.text = f"Could not join world {self.console.world}: {exc.reason}"
            self.login_btn.enable()
            return
        self.world, self.entries, self.handles = world, entries, handles
        self.user = name
        self.client.on_disconnect(self._disconnected)
        self.client.on_delete(self._gone)
        self.root.clear()
        with self.root:
            self._main()

    async def _disconnected(self) -> None:
        """The connection dropped (the tab closed, the network went): a held key is let go at once, since its
        release may never come."""
        if self.base is not None and self.driver.stop():
            await self._send_twist()

    def _gone(self) -> None:
        """The tab closed (or lost its connection for good): her robots stop, her world closes after the grace."""
        self.driver.stop()
        if self.world is not None:  # stopping her robots waits on the network: never on the pages' event loop
            threading.Thread(target=self.console.logins.leave, args=(self.user,), name=f"console-leave-{self.user}", daemon=True).start()

    # ------------------------------------------------------------------ layout

    def _main(self) -> None:
        w = self.world
        self.frame, self.boxes = state.scene_layout(w.info())
        self.arm = next((r for r in self.handles.values() if r.kind == "arm"), None)
        self.base = next((r for r in self.handles.values() if r.kind == "mobile"), None)
        self.selected = (self.arm or self.base).id if self.handles else None
        # every robot's pose for the view, kept undecoded: a page of a 20-robot class decodes 5 poses a second per
        # robot, not 50 (only the robots she selected are followed in full: joints, scan, path)
        w.fabric.subscribe_raw(keys.robot_stream_all(w.name, "pose"), self._on_pose)
        info = w.info()
        target = next((o for o in info.objects if o.kind == "ik_target"), None)
        goal = next((o for o in info.objects if o.kind == "goal_pointer"), None)
        self.target_obj = w.object(target.id) if target else None
        self.goal_obj = w.object(goal.id) if goal else None
        if target is not None:
            self.target = np.asarray(target.position, dtype=float)

        with ui.row().classes("w-full items-center"):
            ui.label(f"robofabric console · world {w.name} · {w.user}").classes("text-h6")
            if self.console.rerun_url:
                ui.link("Rerun web view (the rich view)", self.console.rerun_url, new_tab=True)
        self.message = ui.label("").props('role="status" aria-live="polite"').classes("text-body1")
        with ui.row().classes("w-full no-wrap items-start"):
            with ui.column().classes("w-1/2"):
                self._robot_list()
                if self.arm is not None:
                    self._arm_panel()
                if self.base is not None:
                    self._base_panel()
            with ui.column().classes("w-1/2"):
                self.view = ui.interactive_image(
                    topview.data_url(topview.png_gray(np.full((self.frame.height, self.frame.width), 230, np.uint8))),
                    content="", on_mouse=self._clicked, events=["click"], sanitize=False,
                ).classes("w-full").props('aria-label="Live view: click to place the goal"')
                ui.label("Events").classes("text-subtitle1")
                self.log = ui.log(max_lines=200).classes("w-full h-48")
        ui.on("rf_key", self._key)
        ui.on("rf_blur", self._blur)
        ui.run_javascript(KEYS_JS)
        ui.timer(REFRESH_VIEW_S, self._refresh)
        ui.timer(REFRESH_S, self._keep_driving)
        self._refresh()

    def _robot_list(self) -> None:
        with ui.card().classes("w-full"):
            ui.label("Robots").classes("text-subtitle1")
            self.rows: dict[str, ui.label] = {}
            for r in self.entries:
                with ui.row().classes("items-center"):
                    ui.button(r.id, on_click=lambda _, rid=r.id: self._select(rid)).props("flat dense no-caps")
                    self.rows[r.id] = ui.label("")
            with ui.row().classes("items-center"):
                self.sel_label = ui.label("")
                ui.button("Request", on_click=lambda: self._ownership("request"))
                ui.button("Release", on_click=lambda: self._ownership("release"))
                ui.button("Queue", on_click=lambda: self._ownership("queue"))

    def _arm_panel(self) -> None:
        e = self.arm.entry
        with ui.card().classes("w-full"):
            self.arm_title = ui.label("").classes("text-subtitle1")
            self.sliders = []
            for i, name in enumerate(e.joint_names):
                lo = math.degrees(e.lower[i]) if i < len(e.lower) else -180.0
                hi = math.degrees(e.upper[i]) if i < len(e.upper) else 180.0
                with ui.row().classes("w-full items-center no-wrap"):
                    ui.label(f"J{i + 1}").classes("w-8")
                    s = ui.slider(min=round(lo, 1), max=round(hi, 1), step=0.5, value=0.0,
                                  on_change=self._slider_moved).props(f'label aria-label="J{i + 1} ({name}) degrees"').classes("w-full")
                    self.sliders.append(s)
            with ui.row().classes("w-full items-center no-wrap"):
                ui.label("Speed").classes("w-16")
                self.speed = ui.slider(min=0.05, max=1.0, step=0.05, value=0.5).props('label aria-label="Speed scale"').classes("w-full")
            with ui.row():
                self.arm_stop = ui.button("Stop", color="negative", on_click=lambda: self._call(f"stop {self.arm.id}", self.arm.stop))
                self.arm_reset = ui.button("Reset", color="warning", on_click=self._reset)
            with ui.row().classes("items-center"):
                ui.label("IK target")
                self.target_label = ui.label("")
                self.step = ui.select(list(NUDGE_STEPS), value="1 cm").props('aria-label="Nudge step" dense')
            with ui.row():
                self.nudges = []
                for axis, name in enumerate("xyz"):
                    for sign, txt in ((-1, "−"), (1, "+")):
                        b = ui.button(f"{name}{txt}", on_click=lambda _, a=axis, s=sign: self._nudge(a, s)).props(
                            f'dense aria-label="{name} {"plus" if sign > 0 else "minus"}"')
                        self.nudges.append(b)
            self.ik_label = ui.label("IK: move the target")
            self.apply_btn = ui.button("Apply IK", on_click=self._apply_ik)
        self.arm_controls = [*self.sliders, self.speed, self.arm_stop, self.arm_reset, self.apply_btn, *self.nudges]

    def _base_panel(self) -> None:
        with ui.card().classes("w-full"):
            self.base_title = ui.label("").classes("text-subtitle1")
            ui.label("Hold an arrow key to drive · 1-3 speed · space stops").classes("text-caption")
            self.base_state = ui.label("").classes("rf-base-state")  # bench console reads its data-pose-wall-ms
            with ui.row().classes("items-center"):
                self.base_stop = ui.button("Stop", color="negative", on_click=self._stop_base).props('aria-label="Stop base"')
                self.map_btn = ui.button("Build map", on_click=self._build_map)
                self.planner = ui.radio(list(PLANNERS), value="Hybrid A*").props("inline")
                self.plan_btn = ui.button("Plan", on_click=self._plan)
                self.follow_btn = ui.button("Follow", on_click=self._follow)
            self.goal_label = ui.label("goal: click on the map")
        self.base_controls = [self.base_stop, self.map_btn, self.plan_btn, self.follow_btn]

    # ------------------------------------------------------------------ actions

    def _say(self, text: str) -> None:
        self.message.text = text

    async def _call(self, what: str, fn: Callable, *args: Any, **kw: Any) -> Any:
        """``fn`` off the event loop; its refusal is shown with the reason (and the owner), never raised: it returns
        :data:`FAILED` then."""
        try:
            out = await run.io_bound(fn, *args, **kw)
        except FabricUserError as exc:
            self._say(f"{what}: {self._why(exc)}")
            return FAILED
        except Exception as exc:  # a network hiccup never ends the page
            log.exception("console: %s failed", what)
            self._say(f"{what}: {type(exc).__name__}: {exc}")
            return FAILED
        self._say(f"{what}: ok")
        return out

    def _why(self, exc: FabricUserError) -> str:
        reason = f"{type(exc).__name__}: {exc.reason}"
        rec = self.world.ownership.record(self.selected) if self.selected else None
        owner = rec.owner if rec is not None else ""
        if owner and owner != self.world.user and owner not in exc.reason:
            reason += f" (owner: {owner})"
        return reason

    def _on_pose(self, sample: Any) -> None:
        """(zenoh's thread) keep the latest pose of every robot, undecoded."""
        try:
            self.poses[keys.parse(str(sample.key_expr)).subject] = sample.payload.to_bytes()
        except Exception:  # a key that does not parse: not a robot's pose
            pass

    async def _handle(self, rid: str | None) -> Any:
        """The robot's user-API handle; made (and its streams followed) the first time she selects it."""
        if rid is None:
            return None
        if rid not in self.handles:
            r = await self._call(f"select {rid}", self.world.robot, rid)
            if r is FAILED:
                return None
            self.handles[rid] = r
        return self.handles[rid]

    async def _select(self, rid: str) -> None:
        self.selected = rid
        r = await self._handle(rid)
        if r is not None and r.kind == "arm" and r is not self.arm:
            self.arm, self._synced = r, False
        elif r is not None and r.kind == "mobile" and r is not self.base:
            self.driver.stop()
            self.base = r
        self._refresh()

    async def _ownership(self, op: str) -> None:
        r = await self._handle(self.selected)
        if r is None:
            return
        if op == "request":
            epoch = await self._call(f"request {r.id}", r.request)
            if epoch is not FAILED:
                self._say(f"request {r.id}: you own it (epoch {epoch})")
        elif op == "release":
            if r.kind == "mobile":
                self.driver.stop()
            await self._call(f"release {r.id}", r.release)
        else:
            out = await self._call(f"queue for {r.id}", self.world.ownership.client.request, r.id, wait=True, timeout=self.world.timeout)
            if out is not FAILED:
                self._say(f"queue for {r.id}: {out}")
        self._refresh()

    def _slider_moved(self) -> None:
        if self._syncing or self.arm is None or not self.arm.can_command:
            return
        q = np.radians([s.value for s in self.sliders])
        asyncio.ensure_future(self._call(f"joints {np.round(np.degrees(q), 1).tolist()} deg", self.arm.move_joints, q,
                                         wait=False, speed_scale=float(self.speed.value)))

    async def _reset(self) -> None:
        if await self._call(f"reset {self.arm.id}", self.arm.reset, confirm=False) is not FAILED:
            self._synced = False

    def _nudge(self, axis: int, sign: int) -> None:
        if self.target is None:
            p = self.arm.flange if self.arm is not None else None
            if p is None:
                self._say("no target yet: the arm has sent no flange pose")
                return
            self.target = np.asarray(p.position, dtype=float)
        self.target = self.target.copy()
        self.target[axis] += sign * NUDGE_STEPS[self.step.value]
        if self.target_obj is not None:
            self.target_obj.set_pose(self.target)
        self.ik_q = None
        self.ik_label.text = "IK: solving..."
        if self._ik_task is None or self._ik_task.done():
            self._ik_task = asyncio.ensure_future(self._solve())

    async def _solve(self) -> None:
        """Solve for the newest target until the answer is for the target as it stands (nudges during a solve
        are not queued: the next solve takes the latest)."""
        while True:
            goal = self.target.copy()
            try:
                q = await run.io_bound(self.arm.ik, goal)
            except FabricUserError as exc:
                q, why = None, exc.reason
            if not np.array_equal(goal, self.target):
                continue
            if q is None:
                self.ik_label.text = f"IK: unreachable: {why}"
                return
            self.ik_q = np.asarray(q)
            js = self.arm.joints
            speeds = ""
            if js is not None and self.arm.entry.max_speed:
                # the paper's synchronised move (Eq. 3-7): every joint arrives together, the slowest at its limit
                d = np.abs(self.ik_q - js)
                vmax = np.asarray(self.arm.entry.max_speed) * float(self.speed.value)
                t = float(np.max(d / np.maximum(vmax, 1e-9)))
                speeds = " · speeds " + str(np.round(np.degrees(d / t), 1).tolist() if t > 0 else [0.0] * len(d)) + f" deg/s ({t:.2f} s)"
            self.ik_label.text = f"IK: {np.round(np.degrees(self.ik_q), 1).tolist()} deg{speeds}"
            return

    async def _apply_ik(self) -> None:
        if self.ik_q is None:
            self._say("Apply IK: no IK solution for the target yet")
            return
        q = self.ik_q
        if await self._call(f"apply IK {np.round(np.degrees(q), 1).tolist()} deg", self.arm.move_joints, q,
                            wait=False, speed_scale=float(self.speed.value)) is not FAILED:
            self._set_sliders(q)

    def _set_sliders(self, q: np.ndarray) -> None:
        self._syncing = True
        try:
            for s, v in zip(self.sliders, q):
                s.value = round(math.degrees(float(v)), 1)
        finally:
            self._syncing = False

    # ------------------------------------------------------------------ driving

    async def _key(self, e: GenericEventArguments) -> None:
        if self.base is None or not isinstance(e.args, dict):
            return
        if self.driver.key(str(e.args.get("key", "")), bool(e.args.get("down"))):
            await self._send_twist()

    async def _blur(self) -> None:
        if self.driver.stop():
            await self._send_twist()

    async def _send_twist(self) -> None:
        v, w = self.driver.twist()
        async with self._send_lock:
            try:
                await run.io_bound(self.base.twist, v, w)
            except FabricUserError as exc:
                self.driver.stop()
                self._say(f"drive {self.base.id}: {self._why(exc)}")

    async def _keep_driving(self) -> None:
        if self.base is not None and self.driver.driving and not self._send_lock.locked():
            await self._send_twist()

    async def _stop_base(self) -> None:
        self.driver.stop()
        await self._call(f"stop {self.base.id}", self.base.stop, confirm=False)

    # ------------------------------------------------------------------ navigation

    async def _build_map(self) -> None:
        b = self.base
        if await self._call("start mapping", b.start_mapping) is FAILED:
            return
        grid = await self._call("build map", b.build_map)
        if grid is not FAILED:
            self.grid = grid
            self._say(f"build map: {grid.cells.shape[1]} x {grid.cells.shape[0]} cells at {grid.resolution:.2f} m")

    def _clicked(self, e: MouseEventArguments) -> None:
        x, y = self.frame.world(e.image_x, e.image_y)
        xy = self.base.xy_theta if self.base is not None else None
        yaw = math.atan2(y - xy[1], x - xy[0]) if xy else 0.0
        self.goal = (x, y, yaw)
        if self.goal_obj is not None:
            self.goal_obj.set_pose((x, y, 0.0), yaw=yaw)
        self._say(f"goal at ({x:.2f}, {y:.2f})")

    async def _plan(self) -> None:
        if self.goal is None:
            self._say("Plan: click on the map to place the goal first")
            return
        planner = PLANNERS[self.planner.value]
        # on her own map: a student's Build map makes {user}.map (the class's map is the staff's)
        path = await self._call(f"plan ({planner})", self.base.plan_to, *self.goal, planner=planner,
                                map_name=keys.user_map("map", self.world.user))
        if path is not FAILED:
            self.path = path
            length = float(np.sum(np.hypot(np.diff(path.x), np.diff(path.y)))) if len(path) > 1 else 0.0
            self._say(f"plan ({planner}): {len(path)} poses, {length:.2f} m")

    async def _follow(self) -> None:
        if self.path is None:
            self._say("Follow: plan a path first")
            return
        await self._call(f"follow {self.base.id}", self.base.follow, self.path, wait=False)

    # ------------------------------------------------------------------ refresh

    def _refresh(self) -> None:
        try:
            self._refresh_inner()
        except Exception:
            log.exception("console: refresh failed")

    def _refresh_inner(self) -> None:
        w = self.world
        if w is None or w.closed:
            return
        for r in self.entries:
            line = state.robot_line(w, r.id, r.kind)
            self.rows[r.id].text = line.text()
            rec = w.ownership.record(r.id)
            if rec is not None and self._owners.get(r.id, rec.owner) != rec.owner:
                # records come from the robot's authority only (the ownership replica checks): trusted
                self.log.push(f"trusted · ownership {r.id}: {self._owners[r.id] or 'nobody'} -> {rec.owner or 'nobody'} (epoch {rec.epoch})")
            if rec is not None:
                self._owners[r.id] = rec.owner
        self.sel_label.text = f"selected: {self.selected}" if self.selected else "no robot"
        if self.arm is not None:
            self._refresh_arm()
        if self.base is not None:
            self._refresh_base()
        self._refresh_view()
        self._refresh_events()

    def _refresh_arm(self) -> None:
        arm = self.arm
        mine = arm.can_command
        rec = arm.record
        who = "you" if mine and rec is not None else (rec.owner or "nobody") if rec is not None else "?"
        self.arm_title.text = f"arm {arm.id} ({arm.type}) · owner: {who}" + ("" if mine else " · controls disabled")
        for c in self.arm_controls:
            c.set_enabled(mine)
        js = arm.joints
        if js is not None and (not mine or not self._synced):
            self._set_sliders(js)  # the sliders follow the robot until you own it: a first change moves one joint
            self._synced = mine
        moved = self.target_obj.pose if self.target_obj is not None else None
        if moved is not None:  # a scene object: whoever moved it last, this page included
            self.target = np.asarray(moved.position, dtype=float)
        elif self.target is None and arm.flange is not None:
            self.target = np.asarray(arm.flange.position, dtype=float)
        if self.target is not None:
            self.target_label.text = "({:.3f}, {:.3f}, {:.3f}) m".format(*self.target)

    def _refresh_base(self) -> None:
        b = self.base
        mine = b.can_command
        rec = b.record
        who = "you" if mine and rec is not None else (rec.owner or "nobody") if rec is not None else "?"
        self.base_title.text = f"base {b.id} ({b.type}) · owner: {who}" + ("" if mine else " · controls disabled")
        for c in self.base_controls:
            c.set_enabled(mine)
        xy, pose = b.xy_theta, b.pose
        text = f"pose ({xy[0]:+.2f}, {xy[1]:+.2f}, {math.degrees(xy[2]):+.0f}°)" if xy else "pose -"
        if pose is not None:
            text += f" · v {math.hypot(pose.linear[0], pose.linear[1]):.2f} m/s"
            stamp = str(pose.header.wall_ns // 1_000_000)
            if self.base_state.props.get("data-pose-wall-ms") != stamp:  # the page's own lag: Date.now() against it
                self.base_state.props(f"data-pose-wall-ms={stamp}")
        v, om = self.driver.twist()
        self.base_state.text = text + f" · speed {self.driver.level} · command v {v:+.2f} w {om:+.2f}"
        if self.goal is not None and xy is not None:
            self.goal_label.text = f"goal ({self.goal[0]:.2f}, {self.goal[1]:.2f}) · distance {math.hypot(self.goal[0] - xy[0], self.goal[1] - xy[1]):.2f} m"

    def _refresh_view(self) -> None:
        w = self.world
        grid = w.latest.get(keys.map_key(w.name, keys.user_map("map", w.user))) or self.grid or w.latest.get(keys.map_key(w.name, "map"))
        if grid is not None and id(grid) != self._map_seq:
            self._map_seq = id(grid)
            self.view.set_source(topview.data_url(topview.grid_png(grid.cells, grid.resolution, grid.origin, self.frame)))
        target = (float(self.target[0]), float(self.target[1])) if self.target is not None else None
        self.view.content = state.view_svg(w, self.entries, self.handles, self.poses, self.frame, self.boxes,
                                           base_id=self.base.id if self.base else None,
                                           selected={self.selected} if self.selected else set(), goal=self.goal, target=target)

    def _refresh_events(self) -> None:
        w = self.world
        mark = w.event_mark()
        if mark != self._events_seen:
            new = min(mark - self._events_seen, 50)
            self._events_seen = mark
            for ev, trusted in w.recent_events(new):
                self.log.push(event_line(ev, trusted))
        gone = w.robots_gone
        if len(gone) != self._gone_seen:
            for rid in gone[self._gone_seen:]:
                self.log.push(f"robot {rid} gone: its sim peer left")
            self._gone_seen = len(gone)
        if not w.world_alive:
            self._say(f"WORLD GONE: no sim peer of {w.name!r} (waiting for one)")


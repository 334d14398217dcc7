"""The arm panel of a page: joint sliders in degrees, speed, Stop, Reset, the IK target with its nudges, the live
IK solution and Apply IK. Enabled only while the page's student owns the arm."""

from __future__ import annotations

import asyncio
import math
from typing import TYPE_CHECKING, Any

import numpy as np
from nicegui import ui
from user_peer.console.workers import CALLS, off_loop

from fabric.text import one_line
from user_peer.console.panel import PanelHooks
from user_peer.errors import FabricUserError

if TYPE_CHECKING:
    from user_peer.console.page import ConsolePage

__all__ = ["ArmPanel", "NUDGE_STEPS", "make", "synchronised_speeds"]

NUDGE_STEPS = {"1 mm": 0.001, "1 cm": 0.01, "5 cm": 0.05}


def synchronised_speeds(q_from: np.ndarray, q_to: np.ndarray, max_speed: np.ndarray) -> tuple[np.ndarray, float]:
    """The paper's synchronised move (Eq. 3-7): every joint arrives together, the slowest at its speed limit.
    Returns each joint's speed (rad/s) and the move's duration (s)."""
    d = np.abs(np.asarray(q_to, float) - np.asarray(q_from, float))
    t = float(np.max(d / np.maximum(np.asarray(max_speed, float), 1e-9), initial=0.0))
    return (d / t if t > 0 else np.zeros_like(d)), t


def make(page: "ConsolePage", info: Any) -> "ArmPanel":
    """The page's arm panel, with the world's IK target sphere when its scene has one (``info``: the world's
    description)."""
    target = next((o for o in info.objects if o.kind == "ik_target"), None)
    return ArmPanel(
        page,
        page.world.object(target.id) if target else None,
        np.asarray(target.position, dtype=float) if target else None,
    )


class ArmPanel(PanelHooks):
    """One card of the page, for its arm ``page.robots["arm"]`` (a :class:`~.panel.Panel`)."""

    def __init__(self, page: "ConsolePage", target_obj: Any, target: np.ndarray | None) -> None:
        self.page = page
        self.target_obj = target_obj  # the IK target sphere (a scene object: anyone moves it)
        self.target = target
        self.ik_q: np.ndarray | None = None
        self._ik_task: asyncio.Task | None = None
        self._syncing = False
        self.synced = False  # the sliders took the owner's joints once: from then on they are hers to move

    @property
    def arm(self) -> Any:
        return self.page.robots["arm"]

    async def switch(self, robot: Any) -> None:
        """Another arm shown: the sliders take its joints."""
        self.synced = False

    def build(self) -> None:
        with ui.card().classes("full-width"):
            self.title = ui.label("").classes("text-subtitle1").props('role="heading" aria-level="2"')
            self.sliders: list[Any] = []
            self._joints: tuple[str, ...] = ()
            self.joints_box = ui.column().classes("full-width gap-0")
            self._build_sliders()
            with ui.row().classes("full-width items-center no-wrap"):
                ui.label("Speed").style("width: 4rem")
                self.speed = (
                    ui.slider(min=0.05, max=1.0, step=0.05, value=0.5)
                    .props('label-always aria-label="Speed scale"')
                    .classes("full-width")
                )
            with ui.row():
                stop = ui.button(
                    "Stop", color="negative", on_click=lambda: self.page.call(f"stop {self.arm.id}", self.arm.stop)
                )
                reset = ui.button("Reset", color="warning", on_click=self._reset)
            with ui.row().classes("items-center"):
                ui.label("IK target")
                self.target_label = ui.label("")
                self.step = ui.select(list(NUDGE_STEPS), value="1 cm", label="Nudge step").props(
                    'aria-label="Nudge step" dense'
                )
            nudges = []
            with ui.row():
                for axis, name in enumerate("xyz"):
                    for sign, txt in ((-1, "−"), (1, "+")):
                        nudges.append(
                            ui.button(f"{name}{txt}", on_click=lambda _, a=axis, s=sign: self._nudge(a, s)).props(
                                f'dense aria-label="{name} {"plus" if sign > 0 else "minus"}"'
                            )
                        )
            # two lines high even when short: the map's row under this panel must not move under the mouse
            self.ik_label = ui.label("IK: move the target").style("min-height: 2.8rem")
            apply = ui.button("Apply IK", on_click=self._apply_ik)
        self._buttons = [self.speed, stop, reset, apply, *nudges]

    @property
    def controls(self) -> list[Any]:
        """What only the owner may use: the selected arm's sliders, the speed and the buttons."""
        return [*self.sliders, *self._buttons]

    def _build_sliders(self) -> None:
        """One slider per joint of the arm shown: rebuilt when the page shows an arm of other joints (a lab's
        7-joint Panda after the 6-joint Meca500)."""
        e = self.arm.entry
        self.joints_box.clear()
        self.sliders = []
        with self.joints_box:
            for i, name in enumerate(e.joint_names):
                lo = math.degrees(e.lower[i]) if i < len(e.lower) else -180.0
                hi = math.degrees(e.upper[i]) if i < len(e.upper) else 180.0
                with ui.row().classes("full-width items-center no-wrap"):
                    ui.label(f"J{i + 1}").style("width: 2rem")
                    # the zero pose clamped into the range: a joint whose range leaves out 0 (the Panda's J4)
                    s = (
                        ui.slider(
                            min=round(lo, 1),
                            max=round(hi, 1),
                            step=0.5,
                            value=min(max(0.0, round(lo, 1)), round(hi, 1)),
                            on_change=self._slider_moved,
                        )
                        .props(f'label-always aria-label="J{i + 1} ({name}) degrees"')
                        .classes("full-width")
                    )
                    self.sliders.append(s)
        self._joints = tuple(e.joint_names)
        self.synced = False

    # ------------------------------------------------------------------ actions

    def _slider_moved(self) -> None:
        if self._syncing or self.arm is None or not self.arm.can_command:
            return
        q = np.radians([s.value for s in self.sliders])
        asyncio.ensure_future(
            self.page.call(
                f"joints {np.round(np.degrees(q), 1).tolist()} deg",
                self.arm.move_joints,
                q,
                wait=False,
                speed_scale=float(self.speed.value),
            )
        )

    async def _reset(self) -> None:
        if await self.page.call(f"reset {self.arm.id}", self.arm.reset, confirm=False) is not self.page.FAILED:
            self.synced = False

    def _nudge(self, axis: int, sign: int) -> None:
        if self.target is None:
            p = self.arm.flange
            if p is None:
                self.page.say("no target yet: the arm has sent no flange pose")
                return
            self.target = np.asarray(p.position, dtype=float)
        moved = self.target.copy()
        moved[axis] += sign * NUDGE_STEPS[self.step.value]
        self.move_target(moved)

    def move_target(self, xyz: np.ndarray) -> None:
        """The IK target to ``xyz`` (a nudge, or a drag on the view): the scene's sphere moves for every page, and
        the IK solution for it follows."""
        self.target = np.asarray(xyz, dtype=float).copy()
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
                q, why = await off_loop(CALLS, self.arm.ik, goal), ""
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
                v, t = synchronised_speeds(
                    js, self.ik_q, np.asarray(self.arm.entry.max_speed) * float(self.speed.value)
                )
                speeds = f" · speeds {np.round(np.degrees(v), 1).tolist()} deg/s ({t:.2f} s)"
            self.ik_label.text = f"IK: {np.round(np.degrees(self.ik_q), 1).tolist()} deg{speeds}"
            return

    async def _apply_ik(self) -> None:
        if self.ik_q is None:
            self.page.say("Apply IK: no IK solution for the target yet")
            return
        q = self.ik_q
        if (
            await self.page.call(
                f"apply IK {np.round(np.degrees(q), 1).tolist()} deg",
                self.arm.move_joints,
                q,
                wait=False,
                speed_scale=float(self.speed.value),
            )
            is not self.page.FAILED
        ):
            self._set_sliders(q)

    def _set_sliders(self, q: np.ndarray) -> None:
        self._syncing = True
        try:
            for s, v in zip(self.sliders, q):
                s.value = round(math.degrees(float(v)), 1)
        finally:
            self._syncing = False

    # ------------------------------------------------------------------ refresh

    def refresh(self) -> None:
        arm = self.arm
        if tuple(arm.entry.joint_names) != self._joints:
            self._build_sliders()
        mine = arm.can_command
        rec = arm.record
        who = "you" if mine and rec is not None else (rec.owner or "nobody") if rec is not None else "?"
        live = (
            arm.id in self.page.world.following.robots
        )  # else its joints are what was kept when the page let go of it
        self.title.text = one_line(
            f"arm {arm.id} ({arm.type}) · owner: {who}"
            + ("" if mine else " · controls disabled")
            + ("" if live else f" · click {arm.id} to follow its joints"),
            300,
        )
        for c in self.controls:
            c.set_enabled(mine)
        js = arm.joints if live else None
        if js is not None and (not mine or not self.synced):
            self._set_sliders(js)  # the sliders follow the robot until you own it: a first change moves one joint
            self.synced = mine
        moved = self.target_obj.pose if self.target_obj is not None else None
        if moved is not None:  # a scene object: whoever moved it last, this page included
            self.target = np.asarray(moved.position, dtype=float)
        elif self.target is None and live and arm.flange is not None:
            self.target = np.asarray(arm.flange.position, dtype=float)
        if self.target is not None:
            self.target_label.text = "({:.3f}, {:.3f}, {:.3f}) m".format(*self.target)

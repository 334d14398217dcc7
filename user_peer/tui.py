"""``robofabric user``: the paper's user interface in a terminal (works over SSH).

One slider per arm joint (each change sends a joint target at the arm speed that
``[``/``]`` pick), stop and reset, arrow keys to drive the mobile base (``1``-``3`` pick
the speed, space stops; while a joint slider has the focus ←/→ move that slider, and
``escape`` gives the arrows back to the base), buttons to request, queue for or release
each robot. Controls are disabled while this user does not own the robot, and the owner's
name (and this user's place in its queue) is shown. Live joints, a scan
preview, and ownership, lease and latency status refresh ten times a second.

The app takes :class:`~user_peer.api.Arm` / :class:`~user_peer.api.Base`
objects, so tests drive it with Textual's pilot against a real world.
"""

from __future__ import annotations

import math

import numpy as np
from textual.app import App, ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.content import Content
from textual.css.query import NoMatches
from textual.widgets import Button, Footer, Header, Label, Sparkline, Static

from fabric.text import escape
from user_peer.api import Arm, Base, World
from user_peer.errors import FabricUserError
from user_peer.event_log import describe
from user_peer.slider import JointSlider

__all__ = ["UserApp", "SPEEDS", "ARM_SPEEDS", "event_line"]

SPEEDS = {1: (0.2, 0.4), 2: (0.5, 0.8), 3: (1.0, 1.5)}
"""Speed level -> (forward m/s, turn rad/s) for the arrow keys."""

ARM_SPEEDS = (0.1, 0.25, 0.5, 1.0)
"""The arm's ``speed_scale`` steps (a fraction of each joint's speed limit), ``[`` slower, ``]`` faster."""


def _age_ms(robot, stream: str) -> float | None:
    """Milliseconds since the latest message of a stream arrived here. Local time only: the sim's
    header clock may be seconds off ours on another machine."""
    age = robot.age(stream)
    return None if age is None else age * 1e3


def plain(text: str) -> Content:
    """Text for a label, never parsed as markup, its control characters escaped: names, reasons and events
    come from the network (an owner called ``[/x]`` raised MarkupError in the refresh timer and ended the
    app; one with an escape sequence could drive the terminal)."""
    return Content(escape(text))


def event_line(ev, trusted: bool) -> str:
    """The status line's latest event, one line (:func:`~user_peer.event_log.describe`); one the robot's
    authority did not send (a decode report, which any login may write) starts with its mark, ahead of any of
    its writer's text: its kind, user and object are only its writer's say-so, and a long reason cannot push
    the mark out of sight."""
    return f"event {describe(ev)}" if trusted else f"unverified, display only · event {describe(ev)}"


class UserApp(App):
    CSS = """
    Screen { layout: vertical; }
    .panel { border: round $primary; padding: 0 1; height: auto; }
    .row { height: auto; }
    .row Button { margin: 0 1 0 0; min-width: 10; }
    #status { height: auto; color: $text-muted; }
    #scan { height: 4; }
    .owner { padding: 0 1; }
    """

    BINDINGS = [
        Binding("up", "drive(1, 0)", "forward", priority=True),
        Binding("down", "drive(-1, 0)", "back", priority=True),
        # not priority: a focused joint slider takes left/right first (docs/user_api.md), the base gets the rest
        Binding("left", "drive(0, 1)", "turn left"),
        Binding("right", "drive(0, -1)", "turn right"),
        Binding("escape", "unfocus", "arrows drive", show=False),
        Binding("space", "halt", "stop base", priority=True),
        Binding("1", "speed(1)", "slow"),
        Binding("2", "speed(2)", "medium"),
        Binding("3", "speed(3)", "fast"),
        Binding("left_square_bracket", "arm_speed(-1)", "arm slower"),
        Binding("right_square_bracket", "arm_speed(1)", "arm faster"),
        Binding("q", "quit", "quit"),
    ]

    def __init__(
        self, world: World, *, arm: Arm | None = None, base: Base | None = None, refresh_hz: float = 10.0
    ) -> None:
        super().__init__()
        self.world = world
        self.arm = arm
        self.base = base
        self.refresh_hz = refresh_hz
        self.speed_level = 1
        self.arm_speed = ARM_SPEEDS[-1]
        self.v = 0.0
        self.omega = 0.0
        self.message = ""
        self.sent = 0
        self._synced = False
        self.title = f"robofabric · {world.name} · {world.user}"

    # ------------------------------------------------------------------ layout

    def compose(self) -> ComposeResult:
        yield Header()
        if self.arm is not None:
            e = self.arm.entry
            with Vertical(classes="panel", id="arm-panel"):
                yield Label(plain(f"arm {self.arm.id} ({self.arm.type}): [ ] arm speed"), id="arm-title")
                yield Label("", id="arm-speed")
                yield Label("", id="arm-owner", classes="owner")
                for i, name in enumerate(e.joint_names):
                    lo = e.lower[i] if i < len(e.lower) else -math.pi
                    hi = e.upper[i] if i < len(e.upper) else math.pi
                    yield JointSlider(name, lo, hi, id=f"joint-{i}")
                with Horizontal(classes="row"):
                    yield Button("Request arm", id="arm-request", variant="primary")
                    yield Button("Queue", id="arm-queue")
                    yield Button("Release", id="arm-release")
                    yield Button("Stop", id="arm-stop", variant="error")
                    yield Button("Reset", id="arm-reset", variant="warning")
        if self.base is not None:
            with Vertical(classes="panel", id="base-panel"):
                yield Label(
                    plain(f"base {self.base.id} ({self.base.type}): arrows drive, 1-3 speed, space stops"),
                    id="base-title",
                )
                yield Label("", id="base-owner", classes="owner")
                yield Label("", id="base-state")
                yield Sparkline([0.0], id="scan")
                with Horizontal(classes="row"):
                    yield Button("Request base", id="base-request", variant="primary")
                    yield Button("Queue", id="base-queue")
                    yield Button("Release", id="base-release")
                    yield Button("Stop", id="base-stop", variant="error")
        yield Static("", id="status")
        yield Footer()

    def on_mount(self) -> None:
        self.set_interval(1.0 / self.refresh_hz, self.refresh_view)
        self.set_interval(0.2, self.keep_driving)
        self.refresh_view()

    # ------------------------------------------------------------------ actions

    def _try(self, what: str, fn, *args, **kw):
        try:
            out = fn(*args, **kw)
            self.message = f"{what}: ok"
            return out
        except FabricUserError as exc:
            self.message = f"{what}: {exc.reason}"
        except Exception as exc:  # never let a network hiccup kill the UI
            self.message = f"{what}: {type(exc).__name__}: {exc}"
        return None

    def on_button_pressed(self, event: Button.Pressed) -> None:
        bid = event.button.id or ""
        robot = self.arm if bid.startswith("arm-") else self.base
        if robot is None:
            return
        action = bid.split("-", 1)[1]
        if action == "request":
            self._try(f"request {robot.id}", robot.request, timeout=3.0)
        elif action == "queue":
            place = self._try(f"queue for {robot.id}", robot.queue, timeout=3.0)
            if place is not None:
                self.message = f"queue for {robot.id}: " + (f"place {place}" if place else "granted at once")
        elif action == "release":
            self._try(f"release {robot.id}", robot.release)
        elif action == "stop":
            if robot is self.base:
                self.v = self.omega = 0.0
            self._try(f"stop {robot.id}", robot.stop)
        elif action == "reset":
            self._try(f"reset {robot.id}", robot.reset)
            if self.message.endswith(": ok"):
                for s in self.query(JointSlider):
                    s.set_value(0.0, notify=False)
        self.refresh_view()

    def on_joint_slider_changed(self, event: JointSlider.Changed) -> None:
        if self.arm is None:
            return
        q = np.array([s.value for s in self.query(JointSlider)])
        if (
            self._try(
                f"{event.slider.joint} -> {math.degrees(event.value):.1f} deg",
                self.arm.move_joints,
                q,
                wait=False,
                speed_scale=self.arm_speed,
            )
            is not None
        ):
            self.sent += 1

    def action_arm_speed(self, step: int) -> None:
        """One ``speed_scale`` step slower or faster for the arm's next joint targets."""
        i = min(max(ARM_SPEEDS.index(self.arm_speed) + step, 0), len(ARM_SPEEDS) - 1)
        self.arm_speed = ARM_SPEEDS[i]
        self.message = f"arm speed {self.arm_speed:.0%} of its joints' limits"

    def action_unfocus(self) -> None:
        """Leave the focused slider, so the arrow keys drive the base again."""
        self.set_focus(None)

    def action_speed(self, level: int) -> None:
        self.speed_level = level
        v, w = SPEEDS[level]
        self.v = math.copysign(v, self.v) if self.v else 0.0
        self.omega = math.copysign(w, self.omega) if self.omega else 0.0
        self.message = f"speed {level}: {v} m/s, {w} rad/s"

    def action_drive(self, forward: int, turn: int) -> None:
        if self.base is None:
            return
        v, w = SPEEDS[self.speed_level]
        if forward:
            self.v = 0.0 if self.v * forward < 0 else forward * v
        if turn:
            self.omega = 0.0 if self.omega * turn < 0 else turn * w
        self._send_twist()

    def action_halt(self) -> None:
        self.v = self.omega = 0.0
        if self.base is not None:
            self._send_twist()

    def _send_twist(self) -> None:
        if (
            self.base is not None
            and self._try(f"drive v={self.v:+.2f} w={self.omega:+.2f}", self.base.twist, self.v, self.omega) is not None
        ):
            self.sent += 1

    def keep_driving(self) -> None:
        """The base keeps the last arrow's twist while this app runs and owns it: the world's twist keeper
        repeats it against the sim's deadman (:meth:`user_peer.mobile_base.Base.twist`). When the keeper gave it up
        (the base was lost, released or stopped) the command shown goes back to zero."""
        if self.base is not None and (self.v or self.omega) and not self.world.twists.holding(self.base.id):
            self.v = self.omega = 0.0

    # ------------------------------------------------------------------ live view

    def _owner_text(self, robot) -> str:
        rec = robot.record
        if rec is None:
            return "owner: no ownership record (a world without ownership, or the authority has not answered yet)"
        mine = rec.owner == self.world.user
        who = "you" if mine else (rec.owner or "nobody")
        text = f"owner: {who} · epoch {rec.epoch} · {rec.state}"
        if rec.queue:
            text += f" · waiting: {', '.join(rec.queue)}"
        place = robot.queue_place
        if place is not None:
            text += f" · you are #{place} in the queue"
        if not mine:
            text += " · controls disabled until you own it"
        return text

    def _may_queue(self, robot) -> bool:
        """Queueing makes sense for a robot someone else owns (moving or not) that we do not wait for yet."""
        rec = robot.record
        return rec is not None and bool(rec.owner) and rec.owner != self.world.user and robot.queue_place is None

    def refresh_view(self) -> None:
        try:
            self._refresh_view()
        except NoMatches:
            pass  # a timer tick while the screen is still mounting or already torn down: nothing to update

    def world_status(self) -> str | None:
        """The status line's warning when the world is gone (its last sim peer left: died, or cut
        off), else None. Read from the world on every refresh, so it clears when a sim is back."""
        if not self.world.world_alive:
            return f"WORLD GONE: no sim peer of {self.world.name!r} (waiting for one)"
        return None

    def _refresh_view(self) -> None:
        status = []
        gone = self.world_status()
        if gone:
            status.append(gone)
        if self.arm is not None:
            mine = self.arm.can_command
            self.query_one("#arm-owner", Label).update(plain(self._owner_text(self.arm)))
            js = self.arm.joint_state
            for i, s in enumerate(self.query(JointSlider)):
                s.disabled = not mine
                if js is not None and i < len(js.q):
                    s.actual = float(js.q[i])
                    if not mine or not self._synced:
                        # Targets follow the robot until you own it, so a first change moves one joint only.
                        s.set_value(float(js.q[i]), notify=False)
            if js is not None and mine:
                self._synced = True
            elif not mine:
                self._synced = False
            for bid in ("#arm-stop", "#arm-reset", "#arm-release"):
                self.query_one(bid, Button).disabled = not mine
            self.query_one("#arm-request", Button).disabled = mine
            self.query_one("#arm-queue", Button).disabled = not self._may_queue(self.arm)
            self.query_one("#arm-speed", Label).update(f"arm speed {self.arm_speed:.0%} of the joint limits")
            lat = _age_ms(self.arm, "joints")
            status.append(f"arm joints age {lat:.0f} ms" if lat is not None else "arm: no joints yet")
        if self.base is not None:
            mine = self.base.can_command
            self.query_one("#base-owner", Label).update(plain(self._owner_text(self.base)))
            for bid in ("#base-stop", "#base-release"):
                self.query_one(bid, Button).disabled = not mine
            self.query_one("#base-request", Button).disabled = mine
            self.query_one("#base-queue", Button).disabled = not self._may_queue(self.base)
            pose = self.base.pose
            xy = self.base.xy_theta
            state = f"pose ({xy[0]:+.2f}, {xy[1]:+.2f}, {math.degrees(xy[2]):+.0f}°)" if xy else "pose -"
            if pose is not None:
                state += f" · v {math.hypot(pose.linear[0], pose.linear[1]):.2f} m/s · w {pose.angular[2]:+.2f} rad/s"
            state += f" · command v {self.v:+.2f} w {self.omega:+.2f} · speed {self.speed_level}"
            self.query_one("#base-state", Label).update(plain(state))
            scan = self.base.scan
            if scan is not None:
                self.query_one("#scan", Sparkline).data = [float(r) for r in scan.ranges[::-1]]
            lat = _age_ms(self.base, "pose")
            status.append(f"base pose age {lat:.0f} ms" if lat is not None else "base: no pose yet")
        status.append(f"sent {self.sent}")
        recent = self.world.recent_events(1)
        if recent:
            status.append(event_line(*recent[-1]))
        if self.message:
            status.append(self.message)
        self.query_one("#status", Static).update(plain(" · ".join(status)))

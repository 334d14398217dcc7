"""A page's 3D view (NiceGUI's ``ui.scene``, three.js): the arms at their live joints, the bases with the selected
base's scan, the scene's walls and shelves, and the IK target, dragged in 3D.

The mouse orbits (left), pans (right) and zooms (wheel); two buttons put the camera on the arm or over the whole
world. The ground carries a grid of 1 m squares and the world's axes (x red, y green, z blue, 1 m long). The IK
target is the orange sphere: dragged, it moves on the horizontal plane of its height (the drag's constraint), and
the height field below the view sets that height. A dropped target goes where a nudge goes
(:meth:`~user_peer.console.arm_panel.ArmPanel.move_target`): the scene's object for every page, and the IK solution
follows; Apply IK reaches it.

Light: the static parts are sent once; an arm's links are moved only when its joints changed, a base when its pose
changed (NiceGUI sends an object's move only when it differs), at the pages' 5 Hz redraw, and a redraw's moves go
down the page's socket as one message (NiceGUI sends each move as a message of its own: 32 moving bases were 64 a
page a redraw). A base's place is worked out once a tick for every page that holds the same pose
(:meth:`~user_peer.console.feed.Decoded.derived`), and a scan's points with numpy, not a list per ray.
"""

from __future__ import annotations

import contextlib
import math
from typing import TYPE_CHECKING, Any, ContextManager

import numpy as np
from nicegui import ui

from fabric.interfaces import yaw_from_quaternion
from robots.kinds import facts
from user_peer.console import state, topview
from user_peer.console.scene3d import arm_points, scene_boxes3d, segment_pose

if TYPE_CHECKING:
    from user_peer.console.page import ConsolePage

__all__ = ["View3D", "LINK_RADIUS", "TARGET_RADIUS"]

LINK_RADIUS = 0.015
"""An arm link's radius (m) as drawn: a Meca500 is 0.3 m long."""
TARGET_RADIUS = 0.02
"""The IK target sphere's radius (m): large enough to grab with the mouse when the camera is on the arm."""
BASE_SIZE = (0.45, 0.35, 0.2)
"""A mobile base as drawn: a box (m)."""


class View3D:
    """The 3D view of one page."""

    def __init__(self, page: "ConsolePage") -> None:
        self.page = page
        self.scene: Any = None
        self.links: dict[str, list[Any]] = {}  # an arm's link cylinders, made when its joints first come
        self.bases: dict[str, Any] = {}
        self.target: Any = None
        self.scan: Any = None
        self.height: Any = None
        self._syncing = False
        self._z: float | None = None
        self._looked: str | None = None  # the arm the camera was last put on
        self._coloured: dict[str, object] = {}  # base -> the ownership record its colour comes from

    def build(self) -> None:
        page = self.page
        info = page.world.info()
        self.spawn = {r.id: tuple(float(v) for v in r.pose) for r in info.robots}
        ui.label("3D view").classes("text-subtitle1").props('role="heading" aria-level="2"')
        self.scene = ui.scene(
            width=480,
            height=360,
            grid=(40, 40),
            on_drag_end=self._dropped,
            background_color="#f8f9fa",
            fps=page.console.view_fps,
        )
        # a group with a name: a div named but with no role is what axe calls aria-prohibited-attr, reported as
        # serious while three.js has not yet put its canvas in it (a loaded box's axe run saw the empty div)
        self.scene.classes("rf-scene3d").props(
            'role="group" aria-label="3D view: drag to orbit, right-drag to pan, wheel to zoom; '
            'drag the orange sphere to move the IK target"'
        )
        with self.scene:
            for b in scene_boxes3d(info.scene):
                self.scene.box(*b.size).move(*b.center).rotate_R([list(r) for r in b.R]).material(b.color, 0.5)
            self.scene.axes_helper(1.0)
            self.scene.text("1 m grid · x red, y green, z blue", "font-size: 11px; color: #495057").move(0.0, -0.3, 0.0)
            for e in page.entries:
                sx, sy, sz, yaw = self.spawn.get(e.id, (0.0, 0.0, 0.0, 0.0))
                if facts(e.kind).base:
                    self.bases[e.id] = (
                        self.scene.box(*BASE_SIZE).material(topview.COLORS["free"]).move(sx, sy, BASE_SIZE[2] / 2)
                    )
                else:
                    self.scene.box(0.12, 0.12, 0.02).material("#495057").move(sx, sy, sz + 0.01)
                self.scene.text(e.id, "font-size: 12px; color: #212529").move(sx, sy, sz + 0.45)
            self.scan = self.scene.point_cloud([], [], point_size=0.04)
            self.target = self.scene.sphere(TARGET_RADIUS).material("#f59f00").draggable().with_name("ik-target")
            self.target.visible(False)
        with ui.row().classes("items-center"):
            self.height = (
                ui.number("IK target height z (m)", step=0.01, format="%.3f", on_change=self._height_set)
                .props('aria-label="IK target height z in metres" dense')
                .style("width: 12rem")
            )
            ui.button("View the arm", on_click=self.look_at_arm).props("flat dense no-caps")
            ui.button("View the whole world", on_click=self.look_at_world).props("flat dense no-caps")
        self.look_at_arm()

    # ------------------------------------------------------------------ camera

    def look_at_arm(self) -> None:
        """The camera 1 m from the page's arm (or the first robot), looking at its middle from above and aside."""
        page, arm = self.page, self.page.robots.get("arm")
        rid = arm.id if arm is not None else (page.entries[0].id if page.entries else None)
        self._looked = arm.id if arm is not None else None
        sx, sy, sz, _ = self.spawn.get(rid, (0.0, 0.0, 0.0, 0.0)) if rid else (0.0, 0.0, 0.0, 0.0)
        self.scene.move_camera(sx + 0.55, sy - 0.75, sz + 0.6, sx, sy, sz + 0.15, duration=0)

    def look_at_world(self) -> None:
        """The camera over the whole world (the 2D view's frame), looking down at it at a slant."""
        f = self.page.frame
        cx, cy, side = (f.xmin + f.xmax) / 2, (f.ymin + f.ymax) / 2, max(f.xmax - f.xmin, f.ymax - f.ymin)
        self.scene.move_camera(cx, cy - 0.6 * side, 0.8 * side, cx, cy, 0.0, duration=0)

    # ------------------------------------------------------------------ the target

    def _dropped(self, e: Any) -> None:
        """The target dropped at (x, y): it keeps its height (the drag is on its plane)."""
        panel = self.page.panels.get("arm")
        if panel is None or e.object_name != "ik-target" or panel.target is None:
            return
        xyz = np.array([float(e.x), float(e.y), float(panel.target[2])])
        panel.move_target(xyz)
        self.page.say("IK target dragged to ({:.3f}, {:.3f}, {:.3f})".format(*xyz))
        self.page.refresh()

    def _height_set(self) -> None:
        panel = self.page.panels.get("arm")
        if self._syncing or panel is None or panel.target is None or self.height.value is None:
            return
        z = float(self.height.value)
        if abs(z - float(panel.target[2])) > 1e-6:
            panel.move_target(np.array([float(panel.target[0]), float(panel.target[1]), z]))
            self.page.say(f"IK target height set to {z:.3f} m")

    def _show_target(self) -> None:
        panel = self.page.panels.get("arm")
        t = panel.target if panel is not None else None
        if t is None:
            return
        self.target.visible(True)
        self.target.move(float(t[0]), float(t[1]), float(t[2]))
        z = round(float(t[2]), 4)
        if z != self._z:  # the drag stays on the target's height
            self._z = z
            self.scene._props["drag-constraints"] = f"z = {z}"
            self.scene.update()
            self._syncing = True
            try:
                self.height.value = z
            finally:
                self._syncing = False

    # ------------------------------------------------------------------ refresh

    def _batched(self) -> ContextManager[Any]:
        """The scene's calls made meanwhile, sent as one message (NiceGUI's own batching, which its scene uses when
        a browser's scene starts; a private method of NiceGUI 3: without it, one message a call as before)."""
        batch = getattr(self.scene, "_batch_calls", None)
        return batch() if callable(batch) else contextlib.nullcontext()

    def refresh(self, poses: dict[str, bytes]) -> None:
        """Move what moved: the followed arms' links, the bases, the selected base's scan, the target; one message."""
        with self._batched():
            self._refresh(poses)

    def _refresh(self, poses: dict[str, bytes]) -> None:
        page, w, arm = self.page, self.page.world, self.page.robots.get("arm")
        if arm is not None and arm.id != self._looked:  # another arm selected: the camera goes to it
            self.look_at_arm()
        decoded = page.console.decoded
        for e in page.entries:
            if facts(e.kind).base:
                if e.id not in page.handles and e.id in poses:  # drawn from the shared feed: placed once a tick
                    self._place(e.id, decoded.derived(e.id, poses[e.id], "3d", base_place))
                else:
                    self._place(e.id, base_place(state._pose(page.handles, poses, e.id, decoded)))
            elif e.id in page.handles:
                js = page.handles[e.id].latest("joints")
                if js is not None and e.id in self.spawn:
                    self._arm(e.id, arm_points(e.type, js.q, self.spawn[e.id]))
        for rid, box in self.bases.items():
            rec = w.ownership.record(rid)
            if rec is not None and rec is self._coloured.get(rid):
                continue  # coloured from this very record already
            self._coloured[rid] = rec
            owner = rec.owner if rec is not None else ""
            box.material(
                topview.COLORS["mine"]
                if owner == w.user
                else topview.COLORS["other"]
                if owner
                else topview.COLORS["free"]
            )
        self._scan()
        self._show_target()

    def _arm(self, rid: str, pts: np.ndarray) -> None:
        if len(pts) < 2:
            return
        links = self.links.get(rid)
        if links is None:
            with self.scene:
                links = self.links[rid] = [
                    self.scene.cylinder(LINK_RADIUS, LINK_RADIUS, 1.0).material("#1c7ed6") for _ in range(len(pts) - 1)
                ]
        for cyl, a, b in zip(links, pts[:-1], pts[1:]):
            mid, R, n = segment_pose(a, b)
            cyl.move(*(round(float(v), 4) for v in mid)).rotate_R([[round(float(v), 4) for v in row] for row in R])
            cyl.scale(1.0, max(round(n, 4), 1e-4), 1.0)

    def _place(self, rid: str, place: tuple[tuple[float, float, float], list[list[float]]] | None) -> None:
        if place is None or rid not in self.bases:
            return
        self.bases[rid].move(*place[0]).rotate_R(place[1])

    def _scan(self) -> None:
        base = self.page.robots.get("mobile")
        if base is None:
            return
        s, p = base.latest("scan"), base.latest("pose")
        if s is None or p is None:
            return
        pts = topview.scan_points(
            float(p.position[0]),
            float(p.position[1]),
            yaw_from_quaternion(p.quaternion),
            s.angle_min,
            s.angle_increment,
            s.ranges,
            s.range_max,
        )
        key = (id(s), id(p))
        if getattr(self, "_scan_key", None) != key:
            self._scan_key = key
            xyz = np.column_stack([np.round(pts, 3), np.full(len(pts), 0.15)])
            self.scan.set_points(xyz.tolist(), [[0.94, 0.24, 0.24]] * len(pts))


def base_place(pose: Any) -> tuple[tuple[float, float, float], list[list[float]]] | None:
    """Where a base's box goes in the 3D view: its centre (mm) and its rotation (yaw to a mrad), from its pose; None
    without one. Shared between the pages that hold the same pose (never changed in place)."""
    if pose is None:
        return None
    yaw = round(yaw_from_quaternion(pose.quaternion), 3)
    centre = (round(float(pose.position[0]), 3), round(float(pose.position[1]), 3), BASE_SIZE[2] / 2)
    c, s = math.cos(yaw), math.sin(yaw)
    return centre, [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]  # a turn about z, as ui.scene's rotate(0, 0, yaw)

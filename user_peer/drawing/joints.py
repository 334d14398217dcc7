"""Joint states, whoever sends them: an arm's joint angles and speeds, a base's wheel angles (their own plot,
apart from the arms'); an arm's 3D pose follows from the same window (:class:`~user_peer.drawing.arm.ArmDrawer`)."""

from __future__ import annotations

import numpy as np
import rerun as rr

from fabric.interfaces import JointState
from robots.kinds import facts
from user_peer.drawing.arm import ArmDrawer
from user_peer.drawing.canvas import Canvas, Rows
from user_peer.drawing.robots import RobotDrawing
from user_peer.rerun_columns import SCALARS, scalars, send

__all__ = ["JointDrawer"]


class JointDrawer:
    """Files joint states per robot and draws each window as plot columns, and the arm through ``arm``."""

    def __init__(self, canvas: Canvas, arm: ArmDrawer) -> None:
        self.canvas = canvas
        self.arm = arm
        self._rows: dict[str, Rows] = {}

    def file(self, rid: str, info: RobotDrawing, js: JointState) -> None:
        rows = self._rows.get(rid)
        if rows is not None and rows.items and len(rows.items[0][0]) != len(js.names):
            self._draw(rid, info, rows)  # the robot changed shape: draw what came before on its own
        self.canvas.file(self._rows, rid, (tuple(js.names), js.q, js.dq))

    def flush(self, robots: dict[str, RobotDrawing]) -> None:
        for rid, rows in self._rows.items():
            if rows.items:
                self._draw(rid, robots[rid], rows)

    def _plot(self, entity: str, names: tuple[str, ...], times: list[rr.TimeColumn], values: np.ndarray) -> None:
        if self.canvas.once(entity):
            self.canvas.rec.log(entity, rr.SeriesLines(names=list(names)), static=True)
        send(self.canvas.rec, entity, times, [scalars(SCALARS, np.degrees(values))])

    def _draw(self, rid: str, info: RobotDrawing, rows: Rows) -> None:
        names = rows.items[0][0]
        q = np.array([it[1] for it in rows.items], dtype=float)
        times = rows.times()
        if facts(info.kind).base:
            self._plot(f"plots/wheels/{rid}", names, times, q)
        else:
            self._plot(f"plots/joints/{rid}", names, times, q)
            self._plot(f"plots/joint_speed/{rid}", names, times, np.array([it[2] for it in rows.items], dtype=float))
        self.arm.draw_joints(rid, info, q, rows)
        rows.clear()

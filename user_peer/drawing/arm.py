"""An arm in 3D: its base and link shapes (static), one transform per joint, the skeleton through its joint
origins, and the flange frame its pose stream carries.

A window of joint states is drawn at once as columns through :class:`~user_peer.rerun_columns.ArmChain`; an
arm whose URDF has a joint kind the chain does not know is drawn row by row with Pinocchio instead.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import rerun as rr

from fabric.interfaces import Pose
from user_peer.drawing.canvas import Canvas, Rows
from user_peer.drawing.labels import OwnershipDrawer
from user_peer.drawing.layout import TIMELINE_SIM, TIMELINE_WALL
from user_peer.drawing.robots import RobotDrawing
from user_peer.geometry import compose
from user_peer.rerun_columns import POSITIONS3, STRIPS3, ArmChain, column, send, strips, transforms, vectors

__all__ = ["ArmDrawer", "log_shape"]


def log_shape(rec: rr.RecordingStream, path: str, shape: Any) -> None:
    """A link's shape under ``path``/shape, static; a mesh that does not load is left out."""
    color = [shape.color]
    if shape.kind == "box":
        arch = rr.Boxes3D(half_sizes=[shape.size], colors=color, fill_mode="solid")
    elif shape.kind == "sphere":
        arch = rr.Ellipsoids3D(half_sizes=[[shape.size[0]] * 3], colors=color, fill_mode="solid")
    elif shape.kind == "cylinder":
        arch = rr.Cylinders3D(lengths=[shape.size[1]], radii=[shape.size[0]], colors=color, fill_mode="solid")
    elif shape.kind == "capsule":
        # Rerun's capsules run along +z from the origin; URDF's are centred.
        arch = rr.Capsules3D(
            lengths=[shape.size[1]], radii=[shape.size[0]], translations=[[0, 0, -shape.size[1] / 2]], colors=color
        )
    elif shape.kind == "mesh" and shape.mesh_path:
        try:
            arch = rr.Asset3D(path=shape.mesh_path)
        except Exception:
            return
    else:
        return
    rec.log(f"{path}/shape", arch, static=True)


class ArmDrawer:
    """The arms' bodies; their joint plots are :class:`~user_peer.drawing.joints.JointDrawer`'s."""

    def __init__(self, canvas: Canvas, labels: OwnershipDrawer) -> None:
        self.canvas = canvas
        self.labels = labels
        self._chains: dict[int, ArmChain] = {}
        self._flanges: dict[str, Rows] = {}

    def chain(self, info: RobotDrawing) -> ArmChain | None:
        """The arm's chain for columnar drawing; None for a robot without an arm, or an arm the chain cannot draw."""
        if info.arm is None:
            return None
        chain = self._chains.get(id(info.arm))
        if chain is None:
            chain = self._chains[id(info.arm)] = ArmChain(info.arm)
        return chain if chain.supported else None

    def static(self, rid: str, info: RobotDrawing) -> None:
        """What never moves: the arm's base, its link shapes below their joints, the skeleton's style, its label."""
        chain = self.chain(info)
        if chain is None or not self.canvas.once(f"{rid}/arm"):
            return
        rec, root, base = self.canvas.rec, f"world/robots/{rid}", info.base
        links = f"{root}/links"
        if base is not None:
            rec.log(
                links,
                rr.Transform3D(translation=base.translation, quaternion=rr.Quaternion(xyzw=base.quat_xyzw)),
                static=True,
            )
        for shape, joint, pl in chain.shapes():
            path = f"{chain.path(links, joint - 1)}/{rr.escape_entity_path_part(shape.name)}"
            rec.log(
                path,
                rr.Transform3D(translation=pl.translation, quaternion=rr.Quaternion(xyzw=pl.quat_xyzw)),
                static=True,
            )
            log_shape(rec, path, shape)
        rec.log(
            f"{root}/skeleton",
            rr.LineStrips3D.from_fields(radii=0.006, colors=[info.color]),
            rr.Points3D.from_fields(radii=0.012, colors=[(60, 60, 60)]),
            static=True,
        )
        at = base.translation if base is not None else np.zeros(3)
        self.labels.place(rid, f"{root}/label", np.asarray(at, dtype=float) + [0.0, 0.0, 0.05])

    def draw_joints(self, rid: str, info: RobotDrawing, q: np.ndarray, rows: Rows) -> None:
        """The arm at a window of joint positions ``q`` (one row each of ``rows``): per-joint transforms and
        the skeleton as columns, or row by row where the chain cannot draw it; nothing if ``q`` is not its shape."""
        chain = self.chain(info)
        n, k = q.shape
        if chain is not None and k == chain.nq:
            root, times = f"world/robots/{rid}", rows.times()
            local = ts, qs = chain.local(q)
            for j in range(len(chain.joints)):
                send(self.canvas.rec, chain.path(f"{root}/links", j), times, transforms(ts[:, j], qs[:, j]))
            origins = chain.origins(
                q, info.base, local
            )  # the skeleton: a line strip through the joint origins, and points at them
            send(
                self.canvas.rec,
                f"{root}/skeleton",
                times,
                [
                    column(STRIPS3, strips(origins)),
                    column(POSITIONS3, vectors(origins.reshape(-1, 3), 3), np.full(n, origins.shape[1])),
                ],
            )
        elif info.arm is not None and k == len(info.arm.joint_names):
            self._draw_rows(rid, info, rows)  # a URDF joint kind the chain does not know: Pinocchio per row

    def _draw_rows(self, rid: str, info: RobotDrawing, rows: Rows) -> None:
        arm, rec = info.arm, self.canvas.rec
        assert arm is not None
        for wall, sim, (_names, q, _dq) in zip(rows.wall, rows.sim, rows.items):
            rec.set_time(TIMELINE_WALL, timestamp=np.datetime64(int(wall), "ns"))
            if sim > 0:
                rec.set_time(TIMELINE_SIM, duration=sim)
            q = np.asarray(q, dtype=float)
            origins = [(compose(info.base, pl))[0] for pl in arm.fk(q)]
            rec.log(f"world/robots/{rid}/skeleton", rr.LineStrips3D([origins], radii=0.006, colors=[info.color]))
            for shape, placement in arm.shape_placements(q):
                path = f"world/robots/{rid}/links/{rr.escape_entity_path_part(shape.name)}"
                t, quat = compose(info.base, placement)
                rec.log(path, rr.Transform3D(translation=t, quaternion=rr.Quaternion(xyzw=quat)))
                if self.canvas.once(path):
                    log_shape(rec, path, shape)

    def file_flange(self, rid: str, pose: Pose) -> None:
        """File the flange frame an arm's pose stream carries."""
        self.canvas.file(self._flanges, rid, (pose, 0))

    def flush(self) -> None:
        """Draw the flange frames filed since the last flush."""
        for rid, rows in self._flanges.items():
            if not rows.items:
                continue
            poses = [it[0] for it in rows.items]
            pos = np.array([p.position for p in poses], dtype=float)
            quat = np.array([p.quaternion for p in poses], dtype=float)[:, [1, 2, 3, 0]]
            path = f"world/robots/{rid}/flange"
            if self.canvas.once(path):
                self.canvas.rec.log(f"{path}/axes", rr.TransformAxes3D(0.05), static=True)
            send(self.canvas.rec, path, rows.times(), transforms(pos, quat))
            rows.clear()

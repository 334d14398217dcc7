"""Forward kinematics and link shapes of an arm, for drawing it: Pinocchio over the robot's URDF.

The viewer needs every link's placement from a JointState; the compute peer
answers FK queries too, but a query per frame at 100 Hz would be wasteful and a
recording has no compute peer to ask. Pinocchio on the same URDF the sim and
the compute peer use (robots/) gives the same numbers locally, with no second
copy of the geometry.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np


@dataclass(frozen=True, slots=True)
class Shape:
    """One visual primitive of a link: kind in box/cylinder/sphere/capsule/mesh, sizes in metres."""

    name: str
    kind: str
    size: tuple[float, ...]  # box: half sizes (3); cylinder/capsule: (radius, length); sphere: (radius,)
    mesh_path: str = ""
    color: tuple[int, int, int, int] = (180, 180, 190, 255)


@dataclass(frozen=True, slots=True)
class Placement:
    """A rigid transform: translation (3,) and quaternion (x, y, z, w) as Rerun wants it."""

    translation: np.ndarray
    quat_xyzw: np.ndarray


DRAWABLE_MESHES = (".stl", ".obj", ".glb", ".gltf")
"""Mesh formats Rerun's ``Asset3D`` loads; a URDF's ``.dae`` visuals are drawn from the link's collision mesh."""


def _unreadable(g) -> bool:
    """A mesh file Rerun cannot load; a primitive (Pinocchio names its ``meshPath`` 'BOX', 'CYLINDER' ...) is drawn."""
    suffix = Path(str(g.meshPath or "")).suffix.lower()
    return bool(suffix) and suffix not in DRAWABLE_MESHES


def _placement(se3) -> Placement:
    import pinocchio as pin

    q = pin.Quaternion(se3.rotation)
    return Placement(np.array(se3.translation, dtype=float), np.array([q.x, q.y, q.z, q.w], dtype=float))


class ArmGeometry:
    """An arm's geometry built from a URDF: joint names, FK to joint origins, and placements of visual shapes.

    For drawing only; the compute peer's ``compute_peer.kinematics.ArmModel`` is the solver's model (limits, IK).
    """

    def __init__(self, urdf: str | Path, *, urdf_text: str | None = None) -> None:
        import pinocchio as pin

        self._pin = pin
        if urdf_text is not None:
            self.model = pin.buildModelFromXML(urdf_text)
            try:
                self.visual = pin.buildGeomFromUrdfString(self.model, urdf_text, pin.GeometryType.VISUAL)
            except Exception:
                self.visual = pin.GeometryModel()
        else:
            path = str(urdf)
            self.model = pin.buildModelFromUrdf(path)
            try:
                self.visual = pin.buildGeomFromUrdf(
                    self.model, path, pin.GeometryType.VISUAL, package_dirs=[str(Path(path).parent)]
                )
            except Exception:
                self.visual = pin.GeometryModel()
        self.data = self.model.createData()
        self.joint_names: tuple[str, ...] = tuple(self.model.names[1:])
        self._link_frames = [i for i, f in enumerate(self.model.frames) if f.type == self._pin.FrameType.BODY]
        self.links = _links(self.model)
        self.root_link = self.links[0][0] if self.links else "base_link"
        self.joint_links: tuple[str, ...] = tuple(
            next((name for name, _p, j, moved in self.links if j == i and (moved or i == 0)), self.model.names[i])
            for i in range(self.model.njoints)
        )
        """The link each joint frame of ``fk`` is (the root link first): a URDF link's frame is its joint's."""
        objects = list(self.visual.geometryObjects)
        if urdf_text is None and any(_unreadable(g) for g in objects):
            objects = self._readable(objects, str(urdf))
        self.shapes: list[tuple[Shape, int, object]] = [s for s in (self._shape(g) for g in objects) if s]

    def _readable(self, visual: list, path: str) -> list:
        """The visual objects Rerun can draw; a link whose visual mesh it cannot (a ``.dae``: the UR5's, the
        Panda's) is drawn with its collision geometry instead (the STL MuJoCo simulates)."""
        pin = self._pin
        try:
            collision = pin.buildGeomFromUrdf(
                self.model, path, pin.GeometryType.COLLISION, package_dirs=[str(Path(path).parent)]
            )
        except Exception:
            return [g for g in visual if not _unreadable(g)]
        lacking = {g.parentFrame for g in visual if _unreadable(g)}
        return [g for g in visual if g.parentFrame not in lacking] + [
            g for g in collision.geometryObjects if g.parentFrame in lacking and not _unreadable(g)
        ]

    def _shape(self, g) -> tuple[Shape, int, object] | None:
        geom = g.geometry
        kind = type(geom).__name__.lower()
        color = tuple(int(max(0.0, min(1.0, c)) * 255) for c in np.asarray(g.meshColor, dtype=float))
        if len(color) != 4 or color == (0, 0, 0, 0):
            color = (180, 180, 190, 255)
        if kind == "box":
            size: tuple[float, ...] = tuple(float(h) for h in geom.halfSide)
        elif kind in ("cylinder", "capsule"):
            size = (float(geom.radius), 2.0 * float(geom.halfLength))
        elif kind == "sphere":
            size = (float(geom.radius),)
        elif g.meshPath:
            kind, size = "mesh", ()
        else:
            return None
        return (
            Shape(g.name, "mesh" if kind == "mesh" else kind, size, str(g.meshPath or ""), color),
            int(g.parentJoint),
            g.placement,
        )

    def fk(self, q: Sequence[float]) -> list[Placement]:
        """Placement of every joint frame (base first: the universe), in the arm's base frame."""
        pin = self._pin
        q = np.asarray(q, dtype=float)
        if q.shape != (self.model.nq,):
            raise ValueError(f"arm model has {self.model.nq} joints, got {q.shape[0] if q.ndim else 0} values")
        pin.forwardKinematics(self.model, self.data, q)
        return [_placement(m) for m in self.data.oMi]

    def link_placements(self, q: Sequence[float]) -> list[Placement]:
        """Placement of every link of ``links`` (same order), in the arm's base frame."""
        self.fk(q)
        self._pin.updateFramePlacements(self.model, self.data)
        return [_placement(self.data.oMf[f]) for f in self._link_frames]

    def shape_placements(self, q: Sequence[float]) -> list[tuple[Shape, Placement]]:
        """Each visual shape with its placement in the base frame (FK must be current: call after ``fk``)."""
        self.fk(q)
        out = []
        for shape, joint, local in self.shapes:
            out.append((shape, _placement(self.data.oMi[joint] * local)))
        return out


def _links(model) -> tuple[tuple[str, str, int, bool], ...]:
    """The URDF's links as Pinocchio keeps them, in its frame order: (name, parent link ("" for the root), the joint
    that moves it, whether a moving joint is its own parent joint), as robot_state_publisher names its frames."""
    import pinocchio as pin

    frames = model.frames
    out = []
    for f in frames:
        if f.type != pin.FrameType.BODY:
            continue
        joint = frames[f.parentFrame]  # the link's joint frame (moving or fixed); the root's is the universe
        parent = frames[joint.parentFrame] if f.parentFrame != 0 else None
        moved = joint.type == pin.FrameType.JOINT
        out.append(
            (
                str(f.name),
                str(parent.name) if parent is not None and parent.type == pin.FrameType.BODY else "",
                int(f.parentJoint),
                moved,
            )
        )
    return tuple(out)

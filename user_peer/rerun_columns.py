"""Columnar drawing: rows gathered per entity, sent to Rerun as columns; an arm's chain as per-joint transforms.

Why: a ``rerun.log`` call costs 0.1-0.3 ms whatever it carries, and a class world sends thousands of
messages a second. :class:`~user_peer.rerun_log.WorldLogger` therefore only appends what a message
brings to a per-stream buffer, and once per window (the live viewer: 0.1 s) turns each buffer into one
``send_columns`` call per entity (Rerun's chunk API: ``rr.TimeColumn`` + ``Archetype.columns()``,
``.partition()`` where a row holds several instances). What never changes is logged once, static
(shapes, colours, radii, names), so the rows carry only what moves.

:class:`ArmChain` is the arm's kinematic tree in numpy: each joint frame is an entity below its parent
(``links/joint_1/joint_2/...``) whose transform is the joint's fixed placement times its motion, so the
link shapes hang below their joint once, static, and a row is one quaternion per joint, computed for a
whole window of JointStates at once (no Pinocchio call per message). Pinocchio still reads the URDF
(:class:`~user_peer.arm_geometry.ArmGeometry`); :meth:`ArmChain.origins` is its FK, vectorised (tested
against it).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np
import pyarrow as pa
import rerun as rr

from user_peer.arm_geometry import ArmGeometry, Placement

__all__ = [
    "ArmChain",
    "column",
    "quat_mul",
    "quat_rotate",
    "scalars",
    "send",
    "strips",
    "time_columns",
    "transforms",
    "vectors",
]


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton products of (..., 4) x, y, z, w quaternions (broadcasting)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    ax, ay, az, aw = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bx, by, bz, bw = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = aw * bx + ax * bw + ay * bz - az * by
    out[..., 1] = aw * by - ax * bz + ay * bw + az * bx
    out[..., 2] = aw * bz + ax * by - ay * bx + az * bw
    out[..., 3] = aw * bw - ax * bx - ay * by - az * bz
    return out


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    out = np.empty(np.broadcast_shapes(u.shape, v.shape))
    out[..., 0] = u[..., 1] * v[..., 2] - u[..., 2] * v[..., 1]
    out[..., 1] = u[..., 2] * v[..., 0] - u[..., 0] * v[..., 2]
    out[..., 2] = u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]
    return out


def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(..., 3) vectors rotated by (..., 4) x, y, z, w unit quaternions (broadcasting)."""
    q = np.asarray(q, dtype=float)
    v = np.asarray(v, dtype=float)
    u, w = q[..., :3], q[..., 3:4]
    t = 2.0 * _cross(u, v)
    return v + w * t + _cross(u, t)


# --------------------------------------------------------------------------- columns built straight in Arrow


class _Batch:
    """An Arrow array as a component batch (what ``rr.ComponentColumn`` partitions into rows)."""

    __slots__ = ("array",)

    def __init__(self, array: pa.Array) -> None:
        self.array = array

    def as_arrow_array(self) -> pa.Array:
        return self.array


_VEC = {k: pa.list_(pa.field("item", pa.float32(), nullable=False), k) for k in (2, 3, 4)}
_STRIP3 = pa.list_(pa.field("item", _VEC[3], nullable=False))


def vectors(values: np.ndarray, width: int) -> pa.Array:
    """(n, width) floats as Rerun's fixed-size float32 vectors (positions, translations, quaternions)."""
    flat = pa.array(np.ascontiguousarray(values, dtype=np.float32).reshape(-1))
    return pa.FixedSizeListArray.from_arrays(flat, type=_VEC[width])


def strips(points: np.ndarray) -> pa.Array:
    """(n, k, 3) points as n line strips of k points each."""
    n, k = points.shape[0], points.shape[1]
    offsets = pa.array(np.arange(0, (n + 1) * k, k, dtype=np.int32))
    return pa.ListArray.from_arrays(offsets, vectors(points.reshape(-1, 3), 3), type=_STRIP3)


def column(descriptor: Any, array: pa.Array, lengths: Sequence[int] | np.ndarray | None = None) -> rr.ComponentColumn:
    """One component's rows: ``lengths`` instances each (default one). The Archetype.columns() path builds
    the same arrays through attrs converters, which costs more than the data; this is the hot path."""
    return rr.ComponentColumn(descriptor, _Batch(array), lengths=lengths)


def scalars(descriptor: Any, values: np.ndarray) -> rr.ComponentColumn:
    """(n, k) values: n rows of k plotted series (``Scalars``)."""
    values = np.asarray(values, dtype=np.float64)
    n = values.shape[0]
    k = values.shape[1] if values.ndim > 1 else 1
    return column(descriptor, pa.array(values.reshape(-1)), np.full(n, k) if k != 1 else None)


SCALARS = rr.Scalars.descriptor_scalars()
TRANSLATION = rr.Transform3D.descriptor_translation()
QUATERNION = rr.Transform3D.descriptor_quaternion()
POSITIONS3 = rr.Points3D.descriptor_positions()
POSITIONS2 = rr.Points2D.descriptor_positions()
STRIPS3 = rr.LineStrips3D.descriptor_strips()


def transforms(translation: np.ndarray, quat_xyzw: np.ndarray) -> list[rr.ComponentColumn]:
    """Rows of Transform3D: (n, 3) translations and (n, 4) x, y, z, w quaternions."""
    return [column(TRANSLATION, vectors(translation, 3)), column(QUATERNION, vectors(quat_xyzw, 4))]


def time_columns(wall_ns: Sequence[int], sim_s: Sequence[float] | None) -> list[rr.TimeColumn]:
    """The rows' ``wall_time`` (ns since the epoch) and, when every row has one, ``sim_time`` (s)."""
    cols = [rr.TimeColumn("wall_time", timestamp=np.asarray(wall_ns, dtype=np.int64).astype("datetime64[ns]"))]
    if sim_s is not None and len(sim_s) and min(sim_s) > 0:
        cols.append(rr.TimeColumn("sim_time", duration=np.asarray(sim_s, dtype=float)))
    return cols


def send(rec: rr.RecordingStream, entity: str, times: list[rr.TimeColumn], columns: Any) -> None:
    """One chunk of rows to the recording (the rows' own times; the stream's ``set_time`` plays no part)."""
    rec.send_columns(entity, indexes=times, columns=columns)


@dataclass(frozen=True, slots=True)
class _Joint:
    name: str
    parent: int  # index into the chain's joints, -1: the arm's base
    idx_q: int
    axis: np.ndarray  # unit vector in the joint frame
    prismatic: bool
    translation: np.ndarray  # fixed placement in the parent joint's frame
    quat: np.ndarray  # x, y, z, w


_AXES = {"X": (1.0, 0.0, 0.0), "Y": (0.0, 1.0, 0.0), "Z": (0.0, 0.0, 1.0)}


class ArmChain:
    """An arm's joints as a tree of frames, for drawing a window of joint states at once.

    ``supported`` is False when the URDF has a joint kind other than revolute or prismatic (one degree
    of freedom each); the logger then falls back to Pinocchio per message.
    """

    def __init__(self, geometry: ArmGeometry) -> None:
        import pinocchio as pin

        m = geometry.model
        self.geometry = geometry
        self.joints: list[_Joint] = []
        self.supported = True
        for i in range(1, m.njoints):
            short = m.joints[i].shortname()
            kind = short.removeprefix("JointModel")
            if kind in ("RX", "RY", "RZ", "PX", "PY", "PZ"):
                axis, prismatic = np.array(_AXES[kind[1]]), kind[0] == "P"
            elif kind in ("RevoluteUnaligned", "PrismaticUnaligned"):
                axis, prismatic = np.asarray(m.joints[i].extract().axis, dtype=float), kind.startswith("P")
            else:
                self.supported = False
                axis, prismatic = np.zeros(3), False
            pl = m.jointPlacements[i]
            q = pin.Quaternion(pl.rotation)
            self.joints.append(
                _Joint(
                    m.names[i],
                    int(m.parents[i]) - 1,
                    int(m.joints[i].idx_q),
                    axis,
                    prismatic,
                    np.array(pl.translation, dtype=float),
                    np.array([q.x, q.y, q.z, q.w]),
                )
            )
            if m.joints[i].nq != 1:
                self.supported = False
        self.nq = int(m.nq)
        self._idx = np.array([j.idx_q for j in self.joints], dtype=int)
        self._axes = np.array([j.axis for j in self.joints]).reshape(-1, 3)
        self._prismatic = np.array([j.prismatic for j in self.joints], dtype=bool)
        self._translations = np.array([j.translation for j in self.joints]).reshape(-1, 3)
        self._quats = np.array([j.quat for j in self.joints]).reshape(-1, 4)

    def shapes(self) -> list[tuple[Any, int, Placement]]:
        """Each visual shape of the URDF, the Pinocchio id of the joint it hangs below (0: the arm's base) and
        its placement in that joint's frame: logged once, static."""
        import pinocchio as pin

        out = []
        for shape, joint, local in self.geometry.shapes:
            q = pin.Quaternion(local.rotation)
            out.append(
                (shape, joint, Placement(np.array(local.translation, dtype=float), np.array([q.x, q.y, q.z, q.w])))
            )
        return out

    def path(self, root: str, joint: int) -> str:
        """The entity of joint ``joint`` (-1: the arm's base) below ``root``: ``root/joint_1/joint_2/...``."""
        parts: list[str] = []
        while joint >= 0:
            parts.append(rr.escape_entity_path_part(self.joints[joint].name))
            joint = self.joints[joint].parent
        return "/".join([root, *reversed(parts)])

    def local(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each joint's transform in its parent's frame for rows of joint values ``q`` (n, nq):
        translations (n, joints, 3) and x, y, z, w quaternions (n, joints, 4)."""
        v = np.asarray(q, dtype=float).reshape(-1, self.nq)[:, self._idx]  # (n, joints)
        n = v.shape[0]
        half = np.where(self._prismatic, 0.0, 0.5 * v)
        motion = np.empty((n, len(self.joints), 4))
        motion[..., :3] = self._axes * np.sin(half)[..., None]
        motion[..., 3] = np.cos(half)
        qs = quat_mul(self._quats, motion)
        ts = np.broadcast_to(self._translations, (n, len(self.joints), 3))
        if self._prismatic.any():
            slide = self._axes * np.where(self._prismatic, v, 0.0)[..., None]
            ts = ts + quat_rotate(self._quats, slide)
        return np.ascontiguousarray(ts), qs

    def origins(
        self, q: np.ndarray, base: Placement | None = None, local: tuple[np.ndarray, np.ndarray] | None = None
    ) -> np.ndarray:
        """Joint origins in the world (n, joints + 1, 3), the arm's base first: Pinocchio's FK, vectorised
        (``local``: :meth:`local` of the same ``q``, when the caller has it)."""
        ts, qs = local if local is not None else self.local(q)
        n = ts.shape[0]
        bt = np.zeros(3) if base is None else np.asarray(base.translation, dtype=float)
        bq = np.array([0.0, 0.0, 0.0, 1.0]) if base is None else np.asarray(base.quat_xyzw, dtype=float)
        wt = np.empty((n, len(self.joints) + 1, 3))
        wq = np.empty((n, len(self.joints) + 1, 4))
        wt[:, 0], wq[:, 0] = bt, bq
        for k, j in enumerate(self.joints):
            p = j.parent + 1
            wt[:, k + 1] = wt[:, p] + quat_rotate(wq[:, p], ts[:, k])
            wq[:, k + 1] = quat_mul(wq[:, p], qs[:, k])
        return wt

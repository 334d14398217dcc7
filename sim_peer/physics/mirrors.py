"""Mirrors: robots simulated by another sim of the world, as kinematic bodies this sim's sensors see.

When several sims share a world, each simulates its own robots; a LIDAR, an ultrasonic ring or a bumper
here must still see a robot simulated elsewhere. A MuJoCo model cannot gain bodies once compiled, so the
model is built with a pool of ``slots``: mocap bodies with one cylinder each, parked far below the floor in
a geom group no sensor sees (an unused slot costs the rays nothing), never colliding (robots are kinematic). A mirror takes slots and puts them in the robots' geom group:

- a mobile base takes one, a cylinder sized to its footprint (its ``BaseInfo`` radius and height), placed
  at each pose of its ``pose`` stream;
- an arm takes one per link geom (capsules, boxes, spheres, cylinders: :mod:`sim_peer.physics.arm_mirror` turns
  its ``joints`` stream into the pose of each), so a bumper or a LIDAR that meets an arm meets its links
  where its own sim has them.

Hiding a mirror parks its slots again. A mirror lags its robot by a stream period plus transport
(docs/sim.md). Pure MuJoCo, no Zenoh: the peer feeds it (:mod:`sim_peer.shards.mirroring`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

__all__ = ["MIRROR_PREFIX", "PARKED_Z", "PRIMITIVES", "Mirror", "Mirrors", "Shape", "add_slots", "footprint"]

MIRROR_PREFIX = "mirror/"
"""Body and geom names of the slots: ``mirror/{i}`` (a robot id cannot contain a slash, so none collides)."""

PARKED_Z = -100.0
"""Where an unused slot waits: far below the floor, out of every sensor's range."""

MIRROR_GROUP = 1
"""The robots' geom group: what LIDARs, sonars and bumpers see (:data:`sim_peer.sensors.SENSED_GROUPS`)."""

PARKED_GROUP = 5
"""A parked slot's geom group, which no sensor casts against: unused slots cost the rays nothing."""


def add_slots(spec: mujoco.MjSpec, slots: int) -> None:
    """Add ``slots`` parked mirror bodies to a model spec before it is compiled."""
    for i in range(slots):
        body = spec.worldbody.add_body(name=f"{MIRROR_PREFIX}{i}", pos=[0.0, 0.0, PARKED_Z], mocap=True)
        body.add_geom(
            name=f"{MIRROR_PREFIX}{i}",
            type=mujoco.mjtGeom.mjGEOM_CYLINDER,
            size=[0.01, 0.01, 0.0],
            contype=0,
            conaffinity=0,
            group=PARKED_GROUP,
            rgba=[0.55, 0.6, 0.7, 0.6],
        )


Shape = tuple[int, tuple[float, float, float]]
"""One slot's geom: its MuJoCo type (``mjtGeom``: a primitive, never a mesh) and its size."""

PRIMITIVES = {
    int(mujoco.mjtGeom.mjGEOM_SPHERE),
    int(mujoco.mjtGeom.mjGEOM_CAPSULE),
    int(mujoco.mjtGeom.mjGEOM_CYLINDER),
    int(mujoco.mjtGeom.mjGEOM_BOX),
    int(mujoco.mjtGeom.mjGEOM_ELLIPSOID),
}


def footprint(radius: float, height: float) -> Shape:
    """A mobile base's one slot: a cylinder about its turn point, standing on the floor."""
    return int(mujoco.mjtGeom.mjGEOM_CYLINDER), (max(float(radius), 0.01), max(float(height), 0.02) / 2.0, 0.0)


def _bounds(shape: Shape) -> tuple[float, list[float]]:
    """The bounding sphere radius and half-extents (``geom_rbound``, ``geom_aabb``) ray casting culls by."""
    kind, (a, b, c) = shape
    if kind == mujoco.mjtGeom.mjGEOM_SPHERE:
        half = [a, a, a]
    elif kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
        half = [a, a, a + b]
    elif kind == mujoco.mjtGeom.mjGEOM_CYLINDER:
        half = [a, a, b]
    else:  # box, ellipsoid: half-sizes
        half = [a, b, c]
    return float(np.linalg.norm(half)), half


@dataclass(frozen=True, slots=True)
class Mirror:
    """A robot of another sim as this sim holds it: which slots, their shapes, and the sim it comes from."""

    robot: str
    slots: tuple[int, ...]
    shapes: tuple[Shape, ...]
    source: str = ""

    @property
    def height(self) -> float:
        """A base's standing height (its one cylinder); 0 for several slots."""
        return 2.0 * self.shapes[0][1][1] if len(self.shapes) == 1 else 0.0


class Mirrors:
    """The pool of mirror slots of one compiled model, and which robot holds which. Not thread-safe: the sim
    calls it between steps, under its world lock."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        self.model, self.data = model, data
        self._mocap: list[int] = []
        self._geom: list[int] = []
        i = 0
        while True:
            bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, f"{MIRROR_PREFIX}{i}")
            if bid < 0:
                break
            self._mocap.append(int(model.body_mocapid[bid]))
            self._geom.append(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f"{MIRROR_PREFIX}{i}"))
            i += 1
        self._held: dict[str, Mirror] = {}
        self._free: list[int] = list(range(len(self._mocap)))  # kept sorted: the lowest slots first
        self._mat = np.zeros(9)
        self.refused = 0  # robots that found too few free slots

    @property
    def slots(self) -> int:
        return len(self._mocap)

    @property
    def free(self) -> int:
        return len(self._free)

    def held(self) -> dict[str, Mirror]:
        return dict(self._held)

    def holds(self, robot: str) -> bool:
        return robot in self._held

    def show(self, robot: str, radius: float, height: float, source: str = "") -> Mirror | None:
        """Give a mobile base one slot sized to its footprint (again: resized); None when none is free."""
        return self.show_shapes(robot, (footprint(radius, height),), source)

    def show_shapes(self, robot: str, shapes: Sequence[Shape], source: str = "") -> Mirror | None:
        """Give ``robot`` one slot per shape (primitive geoms), in the robots' geom group; None, counted, when too
        few slots are free. Showing it again with other shapes resizes it, or takes other slots."""
        m = self._held.get(robot)
        if m is not None and m.source == source and (shapes is m.shapes or tuple(shapes) == m.shapes):
            return m  # as it is (an arm's every joint message): nothing to resize
        shapes = tuple((int(k), tuple(float(x) for x in size)) for k, size in shapes)
        if not shapes or any(k not in PRIMITIVES for k, _ in shapes):
            raise ValueError(
                f"mirror of {robot}: one or more primitive geoms needed, got types {[k for k, _ in shapes]}"
            )
        if m is not None and len(m.slots) != len(shapes):
            self.hide(robot)
            m = None
        if m is None:
            if len(self._free) < len(shapes):
                self.refused += 1
                return None
            slots, self._free = tuple(self._free[: len(shapes)]), self._free[len(shapes) :]
            m = Mirror(robot, slots, (), source)
        for slot, shape, old in zip(m.slots, shapes, m.shapes or (None,) * len(shapes)):
            g = self._geom[slot]
            if shape != old:
                rbound, half = _bounds(shape)
                self.model.geom_type[g] = shape[0]
                self.model.geom_size[g] = shape[1]
                self.model.geom_rbound[g] = rbound  # ray casting culls by these two
                self.model.geom_aabb[g] = [0.0, 0.0, 0.0, *half]
            self.model.geom_group[g] = MIRROR_GROUP
        m = Mirror(robot, m.slots, shapes, source)
        self._held[robot] = m
        return m

    def place(self, robot: str, position: Sequence[float], quaternion: Sequence[float]) -> bool:
        """Put a base's mirror where its own sim says it is (``position``: the base on the floor); False when it
        holds no slot or the pose is not finite."""
        m = self._held.get(robot)
        if m is None:
            return False
        return self.place_shapes(
            robot, [(np.asarray(position, dtype=np.float64) + [0.0, 0.0, m.height / 2.0], quaternion)]
        )

    def place_shapes(self, robot: str, poses: Sequence[tuple[Sequence[float], Sequence[float]]]) -> bool:
        """Put each of ``robot``'s slots at its pose (centre, quaternion), in slot order; False (nothing moved)
        when it holds no slots, the count differs, or a pose is not finite."""
        m = self._held.get(robot)
        if m is None or len(poses) != len(m.slots):
            return False
        try:
            p = np.asarray([pos for pos, _ in poses], dtype=np.float64)
            q = np.asarray([quat for _, quat in poses], dtype=np.float64)
        except ValueError:  # ragged
            return False
        if (
            p.shape != (len(m.slots), 3)
            or q.shape != (len(m.slots), 4)
            or not (np.isfinite(p).all() and np.isfinite(q).all())
        ):
            return False
        n = np.linalg.norm(q, axis=1)
        if (n < 1e-9).any():
            return False
        q = q / n[:, None]
        mocap, geoms = self._rows(m)
        self.data.mocap_pos[mocap], self.data.mocap_quat[mocap] = p, q
        # where MuJoCo's kinematics would put the geoms, now: a world recomputes positions only when something
        # reads them, and a bumper's rays between two reads must see the mirror where it is
        self.data.geom_xpos[geoms] = p
        for g, qi in zip(geoms, q):
            mujoco.mju_quat2Mat(self._mat, qi)
            self.data.geom_xmat[g] = self._mat
        return True

    def _rows(self, m: Mirror) -> tuple[list[int], list[int]]:
        return [self._mocap[s] for s in m.slots], [self._geom[s] for s in m.slots]

    def hide(self, robot: str) -> bool:
        """Park ``robot``'s mirror (its sim left, or it was handed to this sim); False when it had none."""
        m = self._held.pop(robot, None)
        if m is None:
            return False
        for slot in m.slots:
            self.data.mocap_pos[self._mocap[slot]] = [0.0, 0.0, PARKED_Z]
            self.data.geom_xpos[self._geom[slot]] = [0.0, 0.0, PARKED_Z]
            self.model.geom_group[self._geom[slot]] = PARKED_GROUP
        self._free = sorted(self._free + list(m.slots))
        return True

    def hide_from(self, source: str) -> list[str]:
        """Park every mirror of robots that ``source`` (a sim that left) simulated; their ids."""
        gone = [r for r, m in self._held.items() if m.source == source]
        for r in gone:
            self.hide(r)
        return gone

"""Mirrors: robots simulated by another sim of the world, as kinematic bodies this sim's sensors see.

When several sims share a world, each simulates its own robots; a LIDAR, an ultrasonic ring or a bumper
here must still see a robot simulated elsewhere. A MuJoCo model cannot gain bodies once compiled, so the
model is built with a pool of ``slots``: mocap bodies with one cylinder each, parked far below the floor in
a geom group no sensor sees (an unused slot costs the rays nothing), never colliding (robots are kinematic). A mirror takes a slot, joins the robots' geom group, is sized
to the other robot's footprint (its ``BaseInfo`` radius and height) and follows that robot's published pose;
hiding it parks the slot again. The pose comes from the other sim's ``pose`` stream, so a mirror lags by a
stream period plus transport (docs/sim.md).

Arms are not mirrored: an arm stands on its table (part of the scene every sim loads), with its links above
the LIDAR plane. Pure MuJoCo, no Zenoh: the peer feeds it (:mod:`sim_peer.peer`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

__all__ = ["MIRROR_PREFIX", "PARKED_Z", "Mirror", "Mirrors", "add_slots"]

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
            name=f"{MIRROR_PREFIX}{i}", type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[0.01, 0.01, 0.0],
            contype=0, conaffinity=0, group=PARKED_GROUP, rgba=[0.55, 0.6, 0.7, 0.6],
        )


@dataclass(frozen=True, slots=True)
class Mirror:
    """A robot of another sim as this sim holds it: which slot, its footprint, and the sim it comes from."""

    robot: str
    slot: int
    radius: float
    height: float
    source: str = ""


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
        self._mat = np.zeros(9)
        self.refused = 0  # robots that found no free slot

    @property
    def slots(self) -> int:
        return len(self._mocap)

    def held(self) -> dict[str, Mirror]:
        return dict(self._held)

    def holds(self, robot: str) -> bool:
        return robot in self._held

    def show(self, robot: str, radius: float, height: float, source: str = "") -> Mirror | None:
        """Give ``robot`` a slot sized to its footprint (again: resized); None when every slot is taken."""
        m = self._held.get(robot)
        if m is None:
            free = sorted(set(range(self.slots)) - {h.slot for h in self._held.values()})
            if not free:
                self.refused += 1
                return None
            m = Mirror(robot, free[0], 0.0, 0.0, source)
        if (m.radius, m.height) != (radius, height):
            half = max(float(height), 0.02) / 2.0
            r = max(float(radius), 0.01)
            g = self._geom[m.slot]
            self.model.geom_size[g] = [r, half, 0.0]
            self.model.geom_rbound[g] = float(np.hypot(r, half))  # ray casting culls by these two
            self.model.geom_aabb[g] = [0.0, 0.0, 0.0, r, r, half]
        self.model.geom_group[self._geom[m.slot]] = MIRROR_GROUP
        m = Mirror(robot, m.slot, float(radius), float(height), source)
        self._held[robot] = m
        return m

    def place(self, robot: str, position: Sequence[float], quaternion: Sequence[float]) -> bool:
        """Put ``robot``'s mirror where its own sim says it is (``position``: the base on the floor); False
        when it holds no slot or the pose is not finite."""
        m = self._held.get(robot)
        p, q = np.asarray(position, dtype=np.float64), np.asarray(quaternion, dtype=np.float64)
        if m is None or p.shape != (3,) or q.shape != (4,) or not (np.isfinite(p).all() and np.isfinite(q).all()):
            return False
        n = float(np.linalg.norm(q))
        if n < 1e-9:
            return False
        i, g = self._mocap[m.slot], self._geom[m.slot]
        centre, q = p + [0.0, 0.0, max(m.height, 0.02) / 2.0], q / n
        self.data.mocap_pos[i], self.data.mocap_quat[i] = centre, q
        # where MuJoCo's kinematics would put the geom, now: a world recomputes positions only when something
        # reads them, and a bumper's rays between two reads must see the mirror where it is
        self.data.geom_xpos[g] = centre
        mujoco.mju_quat2Mat(self._mat, q)
        self.data.geom_xmat[g] = self._mat
        return True

    def hide(self, robot: str) -> bool:
        """Park ``robot``'s mirror (its sim left, or it was handed to this sim); False when it had none."""
        m = self._held.pop(robot, None)
        if m is None:
            return False
        self.data.mocap_pos[self._mocap[m.slot]] = [0.0, 0.0, PARKED_Z]
        self.data.geom_xpos[self._geom[m.slot]] = [0.0, 0.0, PARKED_Z]
        self.model.geom_group[self._geom[m.slot]] = PARKED_GROUP
        return True

    def hide_from(self, source: str) -> list[str]:
        """Park every mirror of robots that ``source`` (a sim that left) simulated; their ids."""
        gone = [r for r, m in self._held.items() if m.source == source]
        for r in gone:
            self.hide(r)
        return gone

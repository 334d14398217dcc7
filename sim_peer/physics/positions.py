"""Where a world's bodies and sites are, recomputed lazily: only when someone reads them.

Stepping, moving a scene object or a mirror only mark the positions stale; a read (a sensor, a flange, a
pose stream) syncs them first. A headless world that nobody reads never pays for forward kinematics,
which keeps it fast. One :class:`Positions` per world, shared by the parts that move or read things
(:mod:`sim_peer.physics.scene_objects`, :mod:`sim_peer.physics.readings`, the world's mirrors).
"""

from __future__ import annotations

import mujoco


class Positions:
    """The stale flag of one world's MuJoCo positions, and the calls that make them current."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        self.model = model
        self.data = data
        self.stale = True

    def mark(self) -> None:
        """Something moved: positions are recomputed on the next read."""
        self.stale = True

    def sync(self) -> None:
        """Make positions (bodies, sites) match the current state; cheap when nothing changed."""
        if self.stale:
            mujoco.mj_kinematics(self.model, self.data)
            mujoco.mj_comPos(self.model, self.data)  # for Jacobians (flange velocity)
            self.stale = False

    def forward(self) -> None:
        """Recompute everything MuJoCo derives from the state now (after a reset or a restore)."""
        mujoco.mj_forward(self.model, self.data)
        self.stale = False


__all__ = ["Positions"]

"""A world's scene objects: named mocap bodies (an IK target, a goal pointer) users move by hand.

The scene MJCF holds each object as a mocap body; :class:`SceneObjects` maps an object's id to its mocap
slot, checks the poses it is given, keeps the pose each object had when the world was built (a reset puts
it back there) and marks the world's positions stale when one moves. It reads as a mapping from object id
to mocap index, so ``for obj in world.objects`` and ``obj in world.objects`` name the objects.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence

import mujoco
import numpy as np

from sim_peer.physics.positions import Positions


class SceneObjects(Mapping[str, int]):
    """Object id -> mocap index, with the poses' reads and checked writes."""

    def __init__(self, data: mujoco.MjData, index: Mapping[str, int], positions: Positions) -> None:
        self._data = data
        self._index = dict(index)
        self._positions = positions
        self._home = {o: (data.mocap_pos[i].copy(), data.mocap_quat[i].copy()) for o, i in self._index.items()}

    def __getitem__(self, obj: str) -> int:
        return self._index[obj]

    def __iter__(self) -> Iterator[str]:
        return iter(self._index)

    def __len__(self) -> int:
        return len(self._index)

    def pose(self, obj: str) -> tuple[np.ndarray, np.ndarray]:
        """An object's position and quaternion (w, x, y, z), copies."""
        i = self._index[obj]
        return self._data.mocap_pos[i].copy(), self._data.mocap_quat[i].copy()

    def set_pose(self, obj: str, position: Sequence[float], quaternion: Sequence[float] | None = None) -> None:
        """Move an object; the quaternion is normalised, left as it is when not given. KeyError for an
        unknown object, ValueError for a pose that is not finite (nothing moves then)."""
        if obj not in self._index:
            raise KeyError(f"unknown scene object {obj!r}; this scene has {', '.join(self._index) or 'none'}")
        i = self._index[obj]
        p = np.asarray(position, dtype=np.float64)
        if p.shape != (3,) or not np.isfinite(p).all():
            raise ValueError("object position must be 3 finite numbers")
        q = None
        if quaternion is not None:
            q = np.asarray(quaternion, dtype=np.float64)
            n = float(np.linalg.norm(q))
            if q.shape != (4,) or not np.isfinite(q).all() or n < 1e-9:
                raise ValueError("object quaternion must be 4 finite numbers, not all zero")
            q = q / n
        self._data.mocap_pos[i] = p
        if q is not None:
            self._data.mocap_quat[i] = q
        self._positions.mark()

    def reset(self) -> None:
        """Every object back where the world was built with it."""
        for o, i in self._index.items():
            self._data.mocap_pos[i], self._data.mocap_quat[i] = self._home[o]
        self._positions.mark()


__all__ = ["SceneObjects"]

"""The static part of a scene (floor, walls, shelves, tables) as boxes, read from the scene's MJCF.

Robots and scene objects move and are drawn from their streams; what never
moves is drawn once, from the same scene file the sim loads (robots/scenes).
Only geoms of the world body are taken: boxes as they are, planes as thin
slabs, cylinders and spheres as their bounding boxes.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["StaticBox", "static_boxes"]


@dataclass(frozen=True, slots=True)
class StaticBox:
    name: str
    center: np.ndarray
    half_size: np.ndarray
    quat_xyzw: np.ndarray
    rgba: tuple[int, int, int, int]


def static_boxes(mjcf_path: str | Path) -> list[StaticBox]:
    """Boxes for every world-body geom of the scene (markers in geom group 3 are left out)."""
    import mujoco

    m = mujoco.MjModel.from_xml_path(str(mjcf_path))
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    out = []
    for g in range(m.ngeom):
        if m.geom_bodyid[g] != 0 or m.geom_group[g] == 3:
            continue
        t = m.geom_type[g]
        size = np.array(m.geom_size[g], dtype=float)
        if t == mujoco.mjtGeom.mjGEOM_BOX:
            half = size
        elif t == mujoco.mjtGeom.mjGEOM_PLANE:
            half = np.array([size[0] or 10.0, size[1] or 10.0, 0.001])
        elif t == mujoco.mjtGeom.mjGEOM_CYLINDER:
            half = np.array([size[0], size[0], size[1]])
        elif t == mujoco.mjtGeom.mjGEOM_SPHERE:
            half = np.full(3, size[0])
        else:
            continue
        q = np.empty(4)
        mujoco.mju_mat2Quat(q, d.geom_xmat[g])
        rgba = tuple(int(max(0.0, min(1.0, c)) * 255) for c in m.geom_rgba[g])
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g) or f"geom{g}"
        out.append(StaticBox(name, np.array(d.geom_xpos[g]), half, np.array([q[1], q[2], q[3], q[0]]), rgba))  # type: ignore[arg-type]
    return out

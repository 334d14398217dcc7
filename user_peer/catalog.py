"""What kind of robot is behind an id: from the world's description service, or from robots/ by joint names.

A live viewer asks the sim peer's world description (``rf/{world}/srv/world``)
so it needs no local copy of the world; an export from a recording has no one
to ask, so it matches a JointState's joint names against the robot types in
``robots/``. Either way the geometry comes from the same robot descriptions the
sim uses.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from user_peer.arm_model import ArmModel, Placement
from user_peer.rerun_log import RobotInfo

log = logging.getLogger("robofabric.viewer")

__all__ = ["RobotCatalog"]


def _field(obj: Any, *names: str, default: Any = None) -> Any:
    for n in names:
        if isinstance(obj, dict) and n in obj:
            return obj[n]
        if hasattr(obj, n):
            return getattr(obj, n)
    return default


class RobotCatalog:
    """Builds :class:`RobotInfo` for robot ids; caches arm models per type."""

    def __init__(self, world_info: Any = None) -> None:
        self.world_info = world_info
        self._models: dict[str, ArmModel | None] = {}
        self._types: dict[str, dict] | None = None

    # ---------------------------------------------------------------- robots/ descriptions

    def _robot_types(self) -> dict[str, dict]:
        """type name -> {"kind", "joints", "urdf", ...} from robots/, empty if robots/ cannot tell."""
        if self._types is not None:
            return self._types
        out: dict[str, dict] = {}
        try:
            import robots

            names = list(robots.available()) if hasattr(robots, "available") else []
            for name in names:
                try:
                    d = robots.load(name)
                except Exception as exc:
                    log.debug("robots.load(%r) failed: %s", name, exc)
                    continue
                out[name] = {
                    "kind": _field(d, "kind", default=""),
                    "joints": tuple(_field(d, "joints", "joint_names", default=()) or ()),
                    "urdf": _field(d, "urdf_path", "urdf", default=None),
                    "desc": d,
                }
        except Exception as exc:  # robots/ not importable: draw without geometry
            log.debug("robot descriptions unavailable: %s", exc)
        self._types = out
        return out

    def arm_model(self, rtype: str) -> ArmModel | None:
        if rtype not in self._models:
            model = None
            t = self._robot_types().get(rtype)
            urdf = t.get("urdf") if t else None
            if urdf is not None and Path(str(urdf)).is_file():
                try:
                    model = ArmModel(urdf)
                except Exception as exc:
                    log.warning("cannot build a kinematic model of %s from %s: %s", rtype, urdf, exc)
            self._models[rtype] = model
        return self._models[rtype]

    def _world_entry(self, rid: str) -> Any:
        robots = _field(self.world_info, "robots", default=()) or ()
        for r in robots:
            if _field(r, "id", "name") == rid:
                return r
        return None

    def info(self, rid: str, hint: dict) -> RobotInfo:
        """RobotInfo for ``rid``: world description first, else a type whose joint names match."""
        entry = self._world_entry(rid)
        rtype, kind = "", ""
        base: Placement | None = None
        if entry is not None:
            rtype = _field(entry, "type", "robot_type", default="") or ""
            kind = _field(entry, "kind", default="") or ""
            pos = _field(entry, "base_position", "position", default=None)
            quat = _field(entry, "base_quaternion", "quaternion", default=None)
            if pos is not None:
                import numpy as np

                q = np.asarray(quat if quat is not None else [1, 0, 0, 0], dtype=float)
                base = Placement(np.asarray(pos, dtype=float), np.array([q[1], q[2], q[3], q[0]]))
        names = tuple(hint.get("joint_names", ()))
        if not rtype and names:
            for tname, t in self._robot_types().items():
                if t["joints"] and tuple(t["joints"]) == names:
                    rtype, kind = tname, t["kind"] or "arm"
                    break
        if not kind:
            if rtype and rtype in self._robot_types():
                kind = self._robot_types()[rtype]["kind"]
            elif hint.get("mobile"):
                kind = "mobile"
        info = RobotInfo(rid, rtype, kind, base=base)
        if kind == "arm" and rtype:
            info.arm = self.arm_model(rtype)
        if kind == "mobile" and rtype in self._robot_types():
            d = self._robot_types()[rtype]["desc"]
            radius = _field(d, "radius", "base_radius", default=None)
            if radius:
                info.radius = float(radius)
        return info

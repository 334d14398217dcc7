"""Which :class:`~sim_peer.robot.SimRobot` class simulates a robot type: found from the type's description.

One path: the description's ``[robot] hooks`` names the class, as ``"package.module:Class"`` (an importable
module, e.g. in an installed package) or ``"file.py:Class"`` (a Python file in the folder of ``robot.toml``, loaded
from there: a robot folder dropped on ``ROBOFABRIC_ROBOTS_PATH`` brings its MJCF, its description and its hooks).
Only descriptions the operator installed get here: a type another peer names is looked up by name
(:func:`robots.installed`), never read from a path it sends, so nothing a query carries is imported.
A description without ``hooks`` gets the built-in class of its ``kind`` (:data:`BUILTIN`, the sim's registry
keyed by the kinds of :data:`robots.kinds.KINDS`: ``arm``: :class:`ArmRobot`, ``mobile``: :class:`MobileRobot`).
Classes are checked once (a :class:`SimRobot` subclass, no misspelt hook) and kept per reference.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
import threading
from pathlib import Path

from robots import RobotDescription
from sim_peer.physics.errors import WorldError
from sim_peer.robot import SimRobot, check_hooks

BUILTIN = {"arm": "sim_peer.physics.robot_kinds:ArmRobot", "mobile": "sim_peer.physics.robot_kinds:MobileRobot"}
"""The built-in class of each kind, keyed by its name in :data:`robots.kinds.KINDS` (a kind without one here
needs ``hooks`` in every description of it)."""

_cache: dict[tuple[str, str], type[SimRobot]] = {}
_lock = threading.Lock()


def robot_class(desc: RobotDescription) -> type[SimRobot]:
    """The class that simulates robots of type ``desc``; :class:`WorldError` naming the description if none."""
    ref = desc.hooks or BUILTIN.get(desc.kind, "")
    if not ref:
        raise WorldError(f"robot type {desc.name}: no hooks given and no built-in robot of kind {desc.kind!r}")
    module, _, name = ref.partition(":")
    base = str(desc.directory) if module.endswith(".py") else ""
    with _lock:
        cls = _cache.get((base, ref))
        if cls is None:
            cls = _load(desc, module, name)
            _cache[(base, ref)] = cls
    return cls


def _load(desc: RobotDescription, module: str, name: str) -> type[SimRobot]:
    where = f"robot type {desc.name} (hooks {module}:{name})"
    try:
        mod = (
            _import_file(_inside(desc, module), desc.name)
            if module.endswith(".py")
            else importlib.import_module(module)
        )
    except WorldError:
        raise
    except Exception as exc:  # the plug-in's own import error, whatever it is, named with the robot type
        raise WorldError(f"{where}: cannot import: {type(exc).__name__}: {exc}") from exc
    cls = getattr(mod, name, None)
    if not (isinstance(cls, type) and issubclass(cls, SimRobot)):
        raise WorldError(f"{where}: {name} is not a sim_peer.robot.SimRobot subclass in {module}")
    try:
        return check_hooks(cls)
    except TypeError as exc:
        raise WorldError(f"{where}: {exc}") from None


def _inside(desc: RobotDescription, module: str) -> Path:
    """The hooks file of ``desc``: inside its robot folder (``hooks = "../../x.py:C"`` is refused, not imported)."""
    folder = Path(desc.directory).resolve()
    path = (folder / module).resolve()
    if not path.is_relative_to(folder):
        raise WorldError(f"robot type {desc.name}: hooks file {module!r} is outside its folder {folder}")
    return path


def _import_file(path: Path, type_name: str):
    if not path.is_file():
        raise WorldError(f"robot type {type_name}: hooks file {path} does not exist")
    mod_name = f"robofabric_robot_{type_name}_{abs(hash(str(path.resolve())))}"
    if mod_name in sys.modules:
        return sys.modules[mod_name]
    spec = importlib.util.spec_from_file_location(mod_name, path)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules[mod_name] = mod
    try:
        spec.loader.exec_module(mod)
    except BaseException:
        del sys.modules[mod_name]
        raise
    return mod


__all__ = ["BUILTIN", "robot_class"]

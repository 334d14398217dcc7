"""A robot type made from a URDF: the folder ``robofabric robots add FILE.urdf`` writes.

From one URDF it writes ``NAME/`` with everything the peers need and nothing outside it:

- ``NAME.urdf``: the URDF with its meshes' ``package://`` and relative paths pointing into ``meshes/`` (the compute
  peer's Pinocchio model, the viewers' meshes, ROS 2's ``robot_description``); a continuous joint becomes
  revolute over ±2π (the controllers and the IK need a range); a joint off the arm's chain becomes fixed;
- ``NAME.xml``: the MJCF MuJoCo's URDF compiler makes of it (collision geometry; a ``flange`` site at the tip
  link), compiled once as the dry build;
- ``meshes/``: the meshes it names, copied;
- ``robot.toml``: kind ``arm``, the chain's joints, their limits and speeds, the flange.

What it cannot take is said, not hidden: a closed chain, a floating or planar joint or a mimic joint on the chain
is refused (:class:`~robots.description.DescriptionError`); a mesh it cannot find or MuJoCo cannot read, a joint
off the chain, a missing speed limit are taken with a note in :attr:`Imported.notes`.
"""

from __future__ import annotations

import os
import re
import shutil
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from robots.description import ENV_PATH, DescriptionError
from robots.urdf import DEFAULT_SPEED, TURN, ArmChain, arm_chain, parse

MUJOCO_MESHES = (".stl", ".obj", ".msh")
"""Mesh formats MuJoCo reads; a collision mesh in another format (``.dae``) is left out of the MJCF, with a note."""
FLANGE_SITE = "flange"
_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_-]{0,63}$")


@dataclass(frozen=True, slots=True)
class Imported:
    """What ``robots add`` made: the type's name and folder, its arm, what it copied and what it could not take."""

    name: str
    directory: Path
    arm: ArmChain
    root_body: str
    meshes: int
    notes: tuple[str, ...]


def default_folder() -> Path:
    """Where a new type goes: the first folder of ``ROBOFABRIC_ROBOTS_PATH`` (so ``robots.installed`` finds it)."""
    dirs = [p for p in os.environ.get(ENV_PATH, "").split(os.pathsep) if p]
    if not dirs:
        raise DescriptionError(f"{ENV_PATH} is not set: name a folder for installed robots there (or pass --into)")
    return Path(dirs[0])


def type_name(urdf: Path, name: str | None) -> str:
    """``name``, or the URDF file's stem made a type name; :class:`DescriptionError` if it cannot be one."""
    out = name if name is not None else re.sub(r"[^A-Za-z0-9_-]", "_", urdf.stem)
    if not _NAME.match(out):
        raise DescriptionError(f"robot type name {out!r}: 1-64 letters, digits, '-', '_' (pass --name)")
    return out


def install(
    urdf: Path,
    *,
    into: Path | None = None,
    name: str | None = None,
    tip: str | None = None,
    package_dirs: Sequence[Path] = (),
    replace: bool = False,
) -> Imported:
    """Write the robot type made from ``urdf`` into ``into/NAME`` (default :func:`default_folder`); the folder is
    written whole or not at all (made aside, then moved in place)."""
    urdf = Path(urdf).resolve()
    try:
        text = urdf.read_text()
    except OSError as exc:
        raise DescriptionError(f"cannot read {urdf}: {exc}") from None
    tree = parse(text, str(urdf))
    arm = arm_chain(tree, tip)
    name = type_name(urdf, name)
    into = Path(into) if into is not None else default_folder()
    dest = into / name
    if dest.exists() and not replace:
        raise DescriptionError(f"{dest} exists: pass --replace to write the type {name!r} again")
    into.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=into, prefix=f".{name}-") as tmp:
        work = Path(tmp) / name
        work.mkdir()
        notes = list(arm.notes)
        doc = ET.fromstring(text)
        meshes = _copy_meshes(doc, urdf, work, list(package_dirs), notes)
        _make_revolute(doc)
        _weld(doc, arm.locked)
        (work / f"{name}.urdf").write_text(ET.tostring(doc, encoding="unicode"))
        root_body = _write_mjcf(doc, work, name, arm, notes)
        (work / "robot.toml").write_text(_manifest(name, urdf, arm, root_body))
        if dest.exists():
            shutil.rmtree(dest)
        work.rename(dest)
    return Imported(name, dest, arm, root_body, meshes, tuple(notes))


# --------------------------------------------------------------------------- meshes


def resolve_mesh(filename: str, urdf: Path, package_dirs: Sequence[Path] = ()) -> Path | None:
    """The file a URDF's mesh ``filename`` names: ``package://PKG/rest`` in a folder named ``PKG`` among
    ``package_dirs``, ``ROS_PACKAGE_PATH`` and the URDF's own parent folders; ``file://`` and plain paths relative
    to the URDF. ``None`` when there is no such file."""
    if filename.startswith("package://"):
        pkg, _, rest = filename[len("package://") :].partition("/")
        roots = [*package_dirs, *(Path(p) for p in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if p)]
        cands = [d / pkg / rest for d in roots] + [d / rest for d in roots if d.name == pkg]
        cands += [d / rest for d in urdf.parents if d.name == pkg]
        return next((c for c in cands if c.is_file()), None)
    path = Path(filename[len("file://") :] if filename.startswith("file://") else filename)
    path = path if path.is_absolute() else urdf.parent / path
    return path if path.is_file() else None


def _copy_meshes(doc: ET.Element, urdf: Path, work: Path, package_dirs: list[Path], notes: list[str]) -> int:
    """Copy every mesh the URDF names into ``work/meshes`` and point the URDF there; a geometry whose mesh is
    missing is dropped from the URDF (and said)."""
    copied: dict[Path, str] = {}
    for link in doc.findall("link"):
        for part in [*link.findall("visual"), *link.findall("collision")]:
            mesh = part.find("geometry/mesh")
            if mesh is None:
                continue
            filename = str(mesh.get("filename", ""))
            src = resolve_mesh(filename, urdf, package_dirs)
            if src is None:
                notes.append(f"link {link.get('name')}: {part.tag} mesh {filename} not found: left out")
                link.remove(part)
                continue
            if src not in copied:
                rel = f"meshes/{src.parent.name}/{src.name}"
                while rel in copied.values():
                    rel = f"meshes/{len(copied)}_{src.parent.name}/{src.name}"
                (work / rel).parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(src, work / rel)
                copied[src] = rel
            mesh.set("filename", copied[src])
    return len(copied)


def _make_revolute(doc: ET.Element) -> None:
    """Continuous joints become revolute over ±2π (one coordinate each, the range the robot.toml gives); a
    ``<limit>`` without ``effort`` or ``velocity`` gets them (0, and the speed taken), as urdfdom (Pinocchio's
    and ROS 2's parser) refuses a limit without them."""
    for j in doc.findall("joint"):
        for limit in j.findall("limit"):
            limit.set("effort", limit.get("effort") or "0")
            limit.set("velocity", limit.get("velocity") or repr(DEFAULT_SPEED))
        if j.get("type") == "continuous":
            j.set("type", "revolute")
            limit = j.find("limit")
            if limit is None:
                limit = ET.SubElement(j, "limit", effort="0")
            limit.set("lower", repr(-TURN))
            limit.set("upper", repr(TURN))


def _weld(doc: ET.Element, joints: Sequence[str]) -> None:
    """The joints off the arm's chain (a gripper's fingers) become fixed at zero, as the sim welds them: every
    reader of the URDF (the compute peer, the viewers, ROS 2's ``robot_description``) sees the joints the sim
    streams, no more."""
    for j in doc.findall("joint"):
        if j.get("name") in joints:
            j.set("type", "fixed")
            for tag in ("limit", "mimic", "axis", "dynamics", "safety_controller", "calibration"):
                for e in j.findall(tag):
                    j.remove(e)


# --------------------------------------------------------------------------- MJCF


def _mujoco_urdf(doc: ET.Element, notes: list[str]) -> str:
    """The URDF as MuJoCo's compiler should read it: collision geometry only, meshes it reads, bodies kept apart
    (``fusestatic`` off: the tip link may be a fixed one), paths as written (``strippath`` off)."""
    doc = ET.fromstring(ET.tostring(doc))
    for link in doc.findall("link"):
        for part in link.findall("visual"):
            link.remove(part)
        for part in link.findall("collision"):
            mesh = part.find("geometry/mesh")
            if mesh is not None and Path(str(mesh.get("filename", ""))).suffix.lower() not in MUJOCO_MESHES:
                notes.append(
                    f"link {link.get('name')}: collision mesh {mesh.get('filename')} is not a format MuJoCo "
                    f"reads ({', '.join(MUJOCO_MESHES)}): left out of the simulation"
                )
                link.remove(part)
    ext = ET.Element("mujoco")
    ET.SubElement(
        ext,
        "compiler",
        strippath="false",
        discardvisual="true",
        fusestatic="false",
        boundmass="1e-4",
        boundinertia="1e-8",
    )
    doc.insert(0, ext)
    return ET.tostring(doc, encoding="unicode")


def _write_mjcf(doc: ET.Element, work: Path, name: str, arm: ArmChain, notes: list[str]) -> str:
    """Compile the URDF (its joints off the chain welded already) with MuJoCo, add the flange site, compile again
    (the dry build) and write ``NAME.xml``; returns the root body's name."""
    import mujoco

    src = work / f".{name}.mujoco.urdf"
    src.write_text(_mujoco_urdf(doc, notes))
    try:
        spec = mujoco.MjSpec.from_file(str(src))
        tip = spec.body(arm.tip)
        if tip is None:
            raise DescriptionError(f"MuJoCo's URDF compiler merged the tip link {arm.tip!r} away: pick another --tip")
        tip.add_site(name=FLANGE_SITE, size=[0.005, 0, 0], rgba=[1, 0.3, 0.1, 1], group=3)
        roots = list(spec.worldbody.bodies)
        if len(roots) != 1:
            raise DescriptionError(f"MuJoCo made {len(roots)} root bodies of the URDF, the sim attaches one")
        spec.compile()
        (work / f"{name}.xml").write_text(spec.to_xml())
    except ValueError as exc:  # MuJoCo's parse and compile errors
        raise DescriptionError(f"MuJoCo's URDF compiler: {exc}") from None
    finally:
        src.unlink(missing_ok=True)
    return roots[0].name


def _toml_list(values: Sequence[object]) -> str:
    return "[" + ", ".join(f'"{v}"' if isinstance(v, str) else repr(float(v)) for v in values) + "]"


def _manifest(name: str, urdf: Path, arm: ArmChain, root_body: str) -> str:
    return "\n".join(
        [
            f"# written by `robofabric robots add {urdf.name}`; edit freely, or add the URDF again with --replace",
            "[robot]",
            f'name = "{name}"',
            'kind = "arm"',
            f'description = "{name}, from {urdf.name} ({len(arm.joints)} joints)"',
            f'urdf = "{name}.urdf"',
            f'mjcf = "{name}.xml"',
            f'root_body = "{root_body}"',
            f'flange_site = "{FLANGE_SITE}"',
            f'flange_frame = "{arm.tip}"',
            f"joints = {_toml_list(arm.joints)}",
            f"lower = {_toml_list(arm.lower)}",
            f"upper = {_toml_list(arm.upper)}",
            f"max_speed = {_toml_list(arm.max_speed)}",
            "",
        ]
    )


__all__ = ["FLANGE_SITE", "Imported", "MUJOCO_MESHES", "default_folder", "install", "resolve_mesh", "type_name"]

"""Robot types another peer names are installed names, never paths (a move_in naming a path to
a student's own robot.toml would run her hooks inside the sim). ``robots.installed`` looks a NAME up in the operator's
folders (ROBOFABRIC_ROBOTS_PATH, the ``robofabric.robots`` entry points, the robots package); the registry imports a
hooks file only from inside its robot's folder. The operator's own command line keeps paths (``robots.load``)."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import pytest

import robots
from robots.description import ENTRY_POINTS, plugin_dirs
from sim_peer.physics.errors import WorldError
from sim_peer.physics.registry import robot_class

PLANAR2 = Path(__file__).parents[1] / "plugin_robots" / "planar2"
EVIL_HOOKS = "from pathlib import Path\nPath({marker!r}).write_text('ran')\nfrom sim_peer import ArmRobot as Evil\n"


def _evil_robot(folder: Path, marker: Path, hooks: str = "hooks.py:Evil") -> Path:
    """A robot folder whose hooks write ``marker`` when imported (what mallory sent the sim's path to)."""
    folder.mkdir(parents=True)
    for f in ("planar2.xml", "robot.toml"):
        shutil.copy(PLANAR2 / f, folder / f)
    toml = (folder / "robot.toml").read_text().replace('name = "planar2"', f'name = "{folder.name}"')
    (folder / "robot.toml").write_text(toml.replace("hooks.py:Planar2Arm", hooks))
    (folder / "hooks.py").write_text(EVIL_HOOKS.format(marker=str(marker)))
    return folder


@pytest.mark.parametrize(
    "name", ["/tmp/evil", "../reeman", "reeman/robot.toml", "./reeman", "evil.toml", "", "a" * 65, "re man"]
)
def test_a_type_another_peer_names_is_a_name_never_a_path(name):
    with pytest.raises(robots.DescriptionError, match="is not a type name"):
        robots.installed(name)


def test_an_installed_name_is_found_in_the_operators_folders_only(tmp_path, monkeypatch):
    marker = tmp_path / "ran"
    evil = _evil_robot(tmp_path / "cwd" / "evil", marker)
    monkeypatch.chdir(evil.parent)  # a folder named like the type in the working directory is not installed
    assert robots.load("evil").name == "evil"  # the operator's command line may name it (a path, or a folder here)
    with pytest.raises(robots.DescriptionError, match="'evil' is not installed here"):
        robots.installed("evil")
    with pytest.raises(robots.DescriptionError, match="is not a type name"):
        robots.installed(str(evil))
    assert robots.installed("reeman").name == "reeman"  # the robots package
    monkeypatch.setenv(robots.description.ENV_PATH, str(PLANAR2.parent))  # the operator's path
    assert robots.installed("planar2").directory == PLANAR2
    assert not marker.exists()  # looked up, read: nothing of it ran


def test_robots_of_an_entry_point_package_are_installed(tmp_path, monkeypatch):
    """A package installs robots with an entry point of group robofabric.robots naming it: its folder is searched."""
    pkg = tmp_path / "site" / "classbots"
    pkg.mkdir(parents=True)
    (pkg / "__init__.py").write_text("raise RuntimeError('a robots package is found, not imported')\n")
    shutil.copytree(PLANAR2, pkg / "planar2")
    dist = tmp_path / "site" / "classbots-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: classbots\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text(f"[{ENTRY_POINTS}]\nclassbots = classbots\n")
    monkeypatch.syspath_prepend(str(tmp_path / "site"))
    plugin_dirs.cache_clear()
    try:
        assert pkg in plugin_dirs()
        assert robots.installed("planar2").directory == pkg / "planar2"
        assert "planar2" in robots.available_robots()
        assert "classbots" not in sys.modules
    finally:
        plugin_dirs.cache_clear()


def test_a_hooks_file_outside_its_robots_folder_is_not_imported(tmp_path, monkeypatch):
    marker = tmp_path / "ran"
    outside = _evil_robot(tmp_path / "elsewhere" / "evil", marker)
    robot = _evil_robot(tmp_path / "path" / "planar9", marker, hooks="../../elsewhere/evil/hooks.py:Evil")
    monkeypatch.setenv(robots.description.ENV_PATH, str(robot.parent))
    with pytest.raises(WorldError, match="outside its folder"):
        robot_class(robots.installed("planar9"))
    assert not marker.exists() and outside.is_dir()

"""``robofabric robots add FILE.urdf`` and ``robofabric robots list``: a lab's own arm as an installed robot type.

``add`` writes the type (:mod:`robots.urdf_import`) into the first folder of ``ROBOFABRIC_ROBOTS_PATH`` (or
``--into``), runs the dry build (:mod:`robofabric.robot_check`) and says what it could not take; a type the dry
build refuses is removed again, so an installed type is one the sim and the compute peer both take.
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Annotated, Optional

import typer

from fabric.cli_common import UserError

robots_app = typer.Typer(help="Robot types: add one from a URDF, list the installed ones.", no_args_is_help=True)


@robots_app.command("add")
def add_cmd(
    urdf: Annotated[
        Path, typer.Argument(help="The robot's URDF; its meshes are found from package:// and relative paths.")
    ],
    name: Annotated[Optional[str], typer.Option("--name", help="The type's name (default: the file's name).")] = None,
    tip: Annotated[
        Optional[str],
        typer.Option("--tip", help="The flange link (default: past the last revolute joint, along fixed joints)."),
    ] = None,
    into: Annotated[
        Optional[Path],
        typer.Option("--into", help="Folder to write the type into (default: the first of ROBOFABRIC_ROBOTS_PATH)."),
    ] = None,
    package_path: Annotated[
        Optional[list[Path]],
        typer.Option(
            "--package-path",
            help="A folder holding ROS packages, for package:// meshes (repeatable; ROS_PACKAGE_PATH too).",
        ),
    ] = None,
    replace: Annotated[bool, typer.Option("--replace", help="Write the type again when it exists.")] = False,
) -> None:
    """Make an installed arm type from a URDF: its MJCF by MuJoCo's URDF compiler, its meshes copied, its joint
    limits, speeds and flange in robot.toml. A dry build checks that the sim takes it and that the compute peer's
    FK agrees with the sim's; what could not be taken (a gripper's joints, a mesh MuJoCo cannot read) is listed."""
    from robofabric.robot_check import dry_build
    from robots import DescriptionError
    from robots.urdf_import import install

    try:
        made = install(urdf, into=into, name=name, tip=tip, package_dirs=package_path or (), replace=replace)
    except DescriptionError as exc:
        raise UserError(str(exc)) from None
    try:
        check = dry_build(made.directory)
    except DescriptionError as exc:
        shutil.rmtree(made.directory, ignore_errors=True)
        raise UserError(f"{exc}; {made.name} was not installed") from None
    arm = made.arm
    print(
        f"installed {made.name} in {made.directory}: {len(arm.joints)} joints ({', '.join(arm.joints)}), "
        f"flange {arm.tip}, root body {made.root_body}, {made.meshes} meshes"
    )
    fk = (
        "no Pinocchio here: the compute peer's FK is not checked"
        if check.fk_gap is None
        else f"the compute peer's FK agrees with the sim's within {check.fk_gap:.1g} m/rad ({check.samples} random poses)"
    )
    print(f"dry build: the sim builds a world with it; {fk}")
    for note in made.notes:
        print(f"not taken as is: {note}")


@robots_app.command("list")
def list_cmd() -> None:
    """The robot types installed here (ROBOFABRIC_ROBOTS_PATH, robot packages, the built-in ones): kind, joints,
    folder."""
    import robots

    for name in robots.available_robots():
        try:
            d = robots.installed(name)
        except robots.DescriptionError as exc:
            print(f"{name:16} broken: {exc}")
            continue
        print(f"{name:16} {d.kind:7} {d.dof} joints  {d.directory}")


def register(app: typer.Typer) -> None:
    app.add_typer(robots_app, name="robots")

"""``robofabric robots add FILE.urdf``: a lab's arm from its URDF becomes an installed robot type (robots.urdf,
robots.urdf_import, the dry build of robofabric.robot_check), shown on real descriptions (example-robot-data's
UR5 and Panda) and on small URDFs written here for what it must refuse or say."""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np
import pytest

import robots
from robofabric import cli
from robofabric.testing import example_robot_urdf
from robots import urdf
from robots.urdf_import import install

UR5 = "ur_description/urdf/ur5_robot.urdf"
PANDA = "panda_description/urdf/panda.urdf"


def _robots(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    folder = tmp_path / "robots"
    monkeypatch.setenv(robots.description.ENV_PATH, str(folder))
    return folder


def _run(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str]:
    """``robofabric ARGS`` in this process: its exit code and what it printed."""
    code = cli.main(list(args))
    out = capsys.readouterr()
    return code, out.out + out.err


@pytest.mark.slow  # the whole CLI in this process, two robots built and dry-built: seconds
def test_add_makes_installed_types_of_the_ur5_and_the_panda_that_the_list_shows(tmp_path, monkeypatch, capsys):
    folder = _robots(tmp_path, monkeypatch)
    code, out = _run(capsys, "robots", "add", str(example_robot_urdf(UR5)), "--name", "ur5")
    assert code == 0, out
    assert "6 joints" in out and "flange tool0" in out and "the compute peer's FK agrees with the sim's" in out
    code, out = _run(capsys, "robots", "add", str(example_robot_urdf(PANDA)), "--name", "panda")
    assert code == 0, out
    # the gripper's fingers are said, not hidden: one prismatic, one mimicking it
    assert "panda_finger_joint1 (prismatic" in out and "panda_finger_joint2 (mimics panda_finger_joint1)" in out
    ur5, panda = robots.installed("ur5"), robots.installed("panda")
    assert ur5.directory == folder / "ur5" and ur5.kind == "arm" and ur5.dof == 6
    assert ur5.joint_names == (
        "shoulder_pan_joint",
        "shoulder_lift_joint",
        "elbow_joint",
        "wrist_1_joint",
        "wrist_2_joint",
        "wrist_3_joint",
    )
    assert ur5.max_speed == (3.15, 3.15, 3.15, 3.2, 3.2, 3.2) and ur5.upper[2] == pytest.approx(math.pi)
    assert panda.dof == 7 and panda.flange_frame == "panda_hand_tcp" and panda.lower[3] == -3.0718
    # the folder carries its meshes: the MJCF compiles from anywhere, without the package it came from
    model = mujoco.MjModel.from_xml_path(str(panda.mjcf_path))
    assert model.njnt == 7 and model.nmesh >= 8 and (folder / "panda" / "meshes" / "collision" / "link0.stl").is_file()
    assert "package://" not in panda.urdf_path.read_text()  # the URDF points into the folder too
    code, listed = _run(capsys, "robots", "list")
    assert code == 0, listed
    assert any(line.split()[:4] == ["panda", "arm", "7", "joints"] for line in listed.splitlines()), listed
    assert any(line.split()[:2] == ["meca500", "arm"] for line in listed.splitlines()), listed
    code, out = _run(capsys, "robots", "add", str(example_robot_urdf(UR5)), "--name", "ur5")
    assert code == 2 and "--replace" in out  # an installed type is not overwritten by accident


def test_the_sim_flange_and_the_compute_fk_agree_at_random_joints(tmp_path, monkeypatch):
    """The two compilers of one URDF (MuJoCo for the sim, Pinocchio for the compute peer) put the flange at the
    same place: what IK solves, the sim reaches."""
    from compute_peer.kinematics.ik_common import rotation_error
    from compute_peer.kinematics.model import ArmModel

    folder = _robots(tmp_path, monkeypatch)
    made = install(example_robot_urdf(PANDA), into=folder, name="panda")
    arm = ArmModel("panda")
    model = mujoco.MjModel.from_xml_path(str(made.directory / "panda.xml"))
    data = mujoco.MjData(model)
    rng = np.random.default_rng(3)
    for _ in range(10):
        q = rng.uniform(arm.lower, arm.upper)
        for name, v in zip(made.arm.joints, q):
            data.qpos[model.joint(name).qposadr[0]] = v
        mujoco.mj_kinematics(model, data)
        m = arm.fk(q)
        assert np.linalg.norm(data.site("flange").xpos - m.translation) < 1e-9
        # the MJCF writes rotations with 6 significant digits: a micro-radian apart
        assert rotation_error(data.site("flange").xmat.reshape(3, 3), m.rotation) < 1e-5


def _tiny(joints: str, links: str = "", meshes: str = "") -> str:
    return (
        f'<robot name="tiny"><link name="base"/><link name="l1">{meshes}</link><link name="l2"/>{links}{joints}</robot>'
    )


def _j(name: str, kind: str, parent: str, child: str, extra: str = "") -> str:
    return (
        f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
        f'<axis xyz="0 0 1"/><origin xyz="0 0 0.1"/>{extra}</joint>'
    )


LIMIT = '<limit lower="-1" upper="1" velocity="2" effort="1"/>'


def test_what_cannot_be_taken_is_refused_with_the_reason():
    chain = _j("a", "revolute", "base", "l1", LIMIT) + _j("b", "revolute", "l1", "l2", LIMIT)
    closed = chain + _j("c", "revolute", "base", "l2", LIMIT)
    with pytest.raises(robots.DescriptionError, match="closed chain"):
        urdf.parse(_tiny(closed))
    floating = _j("a", "floating", "base", "l1") + _j("b", "revolute", "l1", "l2", LIMIT)
    with pytest.raises(robots.DescriptionError, match="mobile bases from URDF"):
        urdf.arm_chain(urdf.parse(_tiny(floating)))
    mimic = _j("a", "revolute", "base", "l1", LIMIT) + _j("b", "revolute", "l1", "l2", LIMIT + '<mimic joint="a"/>')
    with pytest.raises(robots.DescriptionError, match="mimic"):
        urdf.arm_chain(urdf.parse(_tiny(mimic)))
    unlimited = _j("a", "revolute", "base", "l1") + _j("b", "revolute", "l1", "l2", LIMIT)
    with pytest.raises(robots.DescriptionError, match="no usable <limit"):
        urdf.arm_chain(urdf.parse(_tiny(unlimited)))
    with pytest.raises(robots.DescriptionError, match="not a link"):
        urdf.arm_chain(urdf.parse(_tiny(chain)), "nowhere")
    with pytest.raises(robots.DescriptionError, match="one root link"):
        urdf.parse('<robot name="two"><link name="a"/><link name="b"/></robot>')


def test_continuous_joints_missing_speeds_and_missing_meshes_are_taken_with_a_note(tmp_path):
    mesh = '<collision><geometry><mesh filename="package://nowhere/meshes/l1.stl"/></geometry></collision>'
    box = '<collision><geometry><box size="0.02 0.02 0.1"/></geometry></collision>'
    (tmp_path / "parts").mkdir()  # a mesh named by a path relative to the URDF
    stl = example_robot_urdf(UR5).parents[1] / "meshes" / "ur5" / "collision" / "wrist3.stl"
    (tmp_path / "parts" / "l1.stl").write_bytes(stl.read_bytes())
    relative = '<collision><geometry><mesh filename="parts/l1.stl"/></geometry></collision>'
    text = _tiny(
        _j("a", "continuous", "base", "l1") + _j("b", "revolute", "l1", "l2", '<limit lower="-2" upper="2"/>'),
        meshes=mesh + box + relative,
    )
    src = tmp_path / "tiny.urdf"
    src.write_text(text)
    made = install(src, into=tmp_path / "robots")
    assert made.name == "tiny" and made.arm.joints == ("a", "b") and made.arm.tip == "l2"
    assert made.arm.lower == (-2 * math.pi, -2.0) and made.arm.max_speed == (urdf.DEFAULT_SPEED, urdf.DEFAULT_SPEED)
    notes = "\n".join(made.notes)
    assert (
        "package://nowhere/meshes/l1.stl not found" in notes and "continuous" in notes and "no velocity limit" in notes
    )
    desc = robots.load(str(made.directory))
    model = mujoco.MjModel.from_xml_path(str(desc.mjcf_path))
    # the box and the relative mesh (copied into the folder) stayed, the missing mesh went; the flange site is there
    assert model.ngeom == 2 and model.nmesh == 1 and model.nsite == 1 and made.meshes == 1
    assert (made.directory / "meshes" / "parts" / "l1.stl").is_file()
    assert '"revolute"' in desc.urdf_path.read_text()  # Pinocchio reads one coordinate for it


def test_the_default_tip_follows_fixed_joints_past_the_last_revolute_one():
    ur5 = urdf.parse(example_robot_urdf(UR5).read_text())
    panda = urdf.parse(example_robot_urdf(PANDA).read_text())
    assert urdf.default_tip(ur5) == "tool0"
    assert urdf.default_tip(panda) == "panda_hand_tcp"  # not into the fingers: they move by prismatic joints
    arm = urdf.arm_chain(panda, "panda_link8")
    assert (
        arm.tip == "panda_link8"
        and len(arm.joints) == 7
        and arm.locked == ("panda_finger_joint1", "panda_finger_joint2")
    )


def test_every_reader_of_the_written_urdf_sees_the_joints_the_sim_streams(tmp_path):
    """The Panda's fingers are fixed in the URDF it writes, as in its MJCF: the compute peer, the viewers' models
    (Pinocchio's, and the console's numpy chain) and ROS 2's robot_description all see its 7 joints."""
    import pinocchio as pin

    from user_peer.urdf_chain import UrdfChain

    made = install(example_robot_urdf(PANDA), into=tmp_path, name="panda")
    written = made.directory / "panda.urdf"
    tree = urdf.parse(written.read_text())
    assert [j.name for j in tree.joints if j.type != "fixed"] == list(made.arm.joints)
    assert pin.buildModelFromUrdf(str(written)).nq == 7 and UrdfChain.from_file(written).nq == 7
    # the viewers' model: 7 joints, every link drawn (its .dae visuals Rerun cannot load: from its collision STL)
    from user_peer.arm_geometry import ArmGeometry

    drawn = ArmGeometry(written)
    assert drawn.model.nq == 7 and len(drawn.shapes) >= 9
    assert all(
        shape.mesh_path.endswith(".stl") and Path(shape.mesh_path).is_file()
        for shape, _, _ in drawn.shapes
        if shape.kind == "mesh"
    )
    assert "<mimic" not in written.read_text()


def test_where_it_goes_and_what_it_is_called_are_checked_before_anything_is_written(tmp_path, monkeypatch):
    src = tmp_path / "my arm.urdf"
    src.write_text(_tiny(_j("a", "revolute", "base", "l1", LIMIT) + _j("b", "revolute", "l1", "l2", LIMIT)))
    monkeypatch.delenv(robots.description.ENV_PATH, raising=False)
    with pytest.raises(robots.DescriptionError, match="ROBOFABRIC_ROBOTS_PATH is not set"):
        install(src)
    with pytest.raises(robots.DescriptionError, match="type name '../up'"):
        install(src, into=tmp_path / "robots", name="../up")
    made = install(src, into=tmp_path / "robots")
    assert made.name == "my_arm" and sorted(p.name for p in (tmp_path / "robots").iterdir()) == ["my_arm"]
    monkeypatch.setenv(robots.description.ENV_PATH, str(tmp_path / "robots"))
    assert robots.installed("my_arm").joint_names == ("a", "b")

"""The Meca500's generated files agree with its geometry, with each other and with an independent DH chain."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import robots
from robots.meca500 import generate

ARM = robots.load("meca500")

# The datasheet's standard DH table, written out here independently of geometry.py (mm, deg):
# T_i = Rz(q_i + offset) Tz(d) Tx(a) Rx(alpha)
DATASHEET_DH = [(0, 135, 0, -90), (-90, 0, 135, 0), (0, 0, 38, -90), (0, 120, 0, 90), (0, 0, 0, -90), (180, 70, 0, 0)]


def dh_fk(q: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    for qi, (off, d, a, alpha) in zip(q, DATASHEET_DH):
        th, al = qi + math.radians(off), math.radians(alpha)
        ct, st_, ca, sa = math.cos(th), math.sin(th), math.cos(al), math.sin(al)
        T = T @ np.array(
            [
                [ct, -st_ * ca, st_ * sa, a / 1000 * ct],
                [st_, ct * ca, -ct * sa, a / 1000 * st_],
                [0, sa, ca, d / 1000],
                [0, 0, 0, 1],
            ]
        )
    return T


def mujoco_fk(q: np.ndarray) -> np.ndarray:
    m = mujoco.MjModel.from_xml_path(str(ARM.mjcf_path))
    d = mujoco.MjData(m)
    for name, v in zip(ARM.joint_names, q):
        d.qpos[m.joint(name).qposadr[0]] = v
    mujoco.mj_kinematics(m, d)
    s = m.site(ARM.flange_site).id
    T = np.eye(4)
    T[:3, :3] = d.site_xmat[s].reshape(3, 3)
    T[:3, 3] = d.site_xpos[s]
    return T


_PIN = pin.buildModelFromUrdf(str(ARM.urdf_path))
_PIN_DATA = _PIN.createData()


def pinocchio_fk(q: np.ndarray) -> np.ndarray:
    pin.framesForwardKinematics(_PIN, _PIN_DATA, np.asarray(q, dtype=float))
    return _PIN_DATA.oMf[_PIN.getFrameId(ARM.flange_frame)].homogeneous


def test_committed_files_are_what_the_geometry_generates(tmp_path):
    assert generate.main([str(tmp_path)]) == 0
    for name in generate.FILES:
        assert (tmp_path / name).read_text() == (ARM.directory / name).read_text(), (
            f"{name} is stale: run python -m robots.meca500.generate"
        )


def test_zero_pose_flange_at_190_0_308_mm_in_every_model():
    q = np.zeros(6)
    for fk in (dh_fk, mujoco_fk, pinocchio_fk):
        np.testing.assert_allclose(fk(q)[:3, 3] * 1000, [190.0, 0.0, 308.0], atol=1e-9, err_msg=fk.__name__)
    # Mecademic's flange frame: z along base +x, x along base -z at zero.
    np.testing.assert_allclose(mujoco_fk(q)[:3, :3], [[0, 0, 1], [0, 1, 0], [-1, 0, 0]], atol=1e-12)


def test_limits_and_speeds_match_the_datasheet():
    deg = [(-175, 175), (-70, 90), (-135, 70), (-170, 170), (-115, 115), (-180, 180)]
    np.testing.assert_allclose(np.degrees(ARM.lower), [lo for lo, _ in deg])
    np.testing.assert_allclose(np.degrees(ARM.upper), [hi for _, hi in deg])
    np.testing.assert_allclose(np.degrees(ARM.max_speed), [150, 150, 180, 300, 300, 500])
    m = mujoco.MjModel.from_xml_path(str(ARM.mjcf_path))
    for name, lo, hi in zip(ARM.joint_names, ARM.lower, ARM.upper):
        np.testing.assert_allclose(m.joint(name).range, [lo, hi])
    np.testing.assert_allclose(_PIN.lowerPositionLimit, ARM.lower)
    np.testing.assert_allclose(_PIN.velocityLimit, ARM.max_speed)


joint_values = st.tuples(*(st.floats(lo, hi) for lo, hi in zip(ARM.lower, ARM.upper)))


@settings(max_examples=60, deadline=None)
@given(joint_values)
def test_fk_agrees_with_an_independent_dh_chain(q):
    q = np.array(q)
    T_dh = dh_fk(q)
    for fk in (mujoco_fk, pinocchio_fk):
        T = fk(q)
        np.testing.assert_allclose(T[:3, 3], T_dh[:3, 3], atol=1e-9, err_msg=fk.__name__)
        np.testing.assert_allclose(T[:3, :3], T_dh[:3, :3], atol=1e-9, err_msg=fk.__name__)


def test_positive_j2_leans_the_arm_forward_and_positive_j3_lowers_the_forearm():
    """Sign conventions as on the real robot (and in Mecademic's jogging)."""
    z0 = mujoco_fk(np.zeros(6))[2, 3]
    assert mujoco_fk(np.array([0, 0.3, 0, 0, 0, 0]))[0, 3] > 0.19
    assert mujoco_fk(np.array([0, 0, 0.3, 0, 0, 0]))[2, 3] < z0
    assert mujoco_fk(np.array([0.3, 0, 0, 0, 0, 0]))[1, 3] > 0  # J1 counter-clockwise seen from above


@pytest.mark.parametrize("name", ["arm_cell", "warehouse", "combined"])
def test_scenes_name_their_robots_and_the_target_and_goal_as_mocap_bodies(name):
    sc = robots.scene(name)
    m = mujoco.MjModel.from_xml_path(str(sc.mjcf_path))
    ids = {o.id for o in sc.objects}
    assert {"target", "goal"} <= ids
    for o in sc.objects:
        assert m.body_mocapid[m.body(o.body).id] >= 0, f"{o.body} is not a mocap body"
    for r in sc.robots:
        assert robots.load(r.type).name == r.type


def test_unknown_robot_and_bad_manifest_are_clear_errors(tmp_path):
    with pytest.raises(robots.DescriptionError, match="unknown robot type 'nope'"):
        robots.load("nope")
    bad = tmp_path / "robot.toml"
    bad.write_text('[robot]\nkind = "tank"\n')
    with pytest.raises(robots.DescriptionError, match="kind must be one of"):
        robots.load(str(bad))

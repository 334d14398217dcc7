"""The URDF chain the console draws an arm with: the same joint origins as Pinocchio's FK, and clear errors."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import robots
from user_peer.urdf_chain import UrdfChain, UrdfError

MECA = robots.load("meca500").urdf_path


@pytest.fixture(scope="module")
def both():
    from user_peer.arm_geometry import ArmGeometry

    return UrdfChain.from_file(MECA), ArmGeometry(MECA)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-3.0, 3.0), min_size=6, max_size=6))
def test_joint_origins_match_pinocchio(both, q):
    chain, geometry = both
    assert chain.moving == list(geometry.joint_names)
    ours = chain.origins(q)
    theirs = np.array([p.translation for p in geometry.fk(q)[1:]])  # Pinocchio's universe first
    assert np.allclose(ours[: len(theirs)], theirs, atol=1e-9)
    assert len(ours) == len(theirs) + 1  # the fixed flange joint ends the chain


def test_a_prismatic_joint_and_a_fixed_rotation():
    urdf = """<robot name="r"><link name="a"/><link name="b"/><link name="c"/>
      <joint name="lift" type="prismatic"><parent link="a"/><child link="b"/><origin xyz="1 0 0" rpy="0 0 1.5707963267948966"/>
        <axis xyz="1 0 0"/></joint>
      <joint name="tip" type="fixed"><parent link="b"/><child link="c"/><origin xyz="0.5 0 0"/></joint></robot>"""
    chain = UrdfChain(urdf)
    pts = chain.origins([0.25])
    assert np.allclose(pts, [[1.0, 0.25, 0.0], [1.0, 0.75, 0.0]])  # the yaw turns the slide and the tip onto +y


@pytest.mark.parametrize(
    "text, words",
    [
        ("<robot", "not XML"),
        ("<robot name='r'><link name='a'/></robot>", "no joints"),
        (
            "<robot><joint name='j' type='fixed'><parent link='a'/><child link='b'/><origin xyz='1 2'/></joint></robot>",
            "three numbers",
        ),
        (
            "<robot><joint name='j' type='fixed'><parent link='a'/><child link='b'/></joint>"
            "<joint name='k' type='fixed'><parent link='b'/><child link='a'/></joint></robot>",
            "root link",
        ),
    ],
)
def test_a_urdf_it_cannot_read_says_why(text, words):
    with pytest.raises(UrdfError, match=words):
        UrdfChain(text)


def test_a_joint_vector_of_the_wrong_length_is_refused():
    with pytest.raises(ValueError, match="6 moving joints, got 5"):
        UrdfChain.from_file(MECA).origins([0.0] * 5)

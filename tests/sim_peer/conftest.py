"""A room with walls at known distances, written as a scene (data) in a temporary folder."""

from __future__ import annotations

import pytest

import robots

ROOM_XML = """<mujoco model="room">
  <worldbody>
    <geom name="floor" type="plane" size="10 10 0.1"/>
    <geom name="front" type="box" pos="{front_c} 0 0.5" size="0.05 3 0.5"/>
    <geom name="left" type="box" pos="0 {left_c} 0.5" size="3 0.05 0.5"/>
    <geom name="right" type="box" pos="0 {right_c} 0.5" size="3 0.05 0.5"/>
    <body name="goal" mocap="true" pos="1 0 0.25">
      <geom type="box" size="0.1 0.1 0.3" contype="0" conaffinity="0" group="3"/>
    </body>
    <body name="target" mocap="true" pos="0 0 -1"><geom type="sphere" size="0.02" group="3"/></body>
  </worldbody>
</mujoco>
"""

FRONT, LEFT, RIGHT = 2.0, 1.5, -1.0  # inner faces of the walls: x = 2, y = 1.5, y = -1


@pytest.fixture
def room(tmp_path) -> robots.SceneDescription:
    (tmp_path / "room.xml").write_text(ROOM_XML.format(front_c=FRONT + 0.05, left_c=LEFT + 0.05, right_c=RIGHT - 0.05))
    (tmp_path / "room.toml").write_text(
        '[scene]\nname = "room"\nmjcf = "room.xml"\ntimestep = 0.002\n'
        '[[robot]]\ntype = "reeman"\nid = "bot"\npose = [0.0, 0.0, 0.0, 0.0]\n'
        '[[object]]\nid = "goal"\nbody = "goal"\n[[object]]\nid = "target"\nbody = "target"\n'
    )
    return robots.scene(str(tmp_path / "room.toml"))

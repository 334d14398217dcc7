"""Users add robots and scenes as data: a folder on ROBOFABRIC_ROBOTS_PATH, no code."""

from __future__ import annotations

import shutil

import robots
from sim_peer.physics.world import SimWorld


def test_a_robot_and_a_scene_added_as_files_are_loaded_and_simulated(tmp_path, monkeypatch):
    bot = tmp_path / "scout"
    shutil.copytree(robots.load("reeman").directory, bot)
    manifest = (
        (bot / "robot.toml")
        .read_text()
        .replace('name = "reeman"', 'name = "scout"')
        .replace("rays = 240", "rays = 135")
    )
    (bot / "robot.toml").write_text(manifest.replace("fov_deg = 135.0", "fov_deg = 134.0"))
    scenes = tmp_path / "scenes"
    scenes.mkdir()
    shutil.copy(robots.scene("warehouse").mjcf_path, scenes / "hall.xml")
    (scenes / "hall.toml").write_text(
        '[scene]\nname = "hall"\nmjcf = "hall.xml"\n'
        '[[robot]]\ntype = "scout"\nid = "s1"\npose = [1.0, 0.0, 0.0, 0.0]\n'
        '[[object]]\nid = "goal"\n[[object]]\nid = "target"\n'
    )
    monkeypatch.setenv(robots.description.ENV_PATH, str(tmp_path))
    assert "scout" in robots.available_robots() and "hall" in robots.available_scenes()
    w = SimWorld("hall", ["reeman:r1@-1,0"])
    w.step()
    assert w.robot("s1").desc.name == "scout" and w.readings.scan("s1").shape == (135,)
    assert w.readings.scan("r1").shape == (240,)

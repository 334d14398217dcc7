"""LIDAR and ultrasonic ranges against walls at known distances, to the wire's quantisation step (1 mm)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fabric.interfaces import Scan
from sim_peer.physics.world import SimWorld
from tests.sim_peer.conftest import FRONT, LEFT, RIGHT

QUANTUM = 0.0005  # Scan carries millimetres: rounding error is at most half of one


def expected_ranges(px: float, py: float, heading: float, angles: np.ndarray, rmax: float) -> np.ndarray:
    """Distance from (px, py) along each ray to the nearest of the three wall planes."""
    out = []
    for a in heading + angles:
        c, s = math.cos(a), math.sin(a)
        ts = []
        if c > 1e-12:
            ts.append((FRONT - px) / c)
        if s > 1e-12:
            ts.append((LEFT - py) / s)
        if s < -1e-12:
            ts.append((RIGHT - py) / s)
        out.append(min(min(ts), rmax))
    return np.array(out)


@pytest.mark.parametrize("pose", [(0.0, 0.0, 0.0), (0.4, 0.3, math.radians(25)), (-1.0, -0.2, math.radians(-40))])
def test_lidar_ranges_match_the_walls_to_the_quantisation_step(room, pose):
    w = SimWorld(room)
    bot = w.robot("bot")
    bot.ctrl.teleport(*pose)
    w.step()
    spec = bot.desc.lidar
    ranges = w.readings.scan("bot")
    scan = Scan.from_ranges(
        ranges, angle_min=spec.angle_min, angle_increment=spec.angle_increment, range_max=spec.range_max
    )
    x, y, yaw = pose
    lx, ly = 0.22, 0.0  # lidar site in the robot frame (robots/reeman/reeman.xml)
    px, py = x + lx * math.cos(yaw) - ly * math.sin(yaw), y + lx * math.sin(yaw) + ly * math.cos(yaw)
    want = expected_ranges(px, py, yaw, scan.angles, spec.range_max)
    assert scan.ranges_mm.shape == (240,)
    np.testing.assert_allclose(scan.ranges, want, atol=QUANTUM + 1e-9)
    assert math.isclose(spec.fov, math.radians(135))


def test_markers_are_invisible_but_other_robots_are_seen(room):
    w = SimWorld(room, ["reeman:other@1.2,0"])
    w.step()
    ranges = w.readings.scan("bot")
    mid = len(ranges) // 2  # 0.28 deg off the axis with 240 rays: 1 mm is plenty
    # straight ahead: the other robot's chassis (x = 1.2 + 0.05 - 0.25) rather than the wall, not the goal marker at 1 m
    assert abs(ranges[mid] - (1.2 + 0.05 - 0.25 - 0.22)) < 1e-3
    w2 = SimWorld(room)
    w2.step()
    assert abs(w2.readings.scan("bot")[mid] - (FRONT - 0.22)) < 1e-3


def test_configurable_ray_count_and_field_of_view(room):
    w = SimWorld(room, lidar_rays=135, lidar_fov_deg=134)
    w.step()
    assert w.readings.scan("bot").shape == (135,)
    assert math.isclose(w.robot("bot").desc.lidar.angle_increment, math.radians(1))


def test_nothing_hit_reads_range_max(room):
    w = SimWorld(room)
    w.robot("bot").ctrl.teleport(-2.5, 0.0, math.pi)  # facing out of the open side of the room (walls end at x = -3)
    w.step()
    spec = w.robot("bot").desc.lidar
    assert np.all(w.readings.scan("bot") == spec.range_max)


def test_noise_is_gaussian_and_seeded(room):
    a = SimWorld(room, seed=7, noise_std=0.01)
    b = SimWorld(room, seed=7, noise_std=0.01)
    c = SimWorld(room, seed=8, noise_std=0.01)
    for w in (a, b, c):
        w.step()
    ra, rb, rc = a.readings.scan("bot"), b.readings.scan("bot"), c.readings.scan("bot")
    np.testing.assert_array_equal(ra, rb)
    assert not np.array_equal(ra, rc)
    clean = SimWorld(room)
    clean.step()
    err = ra - clean.readings.scan("bot")
    assert 0.007 < float(np.std(err)) < 0.013 and abs(float(np.mean(err))) < 0.003


def test_ultrasonic_ring_reads_the_walls(room):
    w = SimWorld(room)
    w.step()
    sonar = w.readings.sonar("bot")
    spec = w.robot("bot").desc.ultrasonic
    assert sonar.shape == (len(spec.angles),)
    front = spec.angles.index(0.0)
    back = spec.angles.index(math.pi)
    assert abs(sonar[front] - (FRONT - spec.center[0] - spec.radius)) < 1e-6
    assert sonar[back] == spec.range_max  # nothing behind within 3 m

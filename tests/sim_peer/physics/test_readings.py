"""Sensor reads on demand: what a robot lacks is named, an unknown robot too."""

from __future__ import annotations

import math

import pytest

from sim_peer.physics.world import SimWorld


def test_readings_name_what_a_robot_lacks():
    w = SimWorld("combined")
    assert w.readings.scan("base1").shape[0] > 0 and len(w.readings.flange("arm1")[0]) == 3
    with pytest.raises(KeyError, match="has no LIDAR"):
        w.readings.scan("arm1")
    with pytest.raises(KeyError, match="is not an arm"):
        w.readings.flange_velocity("base1")
    with pytest.raises(KeyError, match="unknown robot"):
        w.readings.sonar("nobody")
    assert not math.isnan(float(w.readings.flange_velocity("arm1")[0][0]))

"""The world's parts on their own: the bounded note log, checked scene-object poses, reset puts objects home."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fabric.interfaces import EventKind
from sim_peer.notes import NoteLog
from sim_peer.robot import Note
from sim_peer.world import SimWorld


def test_the_note_log_keeps_the_newest_notes_and_take_empties_it():
    log = NoteLog(limit=3)
    for i in range(5):
        log.add(f"r{i}", Note("path_done", f"n{i}"))
    log.add("bot", Note(EventKind.COLLISION, "bumper", data={"t": 1.5}))
    assert len(log) == 3 and log.collisions == [("bot", 1.5)]
    taken = log.take()
    assert [(rid, n.reason) for rid, n in taken] == [("r3", "n3"), ("r4", "n4"), ("bot", "bumper")]
    assert log.take() == [] and log.collisions == []


def test_a_bad_object_pose_moves_nothing_and_reset_puts_objects_home():
    w = SimWorld("combined")
    home = w.objects.pose("target")
    with pytest.raises(ValueError, match="quaternion"):
        w.objects.set_pose("target", [1.0, 2.0, 3.0], [0, 0, 0, 0])
    np.testing.assert_array_equal(w.objects.pose("target")[0], home[0])  # the position did not move either
    w.objects.set_pose("target", [1.0, 2.0, 3.0], [2, 0, 0, 0])
    pos, quat = w.objects.pose("target")
    assert pos.tolist() == [1.0, 2.0, 3.0] and quat.tolist() == [1.0, 0.0, 0.0, 0.0]  # normalised
    assert "target" in w.objects and sorted(w.objects) == sorted(o.id for o in w.scene.objects)
    w.reset()
    np.testing.assert_array_equal(w.objects.pose("target")[0], home[0])


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

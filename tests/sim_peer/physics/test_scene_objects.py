"""Scene objects: checked poses (a bad one moves nothing), normalised quaternions, reset puts them home."""

from __future__ import annotations

import numpy as np
import pytest

from sim_peer.physics.world import SimWorld


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

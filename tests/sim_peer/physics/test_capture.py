"""A world's state as a message and back (sim_peer.physics.capture): a restored world goes on exactly as the original."""

from __future__ import annotations

import numpy as np

from fabric.codec import decode, encode
from sim_peer.physics import capture
from fabric.interfaces import WorldState
from sim_peer.physics.world import SimWorld


def _moving_world() -> SimWorld:
    w = SimWorld("combined", seed=1)
    w.robots["arm1"].joints(np.radians([60.0, 30.0, -40.0, 30.0, 50.0, -30.0]), 0.3)
    w.robots["base1"].path(np.linspace(0, 1.0, 20), np.linspace(0, 0.8, 20), np.full(20, 0.67))
    w.objects.set_pose("target", [3.2, 0.1, 1.0])
    w.step(400)
    return w


def test_a_restored_world_continues_the_motions_in_progress_exactly():
    w = _moving_world()
    t, steps, robots, objects = capture.capture(w)
    state = decode(encode(WorldState(t, steps, robots, objects)))
    assert state.robot("base1").path.shape[0] == 20 and state.robot("arm1").extra["scale"] == 0.3
    w2 = SimWorld("combined", seed=1)
    capture.restore(w2, state)
    assert w2.time == w.time and w2.steps == w.steps
    assert np.allclose(w2.objects.pose("target")[0], [3.2, 0.1, 1.0])
    for _ in range(10):
        w.step(300), w2.step(300)
        assert np.array_equal(w.robots["arm1"].ctrl.q, w2.robots["arm1"].ctrl.q)
        a, b = w.robots["base1"].ctrl, w2.robots["base1"].ctrl
        assert (a.x, a.y, a.yaw, a.v, a.omega) == (b.x, b.y, b.yaw, b.v, b.omega)
    assert w2.robots["base1"].ctrl.paths_done == w.robots["base1"].ctrl.paths_done == 1  # both followed it to the end
    assert np.allclose(w2.readings.flange("arm1")[0], w.readings.flange("arm1")[0])


def test_a_base_reversing_when_taken_over_goes_on_backwards():
    """A Hybrid A* plan may back a base up (a description with ``reverse``): which stretches run backwards is part
    of the follower's state, not only of the headings sent with the path. A restored follower that lost it drove
    its backwards stretch forwards, turning about first."""
    x = np.concatenate([np.linspace(0.0, -1.0, 21), np.linspace(-0.95, 0.5, 30)])  # back 1 m, then forwards
    w = SimWorld("combined", seed=1)
    w.robots["base1"].path(x, np.zeros_like(x), np.zeros_like(x))
    w.step(300)
    assert w.robots["base1"].ctrl.v < -0.05  # reversing now
    t, steps, robots, objects = capture.capture(w)
    state = decode(encode(WorldState(t, steps, robots, objects)))
    w2 = SimWorld("combined", seed=1)
    capture.restore(w2, state)
    assert w2.robots["base1"].ctrl.follower.backwards == [True, False]
    for _ in range(10):
        w.step(300), w2.step(300)
        a, b = w.robots["base1"].ctrl, w2.robots["base1"].ctrl
        assert (a.x, a.y, a.yaw, a.v, a.omega) == (b.x, b.y, b.yaw, b.v, b.omega)


def test_stream_samples_and_advance_bring_robots_to_one_time():
    w = _moving_world()
    t, steps, robots, objects = capture.capture(w)
    state = WorldState(t, steps, robots, objects)
    w.step(25)  # 50 ms later the primary publishes joints...
    from fabric.interfaces import Header, JointState

    names, q, dq = w.robots["arm1"].joint_state()
    js = JointState(names, q, dq, Header(stamp=w.time))
    w.step(15)  # ...and dies 30 ms after that
    w2 = SimWorld("combined", seed=1)
    capture.restore(w2, state)
    capture.overlay_joints(w2, "arm1", js)
    capture.advance(w2, {"arm1": w.time - js.header.stamp, "base1": w.time - state.time})
    assert np.allclose(w2.robots["arm1"].ctrl.q, w.robots["arm1"].ctrl.q, atol=1e-9)
    assert abs(w2.robots["base1"].ctrl.x - w.robots["base1"].ctrl.x) < 1e-9

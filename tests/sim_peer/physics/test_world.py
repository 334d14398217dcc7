"""Robots in a world: joint control with speed limits and clamps, stop, reset, twists, turns, paths."""

from __future__ import annotations

import math

import numpy as np
import pytest

import robots as robots_pkg
from fabric.interfaces import EventKind, Path
from sim_peer.controllers import CommandRejected
from sim_peer.physics.world import SimWorld, WorldError


@pytest.fixture(scope="module")
def combined() -> SimWorld:
    return SimWorld("combined")


def run(w: SimWorld, seconds: float) -> None:
    w.step(int(round(seconds / w.dt)))


def test_zero_pose_flange_is_190_0_308_mm_from_the_arm_base():
    w = SimWorld("arm_cell")
    x, y, z, _ = w.placements["arm1"].pose
    pos, quat = w.readings.flange("arm1")
    np.testing.assert_allclose((pos - [x, y, z]) * 1000, [190.0, 0.0, 308.0], atol=1e-9)
    np.testing.assert_allclose(quat, [math.cos(math.pi / 4), 0, math.sin(math.pi / 4), 0], atol=1e-12)


def test_joint_speed_limits_are_obeyed_over_a_move_and_the_target_is_reached():
    w = SimWorld("arm_cell")
    arm = w.robot("arm1")
    target = np.array([1.0, 0.5, -1.0, 2.0, -1.5, 3.0])
    assert arm.joints(target) is None
    vmax = np.array(arm.desc.max_speed)
    prev = arm.ctrl.q.copy()
    peak = np.zeros(6)
    for _ in range(int(3.0 / w.dt)):
        w.step()
        q = arm.ctrl.q.copy()
        speed = np.abs(q - prev) / w.dt
        assert np.all(speed <= vmax * (1 + 1e-9)), speed / vmax
        peak = np.maximum(peak, speed)
        prev = q
    np.testing.assert_allclose(arm.ctrl.q, target, atol=1e-12)
    assert not arm.moving
    # the slowest joint (J6: 3 rad at 500 deg/s vs J4: 2 rad at 300 deg/s ...) ran at its limit
    assert np.isclose(peak / vmax, 1.0, atol=1e-6).any()
    # joints move together: all finish at the same step, along a straight line in joint space
    qpos = w.data.qpos[arm.qadr]
    np.testing.assert_allclose(qpos, target, atol=1e-12)


def test_speed_scale_slows_the_move():
    w = SimWorld("arm_cell")
    arm = w.robot("arm1")
    arm.joints([0.0, 0.0, 0.0, 0.0, 0.0, 1.0], speed_scale=0.5)
    w.step()
    assert math.isclose(arm.ctrl.dq[5], 0.5 * arm.desc.max_speed[5], rel_tol=1e-9)


def test_out_of_range_targets_are_clamped_and_reported():
    w = SimWorld("arm_cell")
    arm = w.robot("arm1")
    clamp = arm.joints([0.0, math.radians(120), math.radians(-200), 0.0, 0.0, 0.0])
    assert clamp is not None and clamp.what == ("joint_2", "joint_3")
    np.testing.assert_allclose(clamp.applied, [math.radians(90), math.radians(-135)])
    run(w, 3.0)
    np.testing.assert_allclose(arm.ctrl.q[1:3], [math.radians(90), math.radians(-135)])


@pytest.mark.parametrize(
    "q, reason",
    [
        ([0.0] * 5, "wrong_joint_count"),
        ([0.0] * 7, "wrong_joint_count"),
        ([0, 0, math.nan, 0, 0, 0], "not_finite"),
        ([math.inf] * 6, "not_finite"),
    ],
)
def test_bad_joint_targets_are_rejected_and_the_last_valid_one_kept(q, reason):
    w = SimWorld("arm_cell")
    arm = w.robot("arm1")
    arm.joints([0.3] * 6)
    with pytest.raises(CommandRejected) as exc:
        arm.joints(q)
    assert exc.value.reason == reason
    run(w, 1.0)
    np.testing.assert_allclose(arm.ctrl.q, [0.3] * 6)


def test_stop_holds_all_motion_and_reset_returns_to_zero():
    w = SimWorld("combined")
    arm, base = w.robot("arm1"), w.robot("base1")
    arm.joints([1.0, 0.8, -1.0, 1.0, 1.0, 1.0])
    base.twist(0.5, 0.3)
    run(w, 0.3)
    assert arm.moving and base.moving
    arm.stop()
    base.stop()
    held_q, held_pose = arm.ctrl.q.copy(), (base.ctrl.x, base.ctrl.y, base.ctrl.yaw)
    w.step()
    assert not arm.moving and not base.moving
    run(w, 1.0)
    np.testing.assert_array_equal(arm.ctrl.q, held_q)
    assert (base.ctrl.x, base.ctrl.y, base.ctrl.yaw) == held_pose
    arm.reset()
    base.reset()
    run(w, 3.0)
    np.testing.assert_allclose(arm.ctrl.q, np.zeros(6), atol=1e-12)
    assert (base.ctrl.x, base.ctrl.y, base.ctrl.yaw) == base.ctrl.home


def test_an_arm_that_took_a_target_is_underway_before_its_first_step_and_not_once_stopped():
    """A hold that comes between a command and the next step must know the arm had work to do: it has no speed yet
    (``moving`` is false), so ``underway`` says so; a stop leaves it with nothing to do."""
    w = SimWorld("arm_cell")
    arm = w.robot("arm1")
    run(w, 0.1)
    assert not arm.underway
    arm.joints([0.5, 0.2, -0.3, 0.4, 0.3, 0.5])
    assert arm.underway and not arm.moving
    w.step()
    assert arm.underway and arm.moving
    arm.stop()
    assert not arm.underway


def test_a_twist_of_v_for_t_moves_v_t():
    w = SimWorld("warehouse")
    base = w.robot("base1")
    v, t = 0.6, 3.0
    a = base.desc.base.max_accel
    base.twist(v, 0.0)
    run(w, t)
    ramp_loss = v * v / (2 * a)  # the acceleration limit costs this much distance versus an instant start
    assert abs(base.ctrl.x - (v * t - ramp_loss)) < 0.005
    assert abs(base.ctrl.y) < 1e-12
    w.sync()
    np.testing.assert_allclose(w.data.xpos[base.body_id][:2], [base.ctrl.x, 0.0], atol=1e-12)


def test_an_in_place_turn_keeps_the_axle_midpoint_fixed():
    w = SimWorld("warehouse")
    base = w.robot("base1")
    m = w.model
    left, right, chassis = (m.geom(f"base1/{n}").id for n in ("wheel_left", "wheel_right", "chassis"))
    w.sync()
    axle0 = (w.data.geom_xpos[left] + w.data.geom_xpos[right]) / 2
    chassis0 = w.data.geom_xpos[chassis].copy()
    base.twist(0.0, 1.0)
    yaws = []
    for _ in range(10):
        run(w, 0.3)
        w.sync()
        axle = (w.data.geom_xpos[left] + w.data.geom_xpos[right]) / 2
        np.testing.assert_allclose(axle, axle0, atol=1e-9)
        yaws.append(base.ctrl.yaw)
    assert yaws[-1] > 2.0  # it really turned
    assert np.linalg.norm(w.data.geom_xpos[chassis] - chassis0) > 0.05  # the chassis centre is not the turn point


def test_twists_beyond_limits_are_clamped_and_absurd_ones_refused():
    w = SimWorld("warehouse")
    base = w.robot("base1")
    clamp = base.twist(2.0, 0.0)
    assert clamp is not None and clamp.what == ("v",) and clamp.applied == (base.desc.base.max_speed,)
    with pytest.raises(CommandRejected) as exc:
        base.twist(100.0, 0.0)
    assert exc.value.reason == "absurd_twist"
    assert base.ctrl.v_cmd == base.desc.base.max_speed  # the last valid command stands
    with pytest.raises(CommandRejected):
        w.robot("base1").joints([0.0, 0.0])
    with pytest.raises(CommandRejected) as exc:
        w.robot("base1").twist(math.nan, 0.0)
    assert exc.value.reason == "not_finite"


def test_the_path_follower_drives_to_the_end_of_the_path():
    w = SimWorld("warehouse")
    base = w.robot("base1")
    xs = np.concatenate([np.linspace(0, 1.5, 16), np.full(15, 1.5)])
    ys = np.concatenate([np.zeros(16), np.linspace(0.1, 1.5, 15)])
    theta = np.full(xs.shape, math.pi / 2)
    base.path(xs, ys, theta)
    for _ in range(300):
        run(w, 0.1)
        if not base.following and not base.moving:
            break
    assert not base.following
    assert math.hypot(base.ctrl.x - 1.5, base.ctrl.y - 1.5) < 0.08
    assert abs(base.ctrl.yaw - math.pi / 2) < 0.05
    assert [(r, n.kind) for r, n in w.notes.take()] == [("base1", "path_done")]


def test_a_base_takes_paths_in_the_world_frame_only():
    w = SimWorld("warehouse")
    base = w.robot("base1")
    follow = base.commands()["path"]
    with pytest.raises(CommandRejected, match="world frame") as refused:
        follow(Path(np.array([0.0, 1.0]), np.array([0.0, 0.0]), np.array([0.0, 0.0]), frame="base1"))
    assert refused.value.reason == "bad_frame" and not base.following
    follow(Path(np.array([0.0, 1.0]), np.array([0.0, 0.0]), np.array([0.0, 0.0])))
    assert base.following


def test_a_path_behind_the_robot_makes_it_turn_to_face_it_first():
    w = SimWorld("warehouse")
    base = w.robot("base1")
    base.path(np.linspace(0, -1.0, 11), np.zeros(11), None)
    xs = []
    for _ in range(200):
        run(w, 0.05)
        xs.append(base.ctrl.x)
        if not base.following and not base.moving:
            break
    assert abs(base.ctrl.x + 1.0) < 0.08
    assert max(xs) < 0.02  # never backed up: turned on the spot (about the axle) then drove


def test_robots_have_ids_and_bad_worlds_are_clear_errors():
    w = SimWorld("combined", ["reeman:base2", "reeman:base3@-3,0,90"])
    assert set(w.robots) == {"arm1", "base1", "base2", "base3"}
    assert w.placements["base3"].pose[:2] == (-3.0, 0.0)
    assert math.isclose(w.robot("base3").ctrl.yaw, math.pi / 2)
    with pytest.raises(WorldError, match="unique"):
        SimWorld("combined", ["reeman:base1"])
    with pytest.raises(WorldError, match="unknown robot type"):
        SimWorld("combined", ["tank:t1"])
    with pytest.raises(WorldError, match="TYPE:ID"):
        SimWorld("combined", ["reeman"])
    with pytest.raises(WorldError, match="unknown scene"):
        SimWorld("nowhere")
    with pytest.raises(WorldError, match="also scene objects"):
        SimWorld("combined", ["reeman:target"])
    with pytest.raises(WorldError, match="forbidden"):
        SimWorld("combined", [robots_pkg.SceneRobot("reeman", "a/b", (1.0, 1.0, 0.0, 0.0))])


def test_moving_flag_follows_motion_and_objects_move():
    w = SimWorld("combined")
    assert w.moving() == {"arm1": False, "base1": False}
    w.robot("arm1").joints([0.2] * 6)
    w.step()
    assert w.moving() == {"arm1": True, "base1": False}
    run(w, 1.0)
    assert w.moving()["arm1"] is False
    w.objects.set_pose("target", [3.2, 0.1, 1.0])
    w.sync()
    np.testing.assert_allclose(w.data.xpos[w.model.body("target").id], [3.2, 0.1, 1.0])
    with pytest.raises(KeyError):
        w.objects.set_pose("nope", [0, 0, 0])
    with pytest.raises(ValueError):
        w.objects.set_pose("target", [math.nan, 0, 0])
    st = w.state("arm1")
    assert st["kind"] == "arm" and len(st["q"]) == 6 and st["moving"] is False
    w.reset()
    assert w.time == 0.0 and w.robot("arm1").ctrl.q.tolist() == [0.0] * 6


def test_the_bumper_stops_a_base_before_a_wall(room):
    from tests.sim_peer.conftest import FRONT

    w = SimWorld(room)
    base = w.robot("bot")
    base.twist(1.0, 0.0)
    run(w, 4.0)
    assert not base.moving and w.notes.collisions and w.notes.collisions[0][0] == "bot"
    said = [n for _, n in w.notes if n.kind == EventKind.COLLISION][0]
    assert said.data["what"] == "front" and said.data["detail"].startswith("stopped before front ahead at (")
    front = base.ctrl.x + 0.05 + 0.25  # chassis centre 5 cm ahead of the axle, radius 0.25 m
    assert FRONT - 0.05 < front <= FRONT
    base.twist(-0.3, 0.0)  # backing away is allowed
    run(w, 1.0)
    assert base.ctrl.x < FRONT - 0.3 - 0.2 and len(w.notes.collisions) == 1
    quiet = SimWorld(room, bumper=False)
    quiet.robot("bot").twist(1.0, 0.0)
    run(quiet, 4.0)
    assert quiet.robot("bot").ctrl.x > FRONT and not quiet.notes.collisions  # without it, walls are no obstacle


def test_free_bodies_are_simulated_while_robots_stay_kinematic(tmp_path):
    import robots

    (tmp_path / "drop.xml").write_text(
        '<mujoco><worldbody><geom type="plane" size="3 3 0.1"/>'
        '<body name="box" pos="0.6 0.6 1.0"><freejoint/><geom type="box" size="0.05 0.05 0.05"/></body>'
        '<body name="target" mocap="true" pos="0 0 -1"><geom type="sphere" size="0.01" group="3" contype="0" conaffinity="0"/></body>'
        "</worldbody></mujoco>"
    )
    (tmp_path / "drop.toml").write_text(
        '[scene]\nmjcf = "drop.xml"\n[[robot]]\ntype = "meca500"\nid = "arm"\npose = [0.0, 0.0, 0.0, 0.0]\n'
        '[[object]]\nid = "target"\n'
    )
    w = SimWorld(robots.scene(str(tmp_path / "drop.toml")))
    assert w.dynamic
    w.robot("arm").joints([0.0, 0.5, 0.0, 0.0, 0.0, 0.0])
    run(w, 1.0)
    w.sync()
    assert w.data.xpos[w.model.body("box").id][2] < 0.06  # fell onto the floor under gravity
    np.testing.assert_allclose(
        w.data.qpos[w.robot("arm").qadr], [0.0, 0.5, 0.0, 0.0, 0.0, 0.0], atol=1e-12
    )  # held, no sag
    assert not SimWorld("combined").dynamic  # only kinematic robots and markers: no dynamics to integrate


def test_with_a_twist_timeout_a_quiet_sender_lets_the_base_stop():
    w = SimWorld("warehouse", twist_timeout=0.5)
    base = w.robot("base1")
    base.twist(0.5, 0.0)
    run(w, 0.4)
    base.twist(0.5, 0.0)  # refreshed in time: keeps going
    run(w, 0.4)
    assert base.ctrl.v == pytest.approx(0.5)
    run(w, 1.5)
    assert not base.moving and base.ctrl.twists_expired == 1
    assert [(r, n.kind) for r, n in w.notes.take()] == [("base1", "twist_timeout")]  # said once, as an event
    with pytest.raises(WorldError, match="twist timeout"):
        SimWorld("warehouse", twist_timeout=0)


@pytest.mark.slow
def test_the_sim_core_does_not_import_zenoh():
    import subprocess
    import sys

    code = (
        "import sys, sim_peer, sim_peer.physics.world, sim_peer.physics.pacing, robots; print('zenoh' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.stdout.strip() == "False", out.stderr

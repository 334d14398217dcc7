"""The sim peer end to end over a real router: commands in, joints/poses/scans/events out, the world service."""

from __future__ import annotations

import math
import threading

import numpy as np
import pytest

from fabric import keys
from fabric.interfaces import Command, Event, Header, JointState, JointTarget, Pose, Reset, Scan, Stop, Twist, WorldInfo
from robofabric.testing import robofabric_cmd, wait_until
from sim_peer.serving.peer import SimPeer
from sim_peer.physics.world import SimWorld


class Inbox:
    """Latest message per key and every event, from a subscription."""

    def __init__(self) -> None:
        self.latest: dict[str, object] = {}
        self.events: list[Event] = []
        self.lock = threading.Lock()

    def __call__(self, key: str, msg: object) -> None:
        with self.lock:
            self.latest[key] = msg
            if isinstance(msg, Event):
                self.events.append(msg)

    def event(self, kind: str, reason: str | None = None) -> Event | None:
        with self.lock:
            for ev in self.events:
                if ev.kind == kind and (reason is None or ev.reason == reason):
                    return ev
        return None


class RecordingGate:
    """Refuses one user; records motion updates."""

    def __init__(self) -> None:
        self.motion: list[tuple[str, bool]] = []

    def admit(self, robot: str, command: Command) -> str | None:
        return "not_owner" if command.user == "mallory" else None

    def update_motion(self, robot: str, moving: bool) -> None:
        self.motion.append((robot, moving))

    def close(self) -> None:
        pass


@pytest.fixture
def sim(world, connect):
    gate = RecordingGate()
    fab = connect("sim", "sim-test")
    peer = SimPeer(fab, SimWorld("combined", seed=3), gate=gate, rates={"joints": 50, "pose": 50, "scan": 20})
    peer.start()
    try:
        yield peer, gate
    finally:
        peer.close()


@pytest.fixture
def user(world, connect):
    fab = connect("user", "alice")
    inbox = Inbox()
    fab.subscribe(keys.robot_all(world), inbox)
    fab.subscribe(keys.event_all(world), inbox, expected=Event)
    return fab, inbox


def send(fab, world, robot, name, body, user="alice"):
    fab.publish(keys.robot_cmd(world, robot, name, user), Command(user=user, epoch=1, body=body))


def test_a_joint_command_goes_in_and_the_joints_come_out(world, sim, user):
    peer, gate = sim
    fab, inbox = user
    target = np.array([0.4, 0.2, -0.3, 0.5, 0.3, -0.6])
    jk = keys.robot_joints(world, "arm1")
    wait_until(lambda: jk in inbox.latest, what="first joint state")
    send(fab, world, "arm1", "joints", JointTarget(target))

    def arrived():
        js = inbox.latest.get(jk)
        return isinstance(js, JointState) and np.allclose(js.q, target, atol=1e-9) and not js.dq.any()

    wait_until(arrived, timeout=10, what="arm at target", seen=lambda: inbox.latest.get(jk))
    js = inbox.latest[jk]
    assert js.names == tuple(f"joint_{i}" for i in range(1, 7)) and js.header.source == "sim-test"
    # the flange pose goes out with the joints, and agrees with the world's kinematics
    pose = inbox.latest[keys.robot_pose(world, "arm1")]
    assert isinstance(pose, Pose)
    pos, _ = peer.world.readings.flange("arm1")
    wait_until(
        lambda: np.allclose(inbox.latest[keys.robot_pose(world, "arm1")].position, pos, atol=1e-9), what="flange pose"
    )
    # the gate heard the arm start and stop moving
    wait_until(lambda: ("arm1", False) in gate.motion[1:], what="motion updates", seen=lambda: gate.motion)
    assert ("arm1", True) in gate.motion
    assert peer.last_state("arm1")["q"] == pytest.approx(list(target))


def test_twist_moves_the_base_and_pose_and_scan_are_published(world, sim, user):
    peer, _ = sim
    fab, inbox = user
    send(fab, world, "base1", "twist", Twist(0.5, 0.0))
    pk = keys.robot_pose(world, "base1")
    wait_until(
        lambda: isinstance(inbox.latest.get(pk), Pose) and inbox.latest[pk].position[0] > 0.2,
        timeout=10,
        what="base moving",
    )
    assert inbox.latest[pk].linear[0] > 0.1
    send(fab, world, "base1", "stop", Stop())
    wait_until(lambda: not peer.world.robot("base1").moving, what="base stopped")
    scan = wait_until(lambda: inbox.latest.get(keys.robot_scan(world, "base1")), what="scan")
    assert isinstance(scan, Scan) and scan.ranges_mm.shape == (240,)
    sonar = wait_until(lambda: inbox.latest.get(keys.robot_stream(world, "base1", "sonar")), what="ultrasonic ring")
    assert isinstance(sonar, Scan) and sonar.ranges_mm.shape == (8,) and sonar.range_max == 3.0
    send(fab, world, "base1", "reset", Reset())
    wait_until(lambda: peer.world.robot("base1").ctrl.x == 0.0, what="base reset")


@pytest.mark.parametrize(
    "robot, name, body, reason",
    [
        ("nobody", "joints", JointTarget(np.zeros(6)), "unknown_robot"),
        ("arm1", "joints", JointTarget(np.zeros(5)), "wrong_joint_count"),
        ("arm1", "joints", Twist(0.1, 0.0), "wrong_body"),
        ("base1", "twist", Twist(50.0, 0.0), "absurd_twist"),
        ("arm1", "twist", Twist(0.1, 0.0), "unsupported"),
    ],
)
def test_bad_commands_are_rejected_with_a_reason_and_the_last_valid_command_stands(
    world, sim, user, robot, name, body, reason
):
    peer, _ = sim
    fab, inbox = user
    good = np.array([0.3, 0.0, 0.0, 0.0, 0.0, 0.0])
    send(fab, world, "arm1", "joints", JointTarget(good))
    wait_until(lambda: peer.counters["accepted"] >= 1, what="good command accepted")
    send(fab, world, robot, name, body)
    ev = wait_until(lambda: inbox.event("reject", reason), what=f"reject event {reason}", seen=lambda: inbox.events)
    # a command for a robot this sim does not have is refused from its key, undecoded: no user known
    assert (
        ev.object == robot and ev.user == ("" if reason == "unknown_robot" else "alice") and ev.data["command"] == name
    )
    assert peer.counters["rejected"] == 1 and peer.counters[f"rejected:{reason}"] == 1
    wait_until(lambda: np.allclose(peer.last_state("arm1")["q"], good), what="arm still reaching the good target")


def test_garbage_is_counted_and_the_peer_goes_on(world, sim, user):
    peer, _ = sim
    fab, inbox = user
    fab.put_raw(keys.robot_cmd(world, "arm1", "joints", "alice"), b"\x93\xff garbage")
    nan = np.array([0.0, 0.0, math.nan, 0.0, 0.0, 0.0])
    fab.put_raw(keys.robot_cmd(world, "arm1", "joints", "alice"), b"")
    fab.publish(
        keys.robot_cmd(world, "arm1", "joints", "alice"), Command("alice", 1, JointTarget(nan))
    )  # refused by the decoder
    wait_until(lambda: peer.fabric.counters["decode_errors"] >= 3, what="decode errors counted")
    assert peer.counters["commands"] == 0 and peer.last_state("arm1")["target"] == [0.0] * 6
    send(fab, world, "arm1", "joints", JointTarget(np.full(6, 0.1)))
    wait_until(lambda: np.allclose(peer.last_state("arm1")["q"], 0.1), what="arm obeys the next good command")


def test_clamped_targets_are_applied_and_reported(world, sim, user):
    peer, _ = sim
    fab, inbox = user
    send(fab, world, "arm1", "joints", JointTarget(np.array([0.0, 3.0, 0.0, 0.0, 0.0, 0.0])))
    ev = wait_until(lambda: inbox.event("clamp"), what="clamp event")
    assert ev.object == "arm1" and ev.data["what"] == ["joint_2"] and ev.data["applied"] == [pytest.approx(math.pi / 2)]
    wait_until(lambda: math.isclose(peer.last_state("arm1")["q"][1], math.pi / 2), what="arm at the clamped target")


def test_the_gate_refuses_and_the_refusal_is_an_event(world, sim, user):
    peer, _ = sim
    fab, inbox = user
    send(fab, world, "arm1", "joints", JointTarget(np.full(6, 0.2)), user="mallory")
    ev = wait_until(lambda: inbox.event("reject", "not_owner"), what="gate refusal event")
    assert ev.user == "mallory" and ev.object == "arm1"
    assert peer.last_state("arm1")["target"] == [0.0] * 6


def test_a_payload_naming_someone_else_than_the_key_is_refused(world, sim, user):
    """The sender is the key's user (the router's access control vouches for it), not the payload's."""
    peer, _ = sim
    fab, inbox = user
    fab.publish(keys.robot_cmd(world, "arm1", "joints", "mallory"), Command("alice", 1, JointTarget(np.full(6, 0.2))))
    ev = wait_until(
        lambda: inbox.event("reject", "user_mismatch"), what="user_mismatch event", seen=lambda: inbox.events
    )
    assert ev.user == "mallory" and ev.object == "arm1" and "'alice'" in ev.data["detail"]
    assert peer.counters["accepted"] == 0 and peer.last_state("arm1")["target"] == [0.0] * 6


def test_a_pose_in_a_made_up_frame_is_refused_quoting_little_of_it(world, sim, user):
    peer, _ = sim
    fab, inbox = user
    fab.publish(keys.object_pose(world, "target", "alice"), Pose(np.array([3.2, 0.1, 1.0]), frame="f" * 4000))
    ev = wait_until(lambda: inbox.event("reject", "bad_frame"), what="bad_frame event", seen=lambda: inbox.events)
    assert ev.object == "target" and len(ev.data["detail"]) < 300 and "(4000 characters)" in ev.data["detail"], ev.data


def test_scene_objects_move_and_the_world_service_describes_everything(world, sim, user):
    peer, _ = sim
    fab, inbox = user
    fab.publish(keys.object_pose(world, "target", "alice"), Pose(np.array([3.2, 0.1, 1.0])))
    wait_until(lambda: np.allclose(peer.world.objects.pose("target")[0], [3.2, 0.1, 1.0]), what="target moved")
    info = fab.rpc.call(keys.srv(world, "world"), timeout=5)
    assert isinstance(info, WorldInfo) and info.scene == "combined" and info.world == world
    arm, base = info.robot("arm1"), info.robot("base1")
    assert arm.kind == "arm" and arm.type == "meca500" and len(arm.joint_names) == 6
    np.testing.assert_allclose(np.degrees(arm.max_speed), [150, 150, 180, 300, 300, 500])
    np.testing.assert_allclose(arm.pose, [3.0, 0.0, 0.75, 0.0])
    assert base.kind == "mobile" and base.lidar.rays == 240 and base.base.max_speed > 0 and base.sonar is not None
    assert math.isclose(base.lidar.fov, math.radians(135)) and base.lidar.offset[0] > 0.1  # ahead of the axle
    assert arm.lidar is None and arm.sonar is None and arm.base is None
    objs = {o.id: o for o in info.objects}
    assert set(objs) == {"target", "goal"} and objs["target"].policy == "scene"
    np.testing.assert_allclose(objs["target"].position, [3.2, 0.1, 1.0])


def _world_info(fab, world):
    from fabric.interfaces import ServiceError

    try:
        return fab.rpc.call(keys.srv(world, "world"), timeout=1.0)
    except ServiceError:
        return None


@pytest.mark.slow
def test_the_cli_runs_a_sim_peer_that_answers_the_world_service(world, router, connect, procs):
    port = router[1]
    proc = procs.start(
        robofabric_cmd(
            "sim",
            "--scene",
            "arm_cell",
            "--no-ownership",
            "--world",
            world,
            "--connect",
            f"tcp/127.0.0.1:{port}",
            "--id",
            "sim1",
        ),
        name="sim",
    )
    fab = connect()
    wait_until(
        lambda: ("sim", "sim1") in fab.live_peers("sim"),
        timeout=30,
        what="sim peer alive",
        seen=lambda: procs.output(proc),
    )
    # alive (token) comes a moment before serving: wait for the answer, and show the peer's output if none comes
    info = wait_until(
        lambda: _world_info(fab, world), timeout=30, what="srv/world answered", seen=lambda: procs.output(proc)
    )
    assert [r.id for r in info.robots] == ["arm1"]
    inbox = Inbox()
    fab.subscribe(keys.robot_joints(world, "arm1"), inbox)
    # the sim's command subscriber known to this session first: a command sent before would be lost (no one to hear it)
    assert fab.wait_matching(keys.robot_cmd(world, "arm1", "joints", "alice"), 30.0), procs.output(proc)[-1500:]
    send(fab, world, "arm1", "joints", JointTarget(np.full(6, 0.05)))
    wait_until(
        lambda: any(np.allclose(m.q, 0.05) for m in inbox.latest.values()),
        timeout=30,
        what="joints from the CLI peer",
        seen=lambda: ([m.q.round(3).tolist() for m in inbox.latest.values()], procs.output(proc)[-1500:]),
    )


@pytest.mark.slow
def test_cli_mistakes_are_one_line_errors(procs):
    import subprocess

    out = subprocess.run(
        robofabric_cmd("sim", "--robot", "reeman", "--no-ownership"), capture_output=True, text=True, timeout=60
    )
    assert out.returncode == 2 and "TYPE:ID" in out.stderr and "Traceback" not in out.stderr
    out = subprocess.run(
        robofabric_cmd("sim", "--speed", "fast", "--no-ownership"), capture_output=True, text=True, timeout=60
    )
    assert out.returncode == 2 and "speed" in out.stderr


@pytest.mark.slow
def test_cli_runs_for_a_duration_at_max_speed_and_exits_cleanly(world, tmp_path):
    import subprocess

    from robofabric.testing import free_port

    argv = robofabric_cmd(
        "sim",
        "--scene",
        "warehouse",
        "--speed",
        "max",
        "--duration",
        "3",
        "--no-ownership",
        "--profile",
        "embedded",
        "--listen",
        f"tcp/127.0.0.1:{free_port()}",
        "--world",
        world,
        "--robot",
        "reeman:extra",
    )
    out = subprocess.run(argv, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert (
        "robots base1 (reeman), extra (reeman)" in out.stdout and "sim stopped at t=3.000 s: 1500 steps" in out.stdout
    )


def test_paths_and_bumps_are_announced_as_events(world, connect, user):
    from fabric.interfaces import Path

    fab, inbox = user
    peer = SimPeer(connect("sim", "fast-sim"), SimWorld("combined"), speed=10.0)
    with peer:
        xs = np.linspace(0.0, 0.6, 7)
        fab.publish(
            keys.robot_cmd(world, "base1", "path", "alice"), Command("alice", 1, Path(xs, np.zeros(7), np.zeros(7)))
        )
        ev = wait_until(lambda: inbox.event("path_done"), timeout=20, what="path_done event", seen=lambda: inbox.events)
        assert ev.object == "base1" and abs(peer.last_state("base1")["pose"][0] - 0.6) < 0.08
        send(fab, world, "base1", "twist", Twist(1.0, 0.0))  # straight at the table in front of the arm
        ev = wait_until(lambda: inbox.event("collision"), timeout=20, what="collision event", seen=lambda: inbox.events)
        assert ev.object == "base1" and ev.reason == "bumper" and peer.counters["collisions"] == 1
        assert not peer.world.robot("base1").moving and peer.last_state("base1")["pose"][0] < 2.85 - 0.25


def test_a_shard_leaves_other_robots_to_their_sims_and_the_scene_objects_to_the_first(world, connect, user):
    """A sim that is not alone in its world refuses nothing about a robot it does not serve (another shard's, docs/sim.md),
    and one that is not the scene objects' authority (objects=False) describes none and mirrors users' poses without a
    word (it may adopt the objects later: docs/sim.md)."""
    fab, inbox = user
    other = connect("sim", "sim-other")  # another sim of the world: its token is there
    peer = SimPeer(
        connect("sim", "sim-shard"),
        SimWorld("combined", seed=3),
        rates={"joints": 50, "pose": 50, "scan": 20},
        objects=False,
    )
    peer.start()
    try:
        info = peer.world_info()
        assert info.objects == () and {r.sim for r in info.robots} == {"sim-shard"}
        wait_until(lambda: "sim-other" in peer.other_sims, what="the other sim's token")
        send(fab, world, "base9", "twist", Twist(0.1, 0.0))
        wait_until(
            lambda: peer.counters["not_mine"] >= 1 or send(fab, world, "base9", "twist", Twist(0.1, 0.0)),
            timeout=10,
            what="a command for another sim's robot counted",
        )
        ok = keys.object_pose(world, "target", "alice")

        def own_command_and_poses():
            fab.publish(
                ok, Pose(np.array([9.0, 9.0, 9.0]), frame="map", header=fab.header(ok))
            )  # a bad one: not a word
            fab.publish(ok, Pose(np.array([0.3, 0.2, 0.4]), header=fab.header(ok)))  # sent beside it, every try
            return send(fab, world, "arm1", "joints", JointTarget(np.full(6, 0.1)))

        wait_until(
            lambda: (
                (peer.counters["accepted"] >= 1 and peer.counters["object_mirrored"] >= 1) or own_command_and_poses()
            ),
            timeout=10,
            what="its own robot's command and a mirrored object pose",
        )
        assert peer.counters["rejected"] == 0 and inbox.event("reject") is None
        assert peer.counters["object_updates"] == 0 and np.allclose(
            peer.world.objects.pose("target")[0], [0.3, 0.2, 0.4]
        )
        other.close()
        wait_until(lambda: not peer.other_sims, what="the other sim gone")
        send(fab, world, "base9", "twist", Twist(0.1, 0.0))
        wait_until(
            lambda: peer.counters["rejected:unknown_robot"] >= 1 or send(fab, world, "base9", "twist", Twist(0.1, 0.0)),
            timeout=10,
            what="alone again: an unknown robot is refused",
        )
    finally:
        peer.close()


class HoldingGate(RecordingGate):
    """Admits everything; the second look at one command (the worker's, as it applies it) asks the sim to hold first:
    the hold lands between the worker taking the command and applying it."""

    def __init__(self) -> None:
        super().__init__()
        self.peer: SimPeer | None = None
        self.looks = 0

    def admit(self, robot: str, command: Command) -> str | None:
        if command.header.seq == 41:
            self.looks += 1
            if self.looks == 2 and self.peer is not None:
                self.peer.commands.hold("a pause, in the test")
        return None


def test_a_command_applied_as_a_hold_came_is_done_again_when_sent_again(world, connect, user):
    gate = HoldingGate()
    peer = SimPeer(connect("sim", "sim-hold"), SimWorld("combined", seed=3), gate=gate, rates={"joints": 50})
    gate.peer = peer
    peer.start()
    try:
        fab, inbox = user
        jk = keys.robot_joints(world, "arm1")
        wait_until(lambda: jk in inbox.latest, what="first joint state")
        target = np.array([0.4, 0.2, -0.3, 0.5, 0.3, -0.6])
        cmd = Command("alice", 1, JointTarget(target), Header(seq=41, source="alice-1", wall_ns=7))
        fab.publish(keys.robot_cmd(world, "arm1", "joints", "alice"), cmd)
        robots = len(peer.world.robots)
        wait_until(
            lambda: peer.commands.held and peer.counters["owner_stops"] >= robots,
            what="the hold, and every robot's halt done by the worker",
            seen=lambda: (gate.looks, dict(peer.counters)),
        )
        peer.commands.resume()
        fab.publish(keys.robot_cmd(world, "arm1", "joints", "alice"), cmd)  # the client's copy, as after a pause

        def arrived() -> bool:
            js = inbox.latest.get(jk)
            return isinstance(js, JointState) and np.allclose(js.q, target, atol=1e-6)

        wait_until(
            arrived,
            timeout=15,
            what="arm1 at the target of the copy",
            seen=lambda: (inbox.latest.get(jk), dict(peer.counters)),
        )
    finally:
        peer.close()

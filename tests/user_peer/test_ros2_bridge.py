"""``robofabric ros2`` against a real ROS 2 node: a plain rclpy process (tests/user_peer/ros2_node.py, importing
nothing from robofabric) gets joint_states, scan, odom, map and clock equal to robofabric's own streams (stamped with
the sim's time), moves an arm through joint_command and joint_trajectory, drives a
base through cmd_vel (a stream that stops, stops the base) for the robots the bridge was told to drive
(``--drive``), without ownership moves nothing and is told why on /rosout, and without ``--drive`` moves nothing
at all: the bridge does not even listen (ROS 2 has no logins). Real router, real sim (the ``live`` fixture), real bridge and node processes on a ROS domain of
their own, discovery kept on this host."""

from __future__ import annotations

import json
import math
import os
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import rclpy  # noqa: E402,F401  (the test extra installs ROS 2 Kilted's wheels: missing, these tests fail)

import user_peer  # noqa: E402
from fabric import keys  # noqa: E402
from fabric.interfaces import OccupancyGrid  # noqa: E402
from robofabric.testing import robofabric_cmd, wait_until  # noqa: E402

pytestmark = pytest.mark.slow

NODE = Path(__file__).with_name("ros2_node.py")


def ros_env(domain: int) -> dict[str, str]:
    """A ROS domain of the test's own, discovery on this host only (other engineers' tests never hear it)."""
    return {"ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "ROS_LOCALHOST_ONLY": "1"}


def domain_for(salt: int) -> int:
    return 1 + (os.getpid() * 7 + salt) % 100


def lines(path: Path) -> list[dict]:
    if not path.exists():
        return []
    out = []
    for line in path.read_text().splitlines():
        try:
            out.append(json.loads(line))
        except json.JSONDecodeError:
            pass  # a line being written
    return out


def of(path: Path, topic: str) -> list[dict]:
    return [r for r in lines(path) if r["topic"] == topic]


def sim_ns(msg) -> int:
    """A message's sim time in ns: the ROS header stamp the bridge gives it (and the export, docs/ros2.md)."""
    return int(round(msg.header.stamp * 1e9))


class Observed:
    """robofabric's own streams, as a user script sees them: messages by their sim time (the ROS stamp)."""

    def __init__(self, world) -> None:
        self.lock = threading.Lock()
        self.joints: dict[int, list[float]] = {}
        self.scans: dict[int, np.ndarray] = {}
        self.sonars: dict[int, np.ndarray] = {}
        self.poses: dict[int, tuple[list[float], float]] = {}  # stamp -> (position, speed)
        self.sim_stamps: set[int] = set()
        self.subs = [
            world.on("robot/arm1/joints", self._joints),
            world.on("robot/base1/scan", self._scan),
            world.on("robot/base1/sonar", self._sonar),
            world.on("robot/base1/pose", self._pose),
        ]

    def _joints(self, key, msg) -> None:
        with self.lock:
            self.joints[sim_ns(msg)] = [float(v) for v in msg.q]
            self.sim_stamps.add(sim_ns(msg))

    def _scan(self, key, msg) -> None:
        with self.lock:
            self.scans[sim_ns(msg)] = np.asarray(msg.ranges, dtype=float)
            self.sim_stamps.add(sim_ns(msg))

    def _sonar(self, key, msg) -> None:
        with self.lock:
            self.sonars[sim_ns(msg)] = np.asarray(msg.ranges, dtype=float)

    def _pose(self, key, msg) -> None:
        with self.lock:
            self.poses[sim_ns(msg)] = ([float(v) for v in msg.position], float(np.linalg.norm(msg.linear[:2])))
            self.sim_stamps.add(sim_ns(msg))

    def latest_pose(self) -> tuple[list[float], float]:
        with self.lock:
            return self.poses[max(self.poses)]

    def close(self) -> None:
        for s in self.subs:
            s.close()


@pytest.fixture
def observer(live):
    world, port, _ = live
    w = user_peer.connect(world=world, connect=f"tcp/127.0.0.1:{port}", user="observer")
    obs = Observed(w)
    try:
        yield w, obs
    finally:
        obs.close()
        w.close()


def start_bridge(procs, world: str, port: int, domain: int, *extra: str):
    bridge = procs.start(
        robofabric_cmd("ros2", "--world", world, "--connect", f"tcp/127.0.0.1:{port}", *extra),
        name="bridge",
        env=ros_env(domain),
    )
    wait_until(
        lambda: "bridging world" in procs.output(bridge) or bridge.poll() is not None,
        timeout=60,
        what="the bridge up",
        seen=lambda: procs.output(bridge)[-2000:],
    )
    assert bridge.poll() is None, procs.output(bridge)[-2000:]
    return bridge


def start_node(procs, tmp_path: Path, domain: int):
    out, ctl = tmp_path / "ros.jsonl", tmp_path / "ctl"
    ctl.mkdir()
    node = procs.start(
        [sys.executable, str(NODE), "--out", str(out), "--control", str(ctl)], name="rosnode", env=ros_env(domain)
    )
    wait_until(
        lambda: of(out, "ready") or node.poll() is not None,
        timeout=30,
        what="the ROS node up",
        seen=lambda: procs.output(node)[-2000:],
    )
    assert node.poll() is None, procs.output(node)[-2000:]
    return node, out, ctl


def test_a_ros2_node_sees_the_world_as_robofabric_does_and_drives_a_base_it_owns(live, observer, procs, tmp_path):
    world, port, _ = live
    w, obs = observer
    # a map, as a compute peer would publish it (latched): the bridge gives it to late ROS joiners
    cells = np.full((4, 6), 255, dtype=np.uint8)
    cells[1, 2], cells[2, 3] = 0, 100
    w.fabric.publish(keys.map_key(world, "map"), OccupancyGrid(0.05, np.array([-1.0, -2.0, 0.0]), cells))
    domain = domain_for(1)
    bridge = start_bridge(
        procs,
        world,
        port,
        domain,
        "--user",
        "rosbridge",
        "--request",
        "base1",
        "--request",
        "arm1",
        "--drive",
        "base1",
        "--drive",
        "arm1",
    )
    assert "rosbridge owns base1" in procs.output(bridge) and "rosbridge owns arm1" in procs.output(bridge)
    assert "commands: taken for arm1, base1 only, from any node on this host" in procs.output(bridge)
    node, out, ctl = start_node(procs, tmp_path, domain)
    seen = lambda: {t: len(of(out, t)) for t in ("joint_states", "scan", "sonar", "odom", "clock", "map")}  # noqa: E731
    wait_until(
        lambda: all(n >= 5 for t, n in seen().items() if t != "map") and seen()["map"] >= 1,
        timeout=60,
        what="joint_states, scan, odom, clock and map on ROS 2",
        seen=lambda: (seen(), procs.output(bridge)[-1500:], procs.output(node)[-1500:]),
    )

    # the values are robofabric's: matched by stamp (the sim's time, which /clock carries, as in export --to ros2)
    with obs.lock:
        joints, scans, poses, sim_stamps = dict(obs.joints), dict(obs.scans), dict(obs.poses), set(obs.sim_stamps)
        sonars = dict(obs.sonars)
    js = [r for r in of(out, "joint_states") if r["stamp"] in joints]
    assert len(js) >= 3, (len(of(out, "joint_states")), len(joints))
    for r in js:
        assert r["frame"] == "arm1/base_link" and r["position"] == joints[r["stamp"]]  # float64 both ways: exact
    sc = [r for r in of(out, "scan") if r["stamp"] in scans]
    assert len(sc) >= 3, (len(of(out, "scan")), len(scans))
    for r in sc:
        assert r["frame"] == "base1/laser" and len(r["ranges"]) == len(scans[r["stamp"]])
        assert math.isclose(r["range_min"], 0.05, rel_tol=1e-6)  # the LIDAR's, from the world description
        mine = scans[r["stamp"]]
        missing = mine >= r["range_max"] - 5e-4  # no echo: robofabric's range_max, ROS's +inf (REP 117)
        np.testing.assert_allclose(r["ranges"], np.where(missing, np.inf, mine), rtol=1e-6)  # float32 in LaserScan
    # the sonar's ranges, measured from the ring's rim, are given from its centre (the frame base1/sonar is there)
    radius = next(r.sonar.radius for r in w.info().robots if r.id == "base1")
    so = [r for r in of(out, "sonar") if r["stamp"] in sonars]
    assert len(so) >= 3 and radius > 0.1, (len(of(out, "sonar")), len(sonars), radius)
    for r in so:
        mine = sonars[r["stamp"]]
        missing = mine >= r["range_max"] - radius - 5e-4
        assert r["frame"] == "base1/sonar" and math.isclose(r["range_min"], 0.02 + radius, rel_tol=1e-6)
        np.testing.assert_allclose(r["ranges"], np.where(missing, np.inf, mine + radius), rtol=1e-6)
    od = [r for r in of(out, "odom") if r["stamp"] in poses]
    assert len(od) >= 3
    for r in od:
        assert (r["frame"], r["child"]) == ("base1/odom", "base1/base_link") and r["position"] == poses[r["stamp"]][0]
    clocks = [r["ns"] for r in of(out, "clock")]
    assert clocks == sorted(clocks) and set(clocks) & sim_stamps, (clocks[:5], sorted(sim_stamps)[:5])
    grid = of(out, "map")[-1]
    assert (grid["frame"], grid["width"], grid["height"]) == ("map", 6, 4) and math.isclose(
        grid["resolution"], 0.05, rel_tol=1e-6
    )
    assert grid["data"][1 * 6 + 2] == 0 and grid["data"][2 * 6 + 3] == 100 and grid["data"].count(-1) == 22

    # drive: the node's cmd_vel stream moves the base; when the stream stops, the base stops (the sim's deadman)
    start, _ = obs.latest_pose()
    (ctl / "drive").write_text("0.4 0.0")
    wait_until(
        lambda: math.dist(obs.latest_pose()[0][:2], start[:2]) > 0.15,
        timeout=20,
        what="base1 driven by cmd_vel",
        seen=lambda: (obs.latest_pose(), procs.output(bridge)[-1500:]),
    )
    (ctl / "drive").unlink()
    assert any(r["subscribers"] >= 1 for r in of(out, "cmd_vel_sent"))  # the bridge listens to base1's cmd_vel
    stopped_at = time.monotonic()
    wait_until(
        lambda: obs.latest_pose()[1] < 0.01,
        timeout=10,
        what="base1 stopped after cmd_vel stopped",
        seen=obs.latest_pose,
    )
    braked_in = time.monotonic() - stopped_at
    there, _ = obs.latest_pose()
    moved_after = 0.0
    # still for a second more: nothing repeats the last twist (hold=False)
    t_end = time.monotonic() + 1.0
    while time.monotonic() < t_end:
        moved_after = max(moved_after, math.dist(obs.latest_pose()[0][:2], there[:2]))
        time.sleep(0.05)
    assert moved_after < 0.01, moved_after
    print(f"base1 stopped {braked_in:.2f} s after the last cmd_vel stream tick was written")

    # joint_command: positions by name, in another order than the arm's, move the arm there
    names = list(w.robot("arm1").entry.joint_names)
    target = [0.3, -0.2, 0.1, 0.0, 0.25, 0.0][: len(names)]
    (ctl / "joints").write_text(json.dumps([names[::-1], target[::-1]]))

    def at_target() -> bool:
        with obs.lock:
            q = obs.joints[max(obs.joints)]
        return bool(np.allclose(q, target, atol=2e-3))

    wait_until(
        at_target,
        timeout=30,
        what="arm1 at the joint_command's target",
        seen=lambda: (obs.joints[max(obs.joints)], procs.output(bridge)[-1500:]),
    )
    (ctl / "joints").unlink()

    # joint_trajectory: a JointTrajectory (names in another order) takes the arm to its last point (at_target
    # reads this new target)
    via, target = [-0.4, 0.3, 0.0, 0.2, 0.0, 0.1][: len(names)], [-0.2, 0.15, 0.2, 0.0, -0.25, 0.3][: len(names)]
    (ctl / "trajectory").write_text(json.dumps([names[::-1], [via[::-1], target[::-1]]]))
    wait_until(
        at_target,
        timeout=30,
        what="arm1 at the JointTrajectory's last point",
        seen=lambda: (obs.joints[max(obs.joints)], procs.output(bridge)[-1500:]),
    )
    (ctl / "trajectory").unlink()


def test_without_ownership_cmd_vel_moves_nothing_and_the_refusal_is_on_rosout(live, observer, procs, tmp_path):
    world, port, _ = live
    w, obs = observer
    wait_until(lambda: obs.poses, timeout=20, what="base1's pose")
    wait_until(lambda: obs.latest_pose()[1] < 0.01, timeout=10, what="base1 still", seen=obs.latest_pose)
    domain = domain_for(2)
    bridge = start_bridge(procs, world, port, domain, "--user", "rosguest", "--drive", "base1")  # owns nothing
    node, out, ctl = start_node(procs, tmp_path, domain)
    start, _ = obs.latest_pose()
    (ctl / "drive").write_text("0.4 0.0")
    refusals = lambda: [r for r in of(out, "rosout") if "refused cmd_vel for base1" in r["msg"]]  # noqa: E731
    wait_until(
        lambda: refusals() and len(of(out, "cmd_vel_sent")) >= 10,
        timeout=30,
        what="the refusal on /rosout after 10 cmd_vel",
        seen=lambda: (of(out, "rosout")[-3:], len(of(out, "cmd_vel_sent")), procs.output(bridge)[-1500:]),
    )
    moved = math.dist(obs.latest_pose()[0][:2], start[:2])
    (ctl / "drive").unlink()
    r = refusals()[0]
    assert r["name"].startswith("robofabric_rosguest") and r["level"] >= 30  # WARN
    assert "rosguest does not own base1" in r["msg"] and "--request base1" in r["msg"]
    assert moved < 0.005, moved
    procs.close()  # SIGTERM: the bridge says what it did before it ends
    assert "refused" in procs.output(bridge) and " 0 commands forwarded" in procs.output(bridge), procs.output(bridge)[
        -1500:
    ]


def test_without_drive_a_ros2_nodes_cmd_vel_moves_nothing_though_the_bridge_owns_the_base(
    live, observer, procs, tmp_path
):
    """A plain rclpy node (no login: ROS 2 has none) on the bridge's domain publishes base1's cmd_vel while the
    bridge's login owns base1: without --drive the bridge does not listen, says so at start, and base1 stays."""
    world, port, _ = live
    w, obs = observer
    wait_until(lambda: obs.poses, timeout=20, what="base1's pose")
    wait_until(lambda: obs.latest_pose()[1] < 0.01, timeout=10, what="base1 still", seen=obs.latest_pose)
    domain = domain_for(3)
    bridge = start_bridge(procs, world, port, domain, "--user", "rosowner", "--request", "base1")
    text = procs.output(bridge)
    assert "rosowner owns base1" in text, text[-1500:]
    assert "commands: none taken (publishing only); --drive ROBOT takes cmd_vel and joint commands for it" in text, (
        text[-1500:]
    )
    node, out, ctl = start_node(procs, tmp_path, domain)
    # the node and the bridge found each other: the node has base1's odometry from it
    wait_until(
        lambda: len(of(out, "odom")) >= 5,
        timeout=60,
        what="odom from the bridge",
        seen=lambda: procs.output(node)[-1500:],
    )
    start, _ = obs.latest_pose()
    (ctl / "drive").write_text("0.4 0.0")
    wait_until(
        lambda: len(of(out, "cmd_vel_sent")) >= 20,
        timeout=30,
        what="20 cmd_vel sent by the node",
        seen=lambda: procs.output(node)[-1500:],
    )
    moved = max(math.dist(obs.latest_pose()[0][:2], start[:2]), obs.latest_pose()[1])
    (ctl / "drive").unlink()
    assert all(r["subscribers"] == 0 for r in of(out, "cmd_vel_sent")), of(out, "cmd_vel_sent")[-3:]
    assert moved < 0.005, moved
    assert w.robot("base1").record.owner == "rosowner"  # the bridge's own, all along
    procs.close()
    assert " 0 commands forwarded, 0 refused" in procs.output(bridge), procs.output(bridge)[-1500:]

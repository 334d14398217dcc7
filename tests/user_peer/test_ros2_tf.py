"""The bridge's /tf is the export's frame tree: for the same robot state, the transforms it publishes equal the
``/tf`` of ``export --to ros2`` (decoded by mcap-ros2-support), stamped with the sim's time; the sensor mounts
go once more on /tf_static (REP 105's names: ``map -> ID/odom -> ID/base_link -> ID/laser``; an arm's URDF links,
each in its parent link's frame, as robot_state_publisher sends them). The message class and the publishers are stand-ins
here, to see each message as sent (test_ros2_ros_users.py reads the real ``tf2_msgs`` over DDS); the bridge
publishes /tf only where ``tf2_msgs`` is importable, and says whether it is."""

from __future__ import annotations

import importlib.util
import os
from dataclasses import dataclass, field

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

import rclpy  # noqa: E402,F401  (the test extra installs ROS 2 Kilted's wheels: missing, these tests fail)

import robots  # noqa: E402
from fabric.interfaces import Header, JointState, Pose  # noqa: E402
from fabric.interfaces.geometry import quaternion_from_yaw  # noqa: E402
from robots.urdf import parse as read_urdf  # noqa: E402
from user_peer.catalog import RobotCatalog  # noqa: E402
from user_peer.openfmt.frames import FrameTracker  # noqa: E402
from user_peer.openfmt.ros2 import Ros2Writer  # noqa: E402
from user_peer.ros2.tf import TfOut, tf_message_class  # noqa: E402

T0 = 1_760_000_000_000_000_000
BUILD_IT = (
    "tf2_msgs is not importable: it is not among ROS 2 Kilted's wheels; build it into this environment with "
    "`python -m user_peer.ros2.msgbuild` (make test does; it needs g++ and Python's headers)"
)


@dataclass
class TFMessage:
    """tf2_msgs/TFMessage's one field."""

    transforms: list = field(default_factory=list)


class Sent:
    """What a publisher was given."""

    def __init__(self) -> None:
        self.msgs: list = []

    def publish(self, msg) -> None:
        self.msgs.append(msg)


def state() -> list[tuple[str, object]]:
    names = robots.load("meca500").joint_names
    out: list[tuple[str, object]] = []
    for i in range(1, 6):
        h = Header(0.05 * i, T0 + i, i, "sim-1")
        out.append(
            ("rf/w/robot/base1/pose", Pose(np.array([0.1 * i, 0.2, 0.0]), quaternion_from_yaw(0.3 * i), header=h))
        )
        out.append(("rf/w/robot/arm1/joints", JointState(names, np.full(6, 0.1 * i), np.zeros(6), h)))
    return out


def row(parent: str, child: str, ns: int, tr, rot) -> tuple:
    return (parent, child, ns, tuple(round(v, 9) for v in tr), tuple(round(v, 9) for v in rot))


def test_the_bridges_tf_is_the_exports_frame_tree_stamped_with_sim_time(tmp_path):
    sent: dict[str, Sent] = {}
    tf = TfOut(
        None,
        RobotCatalog(None, scene="combined"),
        message=TFMessage,
        publisher=lambda topic, qos: sent.setdefault(topic, Sent()),
    )
    with Ros2Writer(tmp_path / "e.mcap", scene="combined") as w:
        for key, msg in state():
            ns = int(round(msg.header.stamp * 1e9))
            tf.on_state(key, msg, ns)
            w.write(key, msg, T0)
    live = [
        row(
            t.header.frame_id,
            t.child_frame_id,
            t.header.stamp.sec * 10**9 + t.header.stamp.nanosec,
            (t.transform.translation.x, t.transform.translation.y, t.transform.translation.z),
            (t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z, t.transform.rotation.w),
        )
        for m in sent["/tf"].msgs
        for t in m.transforms
    ]
    exported = []
    with open(tmp_path / "e.mcap", "rb") as f:
        for _s, _c, _m, m in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages(topics=["/tf"]):
            exported += [
                row(
                    t.header.frame_id,
                    t.child_frame_id,
                    t.header.stamp.sec * 10**9 + t.header.stamp.nanosec,
                    (t.transform.translation.x, t.transform.translation.y, t.transform.translation.z),
                    (t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z, t.transform.rotation.w),
                )
                for t in m.transforms
            ]
    assert live == exported and len(live) > 10
    parents = {r[1]: r[0] for r in live}
    assert {c: p for c, p in parents.items() if c.startswith("base1/")} == {
        "base1/odom": "map",
        "base1/base_link": "base1/odom",
        "base1/laser": "base1/base_link",
        "base1/sonar": "base1/base_link",
    }
    urdf = read_urdf(robots.load("meca500").urdf_path.read_text())  # robot_state_publisher's tree: parent link -> child
    assert {c: p for c, p in parents.items() if c.startswith("arm1/")} == {
        "arm1/" + urdf.root: "map",
        **{f"arm1/{j.child}": f"arm1/{j.parent}" for j in urdf.joints},
    }
    assert {"arm1/base_link", "arm1/link_6", "arm1/flange"} <= set(parents)
    assert {r[2] for r in live} == {int(round(0.05 * i * 1e9)) for i in range(1, 6)}  # the sim's time
    static = [sorted((t.header.frame_id, t.child_frame_id) for t in m.transforms) for m in sent["/tf_static"].msgs]
    assert static == [
        [("base1/base_link", "base1/laser"), ("base1/base_link", "base1/sonar"), ("map", "base1/odom")]
    ]  # once
    assert tf.sent == len(sent["/tf"].msgs)


def test_tf_is_published_where_tf2_msgs_is_importable_and_make_test_builds_it():
    assert importlib.util.find_spec("tf2_msgs") is not None, BUILD_IT
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=1 + (os.getpid() % 100))
    try:
        node = rclpy.create_node("tf_gate", context=context)
        tf = TfOut(node, RobotCatalog(None))
        assert tf.available and tf_message_class() is not None
        assert {name for name, _ in node.get_publisher_names_and_types_by_node("tf_gate", "/")} >= {"/tf", "/tf_static"}
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)


def test_each_sonar_transducers_frame_goes_once_on_tf_static_under_the_namespace():
    from fabric.interfaces import RobotInfo, SonarInfo, WorldInfo

    sent: dict[str, Sent] = {}
    tf = TfOut(
        None,
        RobotCatalog(None),
        namespace="class1",
        message=TFMessage,
        publisher=lambda topic, qos: sent.setdefault(topic, Sent()),
    )
    sonar = SonarInfo(np.radians([0.0, 90.0, 180.0]), 0.26, 0.12, 0.02, 3.0)
    info = WorldInfo(
        "w",
        "s",
        0.002,
        {},
        (RobotInfo("base1", "reeman", "mobile", np.zeros(4), (), np.zeros(0), np.zeros(0), np.zeros(0), sonar=sonar),),
    )
    tf.describe(info)
    tf.describe(info)  # the same description again: nothing more
    assert len(sent["/class1/tf_static"].msgs) == 1  # the transducers, once
    rows = {
        (t.header.frame_id, t.child_frame_id): (t.transform.translation.x, t.transform.translation.y)
        for t in sent["/class1/tf_static"].msgs[0].transforms
    }
    assert set(rows) == {("class1/base1/sonar", f"class1/base1/sonar_{i}") for i in range(3)}
    assert rows[("class1/base1/sonar", "class1/base1/sonar_1")] == pytest.approx((0.0, 0.26), abs=1e-12)


def described_world(*entries: tuple[str, str]):
    """A world description naming each (id, type), a Reeman with its sonar ring."""
    from fabric.interfaces import RobotInfo, SonarInfo, WorldInfo

    sonar = SonarInfo(np.radians(np.arange(0.0, 360.0, 45.0)), 0.26, 0.12, 0.02, 3.0, center=np.array([0.05, 0.0]))
    return WorldInfo(
        "w",
        "s",
        0.002,
        {"scan": 20.0},
        tuple(
            RobotInfo(
                rid,
                rtype,
                robots.load(rtype).kind,
                np.array([3.0, 0.0, 0.75, 0.0]),
                robots.load(rtype).joint_names,
                np.zeros(6),
                np.zeros(6),
                np.zeros(6),
                sonar=sonar if rtype == "reeman" else None,
            )
            for rid, rtype in entries
        ),
    )


def tree(transforms) -> tuple[dict[str, set[str]], set[str]]:
    """Each child's parents, and the roots, of (parent, child) pairs."""
    parents: dict[str, set[str]] = {}
    for parent, child in transforms:
        parents.setdefault(child, set()).add(parent)
    return parents, {p for ps in parents.values() for p in ps} - set(parents)


def test_robots_heard_before_the_world_description_end_with_the_described_static_set_and_one_tree():
    """The bridge hears an arm's and a base's poses before the world description (ids in no scene: drawn from a
    guess, both as mobile bases of no type, the arm with ``arm7/odom`` and ``arm7/laser`` mounts on /tf_static).
    Once the description comes, the latched /tf_static (one message, the whole set) is sent again as the
    described robots have it: the base's mounts with its sonar ring, nothing of the arm; and what follows on
    /tf is one tree under map."""
    sent: dict[str, Sent] = {}
    tf = TfOut(None, RobotCatalog(None), message=TFMessage, publisher=lambda topic, qos: sent.setdefault(topic, Sent()))
    names = robots.load("meca500").joint_names
    h = lambda i: Header(0.05 * i, T0 + i, i, "sim-1")  # noqa: E731
    pose = lambda i: Pose(np.array([0.1 * i, 0.2, 0.0]), quaternion_from_yaw(0.3 * i), header=h(i))  # noqa: E731
    for i in (1, 2):  # before the description
        tf.on_state("rf/w/robot/arm7/pose", pose(i), T0 + i)
        tf.on_state("rf/w/robot/base7/pose", pose(i), T0 + i)
    assert {"arm7/odom", "arm7/laser"} <= {
        t.child_frame_id for t in sent["/tf_static"].msgs[-1].transforms
    }  # the guess
    tf.describe(described_world(("arm7", "meca500"), ("base7", "reeman")))
    first_tf = len(sent["/tf"].msgs)
    for i in (3, 4):  # after it
        tf.on_state("rf/w/robot/arm7/pose", pose(i), T0 + i)
        tf.on_state("rf/w/robot/arm7/joints", JointState(names, np.full(6, 0.1 * i), np.zeros(6), h(i)), T0 + i)
        tf.on_state("rf/w/robot/base7/pose", pose(i), T0 + i)
    static = [(t.header.frame_id, t.child_frame_id) for t in sent["/tf_static"].msgs[-1].transforms]
    assert {c for _, c in static} == {
        "base7/odom",
        "base7/laser",
        "base7/sonar",
        *(f"base7/sonar_{i}" for i in range(8)),
    }
    live = [(t.header.frame_id, t.child_frame_id) for m in sent["/tf"].msgs[first_tf:] for t in m.transforms]
    parents, roots = tree(static + live)
    assert all(len(p) == 1 for p in parents.values()), {c: p for c, p in parents.items() if len(p) != 1}
    assert roots == {"map"} and parents["arm7/base_link"] == {"map"} and parents["base7/sonar"] == {"base7/base_link"}
    assert parents["arm7/flange"] == {"arm7/link_6"}


def test_robots_drawn_at_once_on_several_threads_are_each_drawn_from_the_whole_catalog():
    """The bridge draws robots on zenoh's callback threads, the first ones at the same moment: each must see the
    robot types all loaded (a half-loaded catalog drew the Meca500 as a mobile base with ``arm1/odom`` and
    ``arm1/laser``, and the Reeman without its sonar ring, and those drawings were kept)."""
    import threading

    info = described_world(("arm1", "meca500"), ("base1", "reeman"))
    for _ in range(3):
        tracker = FrameTracker(RobotCatalog(info))
        start = threading.Barrier(2)
        drawn: dict[str, object] = {}

        def draw(rid: str, tracker=tracker, start=start, drawn=drawn) -> None:
            start.wait(timeout=60)
            drawn[rid] = tracker.robot(rid, {"mobile": True})

        threads = [threading.Thread(target=draw, args=(rid,)) for rid in ("arm1", "base1")]
        for t in threads:
            t.start()
        for t in threads:
            t.join(timeout=120)
        assert (drawn["arm1"].kind, drawn["arm1"].type) == ("arm", "meca500")
        assert (drawn["base1"].kind, drawn["base1"].type, drawn["base1"].sonar is not None) == (
            "mobile",
            "reeman",
            True,
        )

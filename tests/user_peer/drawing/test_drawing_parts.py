"""The parts of the Rerun drawing (user_peer.drawing): thinning per key, stream rates per period, static parts
logged once per entity, and the drawers behind WorldLogger each drawing their own kind."""

from __future__ import annotations

import numpy as np
import rerun as rr

from fabric.interfaces import JointState, OccupancyGrid, Pose
from user_peer.drawing.canvas import Canvas
from user_peer.drawing.intake import Intake, RateMeter, message_times
from user_peer.rerun_log import WorldLogger


class Calls:
    """A real recording whose log and send_columns calls are noted instead of sent."""

    def __init__(self) -> None:
        self.rec = rr.RecordingStream("drawing-parts")
        self.seen: list[tuple[str, str, bool]] = []  # (call, entity, static)
        self.rec.log = lambda path, *a, static=False: self.seen.append(("log", path, static))  # type: ignore[method-assign]
        self.rec.send_columns = lambda path, indexes, columns: self.seen.append(("cols", path, False))  # type: ignore[method-assign]

    def entities(self, call: str) -> list[str]:
        return [e for c, e, _ in self.seen if c == call]


def test_thinning_keeps_one_message_per_interval_per_key_and_counts_the_rest():
    intake = Intake(max_hz=10.0)  # one every 0.1 s per key
    t = [i * 50_000_000 for i in range(10)]  # every 50 ms
    drawn = [intake.due("rf/w/robot/a/joints", ti) for ti in t]
    assert drawn == [True, False] * 5
    assert intake.skipped == 5
    assert all(intake.due("rf/w/robot/b/joints", ti) for ti in t[::2])  # another key has its own interval
    assert all(Intake(max_hz=0).due("k", ti) for ti in [0, 0, 1])  # 0: everything is drawn


def test_keys_are_labelled_by_stream_and_foreign_keys_are_not_drawn():
    intake = Intake(max_hz=0)
    assert intake.parse("not/a/fabric/key") is None
    assert intake.parse("rf/w/robot/arm1/joints")[1] == "arm1/joints"
    assert intake.parse("rf/w/map/map")[1] == "map/map"


def test_a_message_time_is_its_wall_clock_else_its_arrival():
    from fabric.interfaces import Header

    assert message_times(object(), 7) == (7, 0.0)
    assert message_times(Pose([0, 0, 0], header=Header(stamp=1.5, wall_ns=99)), 7) == (99, 1.5)
    assert message_times(Pose([0, 0, 0], header=Header(stamp=0.0, wall_ns=0)), 7) == (7, 0.0)


def test_stream_rates_are_the_messages_of_each_period():
    calls = Calls()
    meter = RateMeter(period_s=0.5)
    closed = [meter.count("arm1/joints", i * 100_000_000) for i in range(11)]  # 10 Hz for 1 s
    assert closed == [False, False, False, False, False, True, False, False, False, False, True]
    meter.flush(calls.rec)
    assert calls.entities("cols") == ["plots/rates/arm1/joints"]
    meter.flush(calls.rec)  # nothing new: nothing sent
    assert len(calls.seen) == 1


def test_static_parts_are_logged_once_until_forgotten():
    canvas = Canvas(rr.RecordingStream("once"))
    assert canvas.once("map/m/robots/a") and not canvas.once("map/m/robots/a")
    assert canvas.once("world/objects/goal")
    canvas.forget("map/m/")
    assert canvas.once("map/m/robots/a") and not canvas.once("world/objects/goal")


def test_each_robot_kind_is_drawn_by_its_own_parts():
    """An arm's pose is its flange and its joints move its links; a base's pose is its body (and its dot on
    every map), its joints are its wheels."""
    from user_peer.catalog import RobotCatalog

    calls = Calls()
    logger = WorldLogger(calls.rec, drawing=RobotCatalog(scene="combined").drawing, max_hz=0)
    logger.log("rf/w/map/map", OccupancyGrid(0.1, [0, 0, 0], np.zeros((4, 4), np.uint8)), 1)
    logger.log(
        "rf/w/robot/arm1/joints", JointState(tuple(f"joint_{k}" for k in range(1, 7)), np.zeros(6), np.zeros(6)), 2
    )
    logger.log("rf/w/robot/arm1/pose", Pose([0.1, 0.2, 0.3]), 3)
    logger.log("rf/w/robot/base1/joints", JointState(("left", "right"), np.zeros(2), np.zeros(2)), 4)
    logger.log("rf/w/robot/base1/pose", Pose([1.0, 0.2, 0.0]), 5)
    assert logger.pending == 4 and logger.flush() == 4 and logger.pending == 0
    sent = set(calls.entities("cols"))
    assert {
        "plots/joints/arm1",
        "plots/joint_speed/arm1",
        "world/robots/arm1/links/joint_1",
        "world/robots/arm1/flange",
    } <= sent
    assert {"plots/wheels/base1", "world/robots/base1/base", "plots/speed/base1", "map/map/robots/base1"} <= sent
    assert not {"plots/wheels/arm1", "world/robots/arm1/base", "plots/joints/base1", "world/robots/base1/flange"} & sent
    static = {e for c, e, st in calls.seen if c == "log" and st}
    assert {"world/robots/base1/base/body", "world/robots/arm1/skeleton", "world/robots/arm1/flange/axes"} <= static

"""A JointTrajectory followed in time (user_peer/ros2/trajectory.py, issue 46): its points checked and put in the
arm's order, the position at any time interpolated between them from where the arm was, and the player sending
each playing arm its target for now (a fake clock), replaced by a newer trajectory, ended by a refusal."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from user_peer.ros2.commands import CommandError
from user_peer.ros2.trajectory import Timed, TrajectoryPlayer, sample, timed_points

ARM = ["j1", "j2"]


def traj(names, points) -> JointTrajectory:
    t = JointTrajectory()
    t.joint_names = list(names)
    for positions, seconds in points:
        p = JointTrajectoryPoint()
        p.positions = [float(v) for v in positions]
        p.time_from_start.sec, p.time_from_start.nanosec = int(seconds), int(round((seconds % 1) * 1e9))
        t.points.append(p)
    return t


def test_points_come_in_the_arms_order_with_their_times():
    t = timed_points("arm1", ARM, traj(["j2", "j1"], [([2.0, 1.0], 0.5), ([0.2, 0.1], 3.25)]))
    assert t == Timed((0.5, 3.25), ((1.0, 2.0), (0.1, 0.2)))


@pytest.mark.parametrize(
    "points, why",
    [
        ([], "without points"),
        ([([0.0, 0.0], 2.0), ([0.1, 0.1], 1.0)], "goes back"),
        ([([math.nan, 0.0], 1.0)], "not finite"),
        ([([0.0, 5.0], 1.0)], "outside its limits"),
    ],
)
def test_a_trajectory_the_arm_cannot_follow_is_refused_with_its_reason(points, why):
    with pytest.raises(CommandError, match=why):
        timed_points("arm1", ARM, traj(ARM, points), lower=[-3.0, -3.0], upper=[3.0, 3.0])


def test_the_position_is_interpolated_from_the_arms_start_through_the_points():
    t = Timed((1.0, 3.0), ((1.0, 0.0), (1.0, 2.0)))
    assert sample(t, (0.0, 0.0), 0.0) == ((0.0, 0.0), False)
    assert sample(t, (0.0, 0.0), 0.5) == ((0.5, 0.0), False)
    assert sample(t, (0.0, 0.0), 2.0) == ((1.0, 1.0), False)
    assert sample(t, (0.0, 0.0), 3.0) == ((1.0, 2.0), True)
    assert sample(t, None, 0.2) == ((1.0, 0.0), False)  # no start known: the first point until its time


@given(st.lists(st.floats(0.0, 5.0), min_size=1, max_size=6), st.floats(-1.0, 10.0))
def test_a_sample_lies_between_the_positions_it_comes_between(gaps, elapsed):
    times = tuple(sum(gaps[: i + 1]) for i in range(len(gaps)))
    positions = tuple((float(i), -float(i)) for i in range(1, len(gaps) + 1))
    q, done = sample(Timed(times, positions), (0.0, 0.0), elapsed)
    assert done == (elapsed >= times[-1])
    assert 0.0 <= q[0] <= len(gaps) and q[1] == pytest.approx(-q[0])


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_the_player_sends_a_trajectory_whole_keeps_it_until_its_end_and_a_new_one_replaces_it():
    clock, sent, failed = Clock(), [], []
    player = TrajectoryPlayer(clock)
    t = Timed((2.0,), ((2.0, 4.0),))
    first = player.play("arm1", t, (0.0, 0.0), sent.append, failed.append)
    assert sent == [t]  # one command: the sim plays it in its own time
    clock.t += 1.0
    assert player.current("arm1") is first and player.playing() == {"arm1"}
    second = player.play("arm1", Timed((1.0,), ((0.0, 0.0),)), (1.0, 2.0), sent.append, failed.append)
    assert player.current("arm1") is second and len(sent) == 2
    clock.t += 1.0
    assert player.current("arm1") is None and player.playing() == set() and not failed  # over on the clock


def test_a_refused_trajectory_ends_at_once_and_is_told():
    clock, failed = Clock(), []

    def refuse(t):
        raise ValueError("arm1 is not yours")

    player = TrajectoryPlayer(clock)
    player.play("arm1", Timed((2.0,), ((2.0, 4.0),)), None, refuse, failed.append)
    assert [str(e) for e in failed] == ["arm1 is not yours"] and player.playing() == set()

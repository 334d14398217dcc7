"""The rider of a waited command (user_peer.pause.PauseRider), alone, on a clock passed in: it sends the command again
while its sim holds, and keeps doing so (once a second) after the sim's reports stop, since the last copy it had
reported refused may not be the last one it refused (its reports are rate-limited) and its word that it hears again
may come before its token (untrusted). A robot that never met a pause is never sent a copy, unless it shows no sign
of the command (given a ``heard`` test): a new sim not yet known as a listener lost it."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import pytest

from fabric.interfaces import Command, Event
from user_peer.errors import NotOwner
from user_peer.pause import QUIET_S, RESEND_MAX_S, UNHEARD_S, PauseRider
from user_peer.robot import HELD


CMD = Command(user="alice", epoch=3, body={"q": [0.0] * 6})


class FakeClock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


class Robot:
    """What the rider reads of a robot: its refusals (appended by the test), its sim's arrivals, its joints."""

    def __init__(self) -> None:
        self.id = "arm1"
        self.refusals: list[Event] = []
        self.sent: list[float] = []
        self.clock = FakeClock()
        self.world = SimpleNamespace(
            rejections=lambda rid, since: list(self.refusals), presence=SimpleNamespace(arrivals=0), user="alice"
        )

    def resend(self, command: str, cmd: Any) -> None:
        self.sent.append(self.clock.t)

    def latest(self, stream: str) -> Any:
        return None


def _refusal(code: str) -> Event:
    return Event(kind="reject", reason=code, object="arm1", user="alice", data={"command": "joints", "code": code})


def _run(robot: Robot, rider: PauseRider, until: float, step: float = 0.05) -> None:
    while robot.clock.t < until:
        rider.check()
        robot.clock.t = round(robot.clock.t + step, 6)


@pytest.fixture
def robot() -> Robot:
    return Robot()


def _gives(robot: Robot) -> list[tuple[str, int]]:
    """(command, epoch) of each command the rider gives anew (``Robot.send`` with an epoch), as it gives them."""
    given: list[tuple[str, int]] = []

    def send(command: str, body: Any, *, epoch: int) -> Command:
        given.append((command, epoch))
        return Command(user="alice", epoch=epoch, body=body)

    robot.send = send  # type: ignore[attr-defined]
    return given


def test_no_pause_no_copy(robot):
    rider = PauseRider(robot, "joints", CMD, 0, clock=robot.clock)  # type: ignore[arg-type]
    _run(robot, rider, 30.0)
    assert robot.sent == [] and rider.note() == ""


def test_copies_go_on_once_a_second_after_the_sims_reports_stop(robot):
    rider = PauseRider(robot, "joints", CMD, 0, clock=robot.clock)  # type: ignore[arg-type]
    robot.refusals.append(_refusal(HELD))  # one hold reported, then nothing more (its reports spent)
    _run(robot, rider, 12.0)
    assert robot.sent[0] == 0.0  # at once
    late = [t for t in robot.sent if t > QUIET_S + RESEND_MAX_S]
    assert len(late) >= 8, robot.sent  # still sent, once a second, long after the last report
    gaps = [b - a for a, b in zip(robot.sent, robot.sent[1:])]
    assert max(gaps) <= RESEND_MAX_S + 0.06 and min(gaps) >= 0.19, gaps  # growing intervals, then one a second
    assert "held its robots (a pause) 1 time(s)" in rider.note()


def test_a_sim_back_after_a_cut_is_sent_the_command_with_no_report_at_all(robot):
    rider = PauseRider(robot, "joints", CMD, 0, clock=robot.clock)  # type: ignore[arg-type]
    _run(robot, rider, 3.0)
    assert robot.sent == []
    robot.world.presence.arrivals += 1  # its token came back: it may never have had the command
    _run(robot, rider, 10.0)
    assert robot.sent[0] == pytest.approx(3.0) and robot.sent[-1] > 9.0, robot.sent


def test_any_other_refusal_is_raised(robot):
    rider = PauseRider(robot, "joints", CMD, 0, clock=robot.clock)  # type: ignore[arg-type]
    robot.refusals.append(
        Event(
            kind="reject",
            reason="not granted",
            object="arm1",
            user="alice",
            data={"command": "joints", "code": "refused"},
        )
    )
    with pytest.raises(NotOwner):
        rider.check()


def test_a_command_with_no_sign_is_sent_again_until_one_comes(robot):
    sign = {"moved": False}
    rider = PauseRider(robot, "joints", CMD, 0, clock=robot.clock, heard=lambda: sign["moved"])  # type: ignore[arg-type]
    _run(robot, rider, UNHEARD_S - 0.1)
    assert robot.sent == []  # the first state with its sign may take a moment
    _run(robot, rider, 4.04)
    assert robot.sent[0] == pytest.approx(UNHEARD_S) and len(robot.sent) == 4, robot.sent  # then once a second
    assert "no sign of the command came, and it was sent again 4 time(s)" in rider.note()
    sign["moved"] = True  # the arm moves: the sim has it
    _run(robot, rider, 20.0)
    assert len(robot.sent) == 4, robot.sent


def test_a_command_heard_at_once_is_never_sent_again(robot):
    rider = PauseRider(robot, "joints", CMD, 0, clock=robot.clock, heard=lambda: True)  # type: ignore[arg-type]
    _run(robot, rider, 20.0)
    assert robot.sent == [] and rider.note() == ""


def test_a_robot_given_back_to_its_owner_gets_the_command_again_under_her_new_epoch_once(robot):
    """Held for gone (her token went with the sim's link, and came back within grace), she owned the robot again at
    a higher epoch: the sim had stopped it, and refuses a copy at the old one. Not for a path (no resend_on_takeover)."""
    given = _gives(robot)
    robot.world.user = "alice"
    robot.record = SimpleNamespace(owner="alice", epoch=3)  # type: ignore[attr-defined]

    rider = PauseRider(robot, "joints", CMD, 0, clock=robot.clock, resend_on_takeover=True)  # type: ignore[arg-type]
    _run(robot, rider, 1.0)
    robot.record = SimpleNamespace(owner="alice", epoch=5)  # taken (4: free), given back (5)
    _run(robot, rider, 3.0)
    assert given == [("joints", 5)] and rider.cmd.epoch == 5 and robot.sent == []
    assert "given back, and the command given again 1 time(s)" in rider.note()
    robot.record = SimpleNamespace(owner="bob", epoch=6)  # someone else's: not hers to give again
    _run(robot, rider, 5.0)
    assert given == [("joints", 5)]
    path_rider = PauseRider(robot, "path", CMD, 0, clock=robot.clock)  # type: ignore[arg-type]
    robot.record = SimpleNamespace(owner="alice", epoch=9)
    _run(robot, path_rider, 8.0)
    assert given == [("joints", 5)]


def test_a_command_refused_for_a_past_epoch_of_hers_is_given_again_under_her_new_one_any_kind(robot):
    """Woken from a pause, the paused student sent his path under the epoch his replica still had; the sim refused it
    ("stale epoch 1 for base1 (current 3)") though base1 was his again: asked, the authority says so, and the path
    is given again under epoch 3. A later refusal of the old copy changes nothing; one while another owns it stands."""
    given = _gives(robot)
    stale = SimpleNamespace(owner="alice", epoch=3)
    robot.record = stale  # type: ignore[attr-defined]
    robot.world.user = "alice"
    robot.world.ownership = SimpleNamespace(fetch=lambda rid, timeout: SimpleNamespace(owner="alice", epoch=5))

    refused = Event(
        kind="reject",
        reason="stale epoch 3 for arm1 (current 5)",
        object="arm1",
        user="alice",
        data={"command": "path", "code": "refused"},
    )
    rider = PauseRider(robot, "path", CMD, 0, clock=robot.clock)  # type: ignore[arg-type]
    robot.refusals.append(refused)
    rider.check()
    assert given == [("path", 5)] and rider.cmd.epoch == 5
    robot.record = SimpleNamespace(owner="alice", epoch=5)  # type: ignore[attr-defined]
    robot.refusals.append(refused)  # the old copy's refusal, late
    rider.check()
    assert given == [("path", 5)]
    robot.world.ownership = SimpleNamespace(fetch=lambda rid, timeout: SimpleNamespace(owner="bob", epoch=6))
    robot.record = SimpleNamespace(owner="bob", epoch=6)  # type: ignore[attr-defined]
    robot.refusals.append(refused)
    with pytest.raises(NotOwner):
        rider.check()


def test_a_copy_due_while_the_robot_is_hers_again_at_a_newer_epoch_is_given_under_it(robot):
    """The paused student (2026-12-04): his sim's token came back as base1 came back to him at epoch 3, and the copy
    that was due went before any refusal of the sim's: at the past epoch it raised "changed hands" (owner: bob). It is
    given again under his epoch instead, then copied under it; another's robot still raises."""
    given = _gives(robot)
    robot.world.user = "alice"
    robot.record = SimpleNamespace(owner="alice", epoch=3)  # type: ignore[attr-defined]

    def resend(command: str, cmd: Command) -> None:  # as Robot.resend: a copy at another epoch than the record's
        if robot.record.owner != "alice" or robot.record.epoch != cmd.epoch:  # type: ignore[attr-defined]
            raise NotOwner(f"changed hands (epoch {cmd.epoch}, now {robot.record.epoch})")  # type: ignore[attr-defined]
        robot.sent.append(robot.clock.t)

    robot.resend = resend  # type: ignore[method-assign]
    rider = PauseRider(robot, "path", CMD, 0, clock=robot.clock)  # type: ignore[arg-type]
    _run(robot, rider, 1.0)
    robot.record = SimpleNamespace(owner="alice", epoch=5)  # type: ignore[attr-defined]  # held for gone, given back
    robot.world.presence.arrivals += 1  # the sim's token back: a copy is due at once
    _run(robot, rider, 4.0)
    assert given == [("path", 5)] and rider.cmd.epoch == 5 and robot.sent, (given, robot.sent)
    assert "given back, and the command given again 1 time(s)" in rider.note()
    robot.record = SimpleNamespace(owner="bob", epoch=6)  # type: ignore[attr-defined]
    with pytest.raises(NotOwner):
        _run(robot, rider, 8.0)

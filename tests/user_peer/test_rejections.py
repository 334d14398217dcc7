"""Which error a sim's refusal becomes: the ownership gate's is NotOwner, anything else Rejected."""

from __future__ import annotations

import pytest

from fabric.interfaces import Event
from user_peer.errors import NotOwner, Paused, Rejected
from user_peer.robot import HELD, OWNERSHIP_REFUSAL, rejection_error


def _reject(reason: str, **data: str) -> Event:
    return Event(kind="reject", reason=reason, object="arm1", user="alice", data=dict(data))


def test_the_ownership_gates_refusal_is_notowner():
    err = rejection_error("arm1", _reject("arm1 is owned by bob, not alice", command="joints", code=OWNERSHIP_REFUSAL))
    assert isinstance(err, NotOwner) and "owned by bob" in err.reason


def test_a_sim_that_does_not_say_which_check_refused_is_read_as_notowner():
    assert isinstance(
        rejection_error("arm1", _reject("stale epoch 1 for arm1 (current 2)", command="joints")), NotOwner
    )


@pytest.mark.parametrize(
    "code, detail",
    [
        ("wrong_body", "a joints command needs a JointTarget, got Twist"),
        ("not_finite", "the path contains NaN or infinity"),
    ],
)
def test_any_other_refusal_is_rejected_with_robot_command_and_code(code, detail):
    err = rejection_error("arm1", _reject(code, command="path", code=code, detail=detail))
    assert isinstance(err, Rejected) and not isinstance(err, (NotOwner, Paused))
    assert (err.robot, err.command, err.code) == ("arm1", "path", code)
    assert err.reason == f"{code}: {detail}"
    assert str(err) == f"arm1 refused the path: {code}: {detail}"


def test_a_sim_that_holds_its_robots_is_a_pause_a_distinct_rejected():
    err = rejection_error(
        "arm1", _reject("held", command="joints", code=HELD, detail="the sim holds its robots (this sim hears no one)")
    )
    assert isinstance(err, Paused) and isinstance(err, Rejected) and not isinstance(err, NotOwner)
    assert (err.robot, err.command, err.code) == ("arm1", "joints", "held")

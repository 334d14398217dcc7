"""A refusal in plain words (:mod:`user_peer.console.wording`): the next step first, the code's reason after."""

from __future__ import annotations

from user_peer.console.wording import plain
from user_peer.errors import FabricUserError, NotOwner, Rejected, Timeout, Unreachable


def test_a_request_refused_while_the_arm_moves_says_wait_or_queue_and_keeps_the_reason():
    text = plain(
        NotOwner("arm1 not granted to bob: denied: in motion, owned by alice"), robot="arm1", owner="alice", me="bob"
    )
    assert text.startswith("arm1 is moving and belongs to alice: wait until it stops, or press Queue to be next")
    assert text.endswith("[NotOwner: arm1 not granted to bob: denied: in motion, owned by alice]")


def test_a_command_on_someone_elses_robot_says_queue_or_ask_and_on_nobodys_says_request_first():
    assert plain(
        NotOwner("bob does not own arm1 (owner: alice); call request() first"), robot="arm1", owner="alice", me="bob"
    ).startswith("arm1 belongs to alice: press Queue to be next, or ask alice to release it")
    assert plain(
        NotOwner("bob does not own arm1 (owner: nobody); call request() first"), robot="arm1", owner="", me="bob"
    ).startswith("you do not own arm1: press Request first")


def test_other_refusals_say_what_to_do_next():
    assert plain(Timeout("no answer"), robot="base1", owner="", me="bob").startswith("no answer in time")
    assert plain(Unreachable("no IK solution"), robot="arm1", owner="", me="bob").startswith(
        "out of reach: no IK solution. Move"
    )
    assert plain(Rejected("bad frame", robot="base1", command="path"), robot="base1", owner="bob", me="bob").startswith(
        "base1 refused it: bad frame"
    )
    assert plain(
        FabricUserError("goal 'a b' contains forbidden character(s) ' '"), robot="", owner="", me="bob"
    ).startswith("a name may not hold a space")


def test_a_reason_with_a_line_break_stays_one_line():
    assert "\n" not in plain(NotOwner("x\ny"), robot="arm1", owner="eve\nmallory", me="bob")
